#!/usr/bin/env bash
# Set up .venv (scripts/setup.sh) and run the test suite on two workers (pytest-xdist).
#
#   bash scripts/test.sh                          # everything under tests/
#   bash scripts/test.sh tests/test_optics.py -x  # extra arguments go to pytest
#
# With no path among the arguments pytest falls back to testpaths = ["tests"] (pyproject.toml).
# The exit code is pytest's.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

bash scripts/setup.sh

if [ "$#" -eq 0 ]; then
    set -- tests
fi
exec .venv/bin/python -m pytest -q -n 2 "$@"
