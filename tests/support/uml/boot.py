"""Boot User Mode Linux with the host's root as its root (hostfs) and tests/support/uml/init.sh as init, which loads
SocketCAN, raises vcan0 and runs either the socketcan tests or a given shell script. Shared by
tests/live/test_socketcan_uml.py and tools/bench_coexist.py; holds no tests.

The UML is Debian's (/usr/bin/linux.uml), or the newer one install.sh puts in .uml/ where Debian's cannot start on
this CPU (tests/support/uml/newer_uml.sh says why). `python tests/support/uml/boot.py --check` boots the guest
once with nothing to run and says whether it worked (install.sh uses it)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import uuid
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[2]     # tests/support/uml -> the repository
NEWER = REPO / ".uml"      # install.sh's newer UML (newer_uml.sh), when Debian's cannot start here
#: what UML 6.1 prints (at KERN_ERR, hence loglevel=4) when the host refuses its fixed-size XSAVE buffer
FP_REGS_FAILED = "ptrace set fp regs failed"


def _trusted(path: Path) -> bool:
    """The file and every directory up to the repository belong to this user and nobody else may write them:
    what is executed (the UML binary, its preloaded shim) must be what install.sh put there."""
    for p in [path, *path.parents]:
        st = p.lstat()
        if st.st_uid != os.getuid() or st.st_mode & 0o022 or (p != path and not p.is_dir()):
            return False
        if p == REPO:
            return True
    return False


def _trusted_tree(top: Path) -> bool:
    """_trusted for `top` and everything under it (the guest loads these kernel modules)."""
    return _trusted(top) and all(_trusted(Path(d) / name) for d, dirs, files in os.walk(top) for name in dirs + files)


def _newer() -> tuple[str, dict, str] | None:
    """(binary, environment additions, modules directory) of .uml/'s UML, when install.sh made it and it is safe."""
    binary, shim, modules = NEWER / "root/usr/bin/linux.uml", NEWER / "libisoc23.so", NEWER / "root/usr/lib/uml/modules"
    if (not binary.is_file() or not _trusted(binary) or (shim.exists() and not _trusted(shim))
            or not modules.is_dir() or not _trusted_tree(modules)):
        return None
    env = {"LD_PRELOAD": str(shim)} if shim.exists() else {}
    return str(binary), env, str(modules)


_NEWER = _newer()
UML = _NEWER[0] if _NEWER else shutil.which("linux.uml")


@dataclass
class Boot:
    booted: bool            # False: UML could not start here (reason in `output`)
    exit_code: int | None   # the command's, None when the guest did not finish
    output: str


def unavailable() -> str | None:
    """Why UML cannot run here, or None."""
    if UML is None:
        return "linux.uml not installed (apt-get install user-mode-linux kmod can-utils)"
    if _NEWER is None and not Path("/usr/lib/uml/modules").is_dir():
        return "user-mode-linux's kernel modules are missing (/usr/lib/uml/modules)"
    return None


def boot(result_dir: Path, script: Path | None = None, timeout: float = 600, mem: str = "512M") -> Boot:
    """Run `script` (sh) inside the guest, or the socketcan tests when None; the guest has one CPU. `timeout`
    covers boot, the tests and power-off: the socketcan tests alone took 142 s of a loaded CI run (the guest runs
    several times slower than the host), and 150 s cut off a guest whose tests had all passed; a hung guest
    still fails, after 10 minutes."""
    result_dir.mkdir(parents=True, exist_ok=True)
    output_file = result_dir / "output.txt"
    output_file.touch()
    # Guest RAM is a file under TMPDIR: it must be a mount without noexec and with room for mem=.
    env = {**os.environ, "TMPDIR": "/dev/shm", **(_NEWER[1] if _NEWER else {})}
    modules = [f"UML_MODULES={_NEWER[2]}"] if _NEWER else []
    command = [UML, f"mem={mem}", "root=/dev/root", "rootfstype=hostfs", "hostfs=/", "rw", "quiet", "loglevel=4",
               f"init={HERE / 'init.sh'}", "con=null", "con0=null,fd:1", f"umid=imu-{uuid.uuid4().hex[:12]}",
               f"UML_RESULT_DIR={result_dir}", f"UML_REPO={REPO}", f"UML_PYTHON={sys.executable}", *modules]
    if script is not None:
        command.append(f"UML_SCRIPT={script}")
    try:
        run = subprocess.run(command, env=env, capture_output=True, text=True, timeout=timeout,
                             stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return Boot(True, None, f"did not power off within {timeout:g} s:\n" + output_file.read_text())
    output = output_file.read_text()
    exit_file = result_dir / "exit_code"
    if not exit_file.exists() and not output.strip():
        said = (run.stdout or "") + (run.stderr or "")
        if FP_REGS_FAILED in said:
            reason = (f"{UML} cannot start on this CPU ({FP_REGS_FAILED}: Debian bookworm's UML 6.1 keeps the "
                      "XSAVE state in a fixed-size buffer, and the host kernel takes nothing less than this CPU's "
                      "whole area, larger with AVX-512 or AMX); ./install.sh fetches a newer UML into .uml/")
        else:
            reason = said.strip()[-500:]
        return Boot(False, None, f"User Mode Linux could not boot here (exit {run.returncode}): {reason}")
    return Boot(True, int(exit_file.read_text()) if exit_file.exists() else None, output)


def check() -> int:
    """Boot once with nothing to run: 0 and 'booted' when the guest ran and powered off, else 1 and why."""
    import tempfile
    reason = unavailable()
    if reason:
        print(reason)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "nothing.sh"
        script.write_text("uname -r\n")
        result = boot(Path(tmp) / "result", script, timeout=120)
    if result.booted and result.exit_code == 0:
        print(f"booted: {UML}, kernel {result.output.split()[-1] if result.output.split() else '?'}")
        return 0
    print(result.output.strip()[-500:] or "the guest did not finish")
    return 1


if __name__ == "__main__":
    if sys.argv[1:] != ["--check"]:
        sys.exit("usage: python tests/support/uml/boot.py --check")
    sys.exit(check())
