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

[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/pip install -q --disable-pip-version-check -e '.[dev]'
echo "install: ready. Test: .venv/bin/pytest   Run: .venv/bin/riderlive serve"
