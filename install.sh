#!/usr/bin/env bash
# Sets up everything the emulator and its tests need on a fresh Debian/Ubuntu machine:
# Debian packages for the real-SocketCAN tests (User Mode Linux, kmod's insmod, can-utils' candump),
# then a virtual environment in .venv with the package (editable) and its test extra.
set -euo pipefail
cd "$(dirname "$0")"

if command -v apt-get >/dev/null 2>&1; then
    sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq user-mode-linux kmod can-utils iproute2 >/dev/null
else
    echo "install.sh: no apt-get here; the SocketCAN tests will be skipped (they need Debian's user-mode-linux)" >&2
fi

python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[test,plot]"
echo "installed: run the tests with  .venv/bin/python -m pytest"
