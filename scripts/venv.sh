# Sourced by serve.sh and test.sh: make .venv and install the project into it, once per
# change of what it declares (pyproject.toml) or of the extras asked for; the project is
# installed editable, so a change of its code needs no reinstall.
ensure_venv() {  # ensure_venv [EXTRAS]: e.g. ensure_venv test
    if [ ! -x .venv/bin/python ]; then
        python3 -m venv .venv
    fi
    local spec="."
    if [ -n "${1:-}" ]; then spec=".[$1]"; fi
    local stamp=".venv/.installed-${1:-base}"
    local want
    want="$(sha256sum pyproject.toml | cut -d' ' -f1)"
    if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
        return
    fi
    .venv/bin/python -m pip install --quiet --upgrade pip
    .venv/bin/python -m pip install --quiet -e "$spec"
    echo "$want" > "$stamp"
}
