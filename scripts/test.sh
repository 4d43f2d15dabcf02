#!/usr/bin/env bash
# Set up .venv (scripts/setup.sh) and run the tests on two workers (pytest-xdist).
#
#   bash scripts/test.sh                          # the fast set: every test not marked `slow`
#   bash scripts/test.sh --full                   # everything (THINFILM_FULL=1 does the same)
#   bash scripts/test.sh --slow                   # the `slow` tests only (CI's second step)
#   bash scripts/test.sh tests/optics -x          # extra arguments go to pytest
#   THINFILM_SETUP=0 bash scripts/test.sh         # skip scripts/setup.sh (.venv is set up already)
#
# `slow` marks the rest of a thinned parameter sweep (the fast set keeps a few values of each)
# and the checks whose set-up takes tens of seconds (docs/benchmarks.md#test-suite). Each test
# file runs on one worker (--dist loadfile), so its module fixtures (a registered extension,
# rendered scenes, compiled shaders) are made once; tests/conftest.py puts the longest files
# first and --no-loadscope-reorder keeps that order (xdist would sort by test count). With no path among the arguments pytest falls back to testpaths = ["tests"]
# (pyproject.toml). The exit code is pytest's; the wall time is printed last.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

selection=(-m "not slow")
if [ "${THINFILM_FULL:-0}" = "1" ]; then
    selection=()
fi
args=()
for arg in "$@"; do
    case "$arg" in
        --full) selection=() ;;
        --slow) selection=(-m "slow") ;;
        *) args+=("$arg") ;;
    esac
done

if [ "${THINFILM_SETUP:-1}" != "0" ]; then
    bash scripts/setup.sh
fi

start=$(date +%s)
status=0
.venv/bin/python -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder "${selection[@]}" "${args[@]}" || status=$?
echo "tests: ${selection[*]:-all} exit $status in $(($(date +%s) - start)) s (load average $(cut -d' ' -f1-3 /proc/loadavg))"
exit "$status"
