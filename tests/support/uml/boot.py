"""Boot User Mode Linux with the host's root as its root (hostfs) and tests/support/uml/init.sh as init, which loads
SocketCAN, raises vcan0 and runs either the socketcan tests or a given shell script. Shared by
tests/live/test_socketcan_uml.py and tools/bench_coexist.py; holds no tests."""
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
UML = shutil.which("linux.uml")


@dataclass
class Boot:
    booted: bool            # False: UML could not start here (reason in `output`)
    exit_code: int | None   # the command's, None when the guest did not finish
    output: str


def unavailable() -> str | None:
    """Why UML cannot run here, or None."""
    if UML is None:
        return "linux.uml not installed (apt-get install user-mode-linux kmod can-utils)"
    if not Path("/usr/lib/uml/modules").is_dir():
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
    env = {**os.environ, "TMPDIR": "/dev/shm"}
    command = [UML, f"mem={mem}", "root=/dev/root", "rootfstype=hostfs", "hostfs=/", "rw", "quiet", "loglevel=3",
               f"init={HERE / 'init.sh'}", "con=null", "con0=null,fd:1", f"umid=imu-{uuid.uuid4().hex[:12]}",
               f"UML_RESULT_DIR={result_dir}", f"UML_REPO={REPO}", f"UML_PYTHON={sys.executable}"]
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
        return Boot(False, None, f"User Mode Linux could not boot here (exit {run.returncode}): "
                                 f"{(run.stderr or run.stdout).strip()[-500:]}")
    return Boot(True, int(exit_file.read_text()) if exit_file.exists() else None, output)
