#!/usr/bin/env bash
# Creates the TSID peer's own virtual environment, benchmarks/.venvs/tsid, and installs
# requirements.txt (beside this script) into it. Re-running it is harmless: the venv is kept
# and pip installs only what is missing. Used by benchmarks/tsid_peer.py.
#
# libtsid (TSID's C++ library, no Python in it: it links no libpython) is published on PyPI
# as wheels tagged for one CPython only (1.10.0: cp314), while the `tsid` bindings have a
# wheel for every CPython. When pip finds no libtsid wheel for this Python, the script
# downloads the published Linux wheel and installs it under a py3-none tag (the same files).
# Set TSID_FROM_SOURCE=1 to build libtsid from its sdist instead (a C++ build: slow).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
bench="$(cd "$here/../.." && pwd)"
venv="$bench/.venvs/tsid"
python="${PYTHON:-python3}"
libtsid_version="1.10.0"
libtsid_python="3.14"  # the CPython whose tag the published libtsid wheel carries

if [ ! -x "$venv/bin/python" ]; then
    echo "creating $venv with $("$python" --version)"
    "$python" -m venv "$venv"
fi
pip=("$venv/bin/python" -m pip --disable-pip-version-check)

install_libtsid() {
    if "$venv/bin/python" -c "import importlib.metadata as m; assert m.version('libtsid') == '$libtsid_version'" 2>/dev/null; then
        return
    fi
    if [ "${TSID_FROM_SOURCE:-0}" = 1 ]; then
        "${pip[@]}" install --no-binary libtsid "libtsid==$libtsid_version"
        return
    fi
    if "${pip[@]}" install --only-binary=:all: --no-deps "libtsid==$libtsid_version" 2>/dev/null; then
        return
    fi
    local tmp
    tmp="$(mktemp -d)"
    trap 'rm -rf "$tmp"' RETURN
    "${pip[@]}" download --no-deps --only-binary=:all: --dest "$tmp" \
        --python-version "$libtsid_python" --platform "manylinux_2_28_$(uname -m)" \
        "libtsid==$libtsid_version"
    local wheel retagged
    wheel="$(ls "$tmp"/libtsid-*.whl)"
    retagged="$(basename "$wheel" | sed -E 's/-cp[0-9]+-cp[0-9]+-/-py3-none-/')"
    mv "$wheel" "$tmp/$retagged"
    echo "installing $retagged (the published cp${libtsid_python/./} wheel: a C++ library)"
    "${pip[@]}" install --no-deps "$tmp/$retagged"
}

install_libtsid
"${pip[@]}" install --only-binary=:all: -r "$here/requirements.txt"
"$venv/bin/python" - <<'PY'
import importlib.metadata as m

for name in ("tsid", "libtsid", "pin", "eiquadprog", "cmeel-boost", "example-robot-data", "numpy"):
    print(f"{name} {m.version(name)}")
PY
