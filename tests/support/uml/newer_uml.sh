#!/usr/bin/env bash
# A User Mode Linux that starts on this CPU, for the SocketCAN tests, in .uml/ (install.sh runs this when Debian's
# cannot start here: `python3 tests/support/uml/boot.py --check`).
#
# Why: Debian bookworm's UML (6.1) keeps a process's XSAVE state in a buffer of fixed size, and the host kernel
# refuses PTRACE_SETREGSET with less than the CPU's whole XSAVE area, which AVX-512 and AMX make larger; UML then
# panics starting init ("userspace - ptrace set fp regs failed, errno = 14"). Debian unstable's UML (7.x) sizes the
# buffer from the host and starts. Its package is fetched with apt from deb.debian.org (InRelease signature checked
# against /usr/share/keyrings/debian-archive-keyring.gpg, the package against the index's hash) and unpacked into
# .uml/root, not installed. It is built against glibc >= 2.38 for two C23 functions (__isoc23_strtol/strtoul); on an
# older host glibc those version requirements are marked weak (weak_version.py) and isoc23.c, compiled to
# .uml/libisoc23.so, supplies the two (boot.py preloads it). Files are made by this user, writable by nobody else
# (boot.py runs nothing from .uml/ otherwise).
#   tests/support/uml/newer_uml.sh [PYTHON]
set -euo pipefail
cd "$(dirname "$0")/../../.."
PYTHON="${1:-python3}"
here=tests/support/uml
dir="$PWD/.uml"
keyring=/usr/share/keyrings/debian-archive-keyring.gpg
suite=sid
for tool in apt-get dpkg-deb gcc; do
    command -v "$tool" >/dev/null 2>&1 || { echo "    no $tool: cannot fetch a newer UML"; exit 1; }
done
[ -r "$keyring" ] || { echo "    no $keyring: cannot check a newer UML's signature"; exit 1; }
umask 022
rm -rf "$dir"
mkdir -p "$dir/apt/lists/partial" "$dir/apt/cache/archives/partial" "$dir/apt/sources.list.d"
echo "deb [signed-by=$keyring] http://deb.debian.org/debian $suite main" > "$dir/apt/sources.list"
opts=(-q -o Dir::Etc::SourceList="$dir/apt/sources.list" -o Dir::Etc::SourceParts="$dir/apt/sources.list.d"
      -o Dir::State::Lists="$dir/apt/lists" -o Dir::Cache="$dir/apt/cache" -o Debug::NoLocking=1)
[ "$(id -u)" -ne 0 ] || opts+=(-o APT::Sandbox::User=root)   # _apt could not write into .uml/
echo "    \$ apt-get update ($suite, user-mode-linux only) into .uml/apt"
apt-get "${opts[@]}" update >/dev/null
echo "    \$ apt-get download user-mode-linux"
(cd "$dir" && apt-get "${opts[@]}" download user-mode-linux >/dev/null)
dpkg-deb -x "$dir"/user-mode-linux_*.deb "$dir/root"
rm -rf "$dir/apt" "$dir"/user-mode-linux_*.deb
uml="$dir/root/usr/bin/linux.uml"
missing=$("$uml" --version 2>&1 | grep -o "version \`GLIBC_[0-9.]*' not found" | grep -o "GLIBC_[0-9.]*" | sort -u || true)
if [ -n "$missing" ]; then
    echo "    this glibc lacks $(echo $missing): marked weak; .uml/libisoc23.so supplies the C23 functions"
    "$PYTHON" "$here/weak_version.py" "$uml" $missing >/dev/null
    gcc -O2 -shared -fPIC -o "$dir/libisoc23.so" "$here/isoc23.c"
fi
version=$(LD_PRELOAD="$([ -f "$dir/libisoc23.so" ] && echo "$dir/libisoc23.so")" "$uml" --version 2>/dev/null | tail -1)
echo "    UML $version in .uml/"
