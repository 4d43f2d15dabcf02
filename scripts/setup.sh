#!/usr/bin/env bash
# Create or refresh the development environment in .venv (repository root).
#
# Idempotent: an existing .venv on Python 3.13 is kept and only brought up to
# requirements-dev.txt (pip installs nothing when every pin is already satisfied).
# Works from any working directory.
#
# Python 3.13 is looked up, in order, as:
#   1. $THINFILM_PYTHON, if set (a path to a python3.13 executable);
#   2. `python3.13` on PATH (a pyenv shim counts only if it actually runs);
#   3. pyenv's newest $(pyenv root)/versions/3.13*/bin/python3.13
#      (pyenv root from `pyenv root`, else $PYENV_ROOT, else ~/.pyenv).
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."
REPO_ROOT="$(pwd)"
VENV="$REPO_ROOT/.venv"
PIP_VERSION="26.3"

say() { printf 'setup: %s\n' "$*"; }

# True when "$1" runs and is Python 3.13.
is_py313() {
    [ -n "$1" ] && "$1" -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 13) else 1)' >/dev/null 2>&1
}

# True when "$1" is Python 3.13 and not itself a virtual environment's interpreter (an activated
# .venv must not be used to rebuild .venv).
is_base_py313() {
    is_py313 "$1" && "$1" -c 'import sys; sys.exit(0 if sys.prefix == sys.base_prefix else 1)' >/dev/null 2>&1
}

find_python() {
    local candidate root
    if [ -n "${THINFILM_PYTHON:-}" ]; then
        if is_base_py313 "$THINFILM_PYTHON"; then
            printf '%s\n' "$THINFILM_PYTHON"
            return 0
        fi
        say "THINFILM_PYTHON=$THINFILM_PYTHON is not a working Python 3.13 (outside a virtual environment)" >&2
        return 1
    fi
    if candidate="$(command -v python3.13 2>/dev/null)" && is_base_py313 "$candidate"; then
        printf '%s\n' "$candidate"
        return 0
    fi
    root=""
    if command -v pyenv >/dev/null 2>&1; then
        root="$(pyenv root 2>/dev/null || true)"
    fi
    for root in "$root" "${PYENV_ROOT:-}" "$HOME/.pyenv"; do
        [ -n "$root" ] && [ -d "$root/versions" ] || continue
        # Newest 3.13.x first.
        while IFS= read -r candidate; do
            if is_base_py313 "$candidate"; then
                printf '%s\n' "$candidate"
                return 0
            fi
        done < <(ls -d "$root"/versions/3.13*/bin/python3.13 2>/dev/null | sort -rV)
    done
    return 1
}

if ! PYTHON="$(find_python)"; then
    cat >&2 <<'MSG'
setup: error: Python 3.13 not found (bpy 5.2 is published for Python 3.13 only).
  Looked for $THINFILM_PYTHON, `python3.13` on PATH, and $(pyenv root)/versions/3.13*/bin/python3.13.
  Install it with pyenv, for example:
      pyenv install 3.13
  (or point THINFILM_PYTHON at a python3.13 executable), then run this script again.
MSG
    exit 1
fi
say "Python 3.13: $PYTHON ($("$PYTHON" -c 'import sys; print(sys.version.split()[0])'))"

if [ -x "$VENV/bin/python" ] && is_py313 "$VENV/bin/python"; then
    say "keeping existing virtual environment $VENV"
else
    if [ -e "$VENV" ]; then
        say "existing $VENV is not a working Python 3.13 environment: recreating it"
        rm -rf "$VENV"
    fi
    say "creating virtual environment $VENV"
    "$PYTHON" -m venv "$VENV"
fi

PIP=("$VENV/bin/python" -m pip --disable-pip-version-check)
if [ "$("${PIP[@]}" --version | awk '{print $2}')" != "$PIP_VERSION" ]; then
    say "installing pip==$PIP_VERSION"
    "${PIP[@]}" install --quiet "pip==$PIP_VERSION"
fi

say "installing requirements-dev.txt (pinned; already-satisfied pins are skipped)"
before="$("${PIP[@]}" freeze --all | sort)"
"${PIP[@]}" install --quiet --requirement "$REPO_ROOT/requirements-dev.txt"
after="$("${PIP[@]}" freeze --all | sort)"
changed="$(comm -13 <(printf '%s\n' "$before") <(printf '%s\n' "$after") | tr '\n' ' ')"
if [ -n "$changed" ]; then
    say "installed: $changed"
else
    say "nothing new to install"
fi
say "done: use $VENV/bin/python"
