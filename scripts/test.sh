#!/usr/bin/env bash
# Set up the project in .venv (if needed), check the code (ruff lint and format, mypy),
# then run the test suite. Arguments go to pytest: `./scripts/test.sh -m "not slow"`
# is the fast loop; no arguments run everything (what CI runs).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e ".[test]"
.venv/bin/python -m ruff check .
.venv/bin/python -m ruff format --check .
.venv/bin/python -m mypy
exec .venv/bin/python -m pytest "$@"
