"""Real SocketCAN, on a host kernel without it: boot User Mode Linux with the host's root as its root
(hostfs, so this very virtualenv runs inside), load can/can-raw/can-dev/vcan, and run tests/socketcan there."""
import os
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
UML = shutil.which("linux.uml")


def test_socketcan_suite_inside_user_mode_linux(tmp_path):
    if UML is None:
        pytest.skip("linux.uml not installed (apt-get install user-mode-linux kmod can-utils)")
    if not Path("/usr/lib/uml/modules").is_dir():
        pytest.skip("user-mode-linux's kernel modules are missing (/usr/lib/uml/modules)")
    result_dir = tmp_path / "uml"
    result_dir.mkdir()
    (result_dir / "output.txt").touch()
    # Guest RAM is a file under TMPDIR: it must be a mount without noexec and with room for mem=.
    env = {**os.environ, "TMPDIR": "/dev/shm"}
    command = [UML, "mem=512M", "root=/dev/root", "rootfstype=hostfs", "hostfs=/", "rw", "quiet", "loglevel=3",
               f"init={HERE / 'uml' / 'init.sh'}", "con=null", "con0=null,fd:1", f"umid=imu-{uuid.uuid4().hex[:12]}",
               f"UML_RESULT_DIR={result_dir}", f"UML_REPO={HERE.parent}", f"UML_PYTHON={sys.executable}"]
    try:
        boot = subprocess.run(command, env=env, capture_output=True, text=True, timeout=150,
                              stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        pytest.fail("User Mode Linux did not power off within 150 s; guest output:\n"
                    + (result_dir / "output.txt").read_text())
    output = (result_dir / "output.txt").read_text()
    exit_file = result_dir / "exit_code"
    if not exit_file.exists() and not output.strip():
        pytest.skip(f"User Mode Linux could not boot here (exit {boot.returncode}): "
                    f"{(boot.stderr or boot.stdout).strip()[-500:]}\n{output[-2000:]}")
    assert exit_file.exists(), f"the guest booted but did not finish the tests:\n{output}"
    code = int(exit_file.read_text().strip())
    assert code == 0, f"socketcan tests inside User Mode Linux failed (exit {code}):\n{output}"
    assert " passed" in output and "skipped" not in output, output
