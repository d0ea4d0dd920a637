#!/usr/bin/env bash
# Set up the project in .venv (if needed) and serve on the embedded defaults:
# SQLite + task queue + uploads under ./data, http://127.0.0.1:8000, one worker.
# Options: python -m app --help (or SHAPES_* environment variables).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e .
exec .venv/bin/python -m app "$@"
