#!/usr/bin/env bash
# Developer set-up on a Debian/Ubuntu machine (users install the wheel: pip install imu-emulator):
#   1. Debian packages for the real-SocketCAN tests (User Mode Linux, kmod's insmod, can-utils' candump, iproute2),
#      when root or passwordless sudo is available; skipped with the reason otherwise;
#   2. a User Mode Linux that starts on this CPU: Debian's, or where it cannot (AVX-512/AMX CPUs) Debian
#      unstable's, unpacked into .uml/ (tests/support/uml/newer_uml.sh);
#   3. a virtual environment in .venv (kept if it is there) with the package, editable, and its test and plot extras.
# Safe to run again: installed packages and an existing venv are left as they are.
#   ./install.sh [--dry-run]     --dry-run prints each step's commands without running them
# Environment: PYTHON (default python3) makes the venv.
set -euo pipefail
cd "$(dirname "$0")"

DRY_RUN=0
for arg in "$@"; do
    case "$arg" in
        --dry-run) DRY_RUN=1 ;;
        -h|--help) sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "install.sh: unknown option '$arg' (see ./install.sh --help)" >&2; exit 2 ;;
    esac
done
PYTHON="${PYTHON:-python3}"
DEBIAN_PACKAGES=(user-mode-linux kmod can-utils iproute2)

step() { echo "==> $*"; }
run() {
    echo "    \$ $*"
    [ "$DRY_RUN" -eq 1 ] || "$@"
}

step "1/3 Debian packages for the SocketCAN tests: ${DEBIAN_PACKAGES[*]}"
if ! command -v apt-get >/dev/null 2>&1; then
    echo "    no apt-get here; SocketCAN tests will be skipped (they need Debian's user-mode-linux)"
else
    missing=()
    for pkg in "${DEBIAN_PACKAGES[@]}"; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
    done
    sudo=()
    if [ "${#missing[@]}" -eq 0 ]; then
        echo "    all installed already"
    elif [ "$(id -u)" -ne 0 ] && ! sudo -n true 2>/dev/null; then
        echo "    SocketCAN tests will be skipped: not root and sudo needs a password (or is missing);"
        echo "    to have them, run as root: apt-get install ${missing[*]}"
        missing=()
    elif [ "$(id -u)" -ne 0 ]; then
        sudo=(sudo -n)
    fi
    if [ "${#missing[@]}" -gt 0 ]; then
        # Another apt or dpkg (unattended upgrades on a fresh machine) may hold the lock: wait for it up to 10 min.
        echo "    installing ${missing[*]} (waiting up to 600 s if another apt/dpkg holds the lock)"
        lock=(-o DPkg::Lock::Timeout=600)
        run ${sudo[@]+"${sudo[@]}"} apt-get "${lock[@]}" update -qq
        run ${sudo[@]+"${sudo[@]}"} env DEBIAN_FRONTEND=noninteractive apt-get "${lock[@]}" install -y -qq "${missing[@]}"
    fi
fi

step "2/3 User Mode Linux that starts on this CPU, for the SocketCAN tests"
uml_check=(tests/support/uml/boot.py --check)
if ! command -v linux.uml >/dev/null 2>&1; then
    echo "    no linux.uml: SocketCAN tests will be skipped"
elif [ "$DRY_RUN" -eq 1 ]; then
    echo "    \$ $PYTHON ${uml_check[*]}   (where Debian's UML cannot start on this CPU: tests/support/uml/newer_uml.sh)"
elif said=$("$PYTHON" "${uml_check[@]}" 2>&1); then
    echo "    $said"
elif grep -q "ptrace set fp regs failed" <<<"$said"; then
    echo "    Debian's UML cannot start on this CPU: fetching Debian unstable's into .uml/"
    if tests/support/uml/newer_uml.sh "$PYTHON" && said=$("$PYTHON" "${uml_check[@]}" 2>&1); then
        echo "    $said"
    else
        echo "    SocketCAN tests will be skipped: $said"
    fi
else
    echo "    SocketCAN tests will be skipped: $said"
fi

step "3/3 virtual environment .venv with the package (editable) and its test and plot extras"
if [ -x .venv/bin/python ]; then
    echo "    .venv exists: kept"
else
    command -v "$PYTHON" >/dev/null 2>&1 || { echo "install.sh: $PYTHON not found (set PYTHON=...)" >&2; exit 1; }
    run "$PYTHON" -m venv .venv
fi
run .venv/bin/python -m pip install -q --upgrade pip
run .venv/bin/python -m pip install -q -e ".[test,plot]"
if [ "$DRY_RUN" -eq 1 ]; then
    echo "dry run: nothing was changed"
else
    echo "installed: run the tests with  .venv/bin/python -m pytest  (imu-emulator: .venv/bin/imu-emulator)"
fi
