#!/usr/bin/env bash
# Set up the project in .venv (if needed), check the code (ruff lint and format, mypy),
# then run the test suite. Arguments go to pytest: `./scripts/test.sh -m "not slow"`
# is the fast loop; no arguments run everything (what CI runs).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/venv.sh
ensure_venv test
# Servers some tests run for real, from Debian's packages (Playwright's own browser
# download is not reachable from every machine): Chromium for the web page's tests,
# PostgreSQL and Redis for the scale-out tests, docker-compose to validate the compose
# files (no container engine runs here). Installed once, as root or via sudo.
apt_install() {  # apt_install PACKAGE...
    if ! command -v apt-get >/dev/null; then
        echo "no apt-get to install $*: the tests that need it will fail or be skipped" >&2
        return
    fi
    local sudo_cmd=""
    if [ "$(id -u)" != 0 ] && command -v sudo >/dev/null; then sudo_cmd="sudo"; fi
    $sudo_cmd apt-get update -qq && $sudo_cmd apt-get install -y -qq "$@" >/dev/null \
        || echo "could not install $*: the tests that need it will fail or be skipped" >&2
}
missing=()
if ! command -v chromium >/dev/null && ! command -v chromium-browser >/dev/null; then
    missing+=(chromium)
fi
if ! compgen -G "/usr/lib/postgresql/*/bin/pg_ctl" >/dev/null; then missing+=(postgresql); fi
if ! command -v redis-server >/dev/null; then missing+=(redis-server); fi
if ! command -v docker-compose >/dev/null; then missing+=(docker-compose); fi
if [ ${#missing[@]} -gt 0 ]; then apt_install "${missing[@]}"; fi
.venv/bin/python -m ruff check .
.venv/bin/python -m ruff format --check .
.venv/bin/python -m mypy
# The test files are spread over the machine's cores (pytest-xdist; a file stays on one
# worker, so its module fixtures start once and a session's service once per worker),
# each worker's BLAS on one thread so that the workers do not crowd each other. `-n 0`
# after it runs them in this one process.
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}" OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
exec .venv/bin/python -m pytest -n auto --dist loadfile "$@"
