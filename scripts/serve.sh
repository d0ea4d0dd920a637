#!/usr/bin/env bash
# Set up the project in .venv (the first time, or after pyproject.toml changed) and serve
# on the embedded defaults: SQLite + task queue + uploads under ./data,
# http://127.0.0.1:8000, two enrollment and two query workers.
# Options: python -m app --help (or SHAPES_* environment variables).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/venv.sh
ensure_venv
exec .venv/bin/python -m app "$@"
