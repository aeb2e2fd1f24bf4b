#!/usr/bin/env bash
# From a fresh clone to ready: .venv with riderlive and its dev tools, and Debian's
# chromium for the browser tests and the C toolchains of firmware_proto/ (installed with
# apt-get when missing; needs root).
set -euo pipefail
cd "$(dirname "$0")"

if ! command -v chromium >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "install: Debian chromium for the browser tests"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq && apt-get install -y -qq chromium >/dev/null
    else
        echo "install: chromium is missing; the browser tests need it: sudo apt-get install chromium" >&2
    fi
fi

# firmware_proto/: a C compiler and make (host build, tests), cJSON (the C test of the link
# vectors), clang (libFuzzer), gcc-avr + avr-libc (the Arduino Mega 2560 cross build),
# simavr (its benchmark).
FIRMWARE_PACKAGES="gcc make libcjson-dev clang gcc-avr avr-libc simavr"
missing=$(for p in $FIRMWARE_PACKAGES; do dpkg -s "$p" >/dev/null 2>&1 || echo "$p"; done | xargs)
if [ -n "$missing" ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "install: Debian $missing for firmware_proto"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq && apt-get install -y -qq $missing >/dev/null
    else
        echo "install: firmware_proto's tests need: sudo apt-get install $missing" >&2
    fi
fi

# mono's C# compiler checks the Unity sample client's syntax (tests/clients).
if ! command -v mcs >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "install: Debian mono-mcs for the C# client's syntax check"
        export DEBIAN_FRONTEND=noninteractive
        apt-get install -y -qq mono-mcs >/dev/null 2>&1 || { apt-get update -qq && apt-get install -y -qq mono-mcs >/dev/null; }
    else
        echo "install: mcs is missing; the C# client check skips: sudo apt-get install mono-mcs" >&2
    fi
fi

[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/pip install -q --disable-pip-version-check -e '.[dev]'
# The Khronos glTF validator for the export tests (npm, into the venv; skipped without node).
if command -v npm >/dev/null 2>&1 && [ ! -d .venv/npm/node_modules/gltf-validator ]; then
    npm install --silent --no-audit --no-fund --prefix .venv/npm gltf-validator@2.0.0-dev.3.10 >/dev/null
fi
# Blender as a Python module (PyPI bpy) for the add-on's test (tests/clients), in its own venv:
# each bpy release targets one Python minor version (4.2-5.0: Python 3.11) and pins numpy < 2.
if [ ! -x .venv/blender/bin/python ] && python3 -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
    echo "install: Blender as a module (bpy, ~370 MB) into .venv/blender"
    python3 -m venv .venv/blender && .venv/blender/bin/pip install -q --disable-pip-version-check 'bpy>=4.2,<5.1' ||
        { rm -rf .venv/blender; echo "install: bpy is unavailable here; the Blender test skips" >&2; }
fi
# The numba kernels compiled once, serially, into their disk cache: the first test run and the
# first `riderlive serve` load them instead of compiling them (several processes at once).
.ci/warm
echo "install: ready. Test: .venv/bin/pytest -n 2 --dist loadfile   Run: .venv/bin/riderlive serve"
