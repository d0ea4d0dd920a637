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
# The web page's tests drive a real browser: Debian's Chromium (Playwright's own
# download is not reachable from every machine). Installed once, as root or via sudo.
if ! command -v chromium >/dev/null && ! command -v chromium-browser >/dev/null; then
    if command -v apt-get >/dev/null; then
        sudo_cmd=""
        if [ "$(id -u)" != 0 ] && command -v sudo >/dev/null; then sudo_cmd="sudo"; fi
        $sudo_cmd apt-get update -qq && $sudo_cmd apt-get install -y -qq chromium >/dev/null \
            || echo "could not install chromium: the web page's tests will be skipped" >&2
    else
        echo "no chromium and no apt-get: the web page's tests will be skipped" >&2
    fi
fi
.venv/bin/python -m ruff check .
.venv/bin/python -m ruff format --check .
.venv/bin/python -m mypy
exec .venv/bin/python -m pytest "$@"
