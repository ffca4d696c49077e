"""Cold compile time of a scene's kernel against its number of IMUs (each with its own lever arm and mounting, so
every IMU adds code): `generate` with an empty kernel cache, one fresh process per count. Prints wall and CPU
seconds per count and the ratio to the first count; asserts nothing. A count that exceeds --timeout is reported as
such. --numba-only adds, interleaved, the same compile without the machine-code export (IMU_EMULATOR_NATIVE=0).

    .venv/bin/python tools/bench_compile_imus.py [--counts 1 2 4 8 16] [--timeout 300] [--numba-only]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SCENE = """
[scene]
rate_hz = 200
duration_s = 1.0
[trajectory]
shape = "helix"
radius_m = 4.0
frequency_hz = 1.0
climb_mps = 0.5
[attitude]
mode = "tangent"
[effects]
gravity = true
lever_arm = true
mounting = true
"""


def scene_text(n_imu: int) -> str:
    imus = "".join(f'[[imu]]\nname = "imu{i}"\nlever_arm_m = [{0.01 * (i + 1)}, {-0.02 * i}, 0.03]\n'
                   f"mounting_rpy_deg = [{i % 7}.0, {2 * (i % 5)}.0, {10 * i % 360}.0]\n" for i in range(n_imu))
    return SCENE + imus


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="*", default=[1, 2, 4, 8, 16])
    parser.add_argument("--timeout", type=float, default=300.0)
    parser.add_argument("--numba-only", action="store_true",
                        help="also time each count with IMU_EMULATOR_NATIVE=0 (no machine-code export), interleaved")
    args = parser.parse_args()
    base = {}
    variants = [("", "1")] + ([(" (numba only)", "0")] if args.numba_only else [])
    for n, (label, native) in ((n, v) for n in args.counts for v in variants):
        with tempfile.TemporaryDirectory() as tmp:
            scene = Path(tmp) / f"imus{n}.toml"
            scene.write_text(scene_text(n))
            env = dict(os.environ, IMU_EMULATOR_CACHE=str(Path(tmp) / "cache"), IMU_EMULATOR_NATIVE=native)
            started = time.monotonic()
            try:
                proc = subprocess.Popen([sys.executable, "-m", "imu_emulator", "generate", str(scene), "-o",
                                         str(Path(tmp) / "o.npz"), "--quiet"], env=env, stderr=subprocess.PIPE)
                _, status, usage = os.wait4(proc.pid, 0) if _wait(proc, args.timeout) else (0, 0, None)
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
            wall = time.monotonic() - started
            if usage is None:
                print(f"{n:4d} IMUs{label}: more than {args.timeout:.0f} s (stopped)")
                continue
            if os.waitstatus_to_exitcode(status):
                print(f"{n:4d} IMUs{label}: failed: {proc.stderr.read().decode().strip()}")
                continue
            cpu = usage.ru_utime + usage.ru_stime
            base.setdefault(label, cpu)
            print(f"{n:4d} IMUs{label}: {wall:7.1f} s wall {cpu:7.1f} s CPU  ({cpu / base[label]:.1f}x the first "
                  f"count's CPU, {cpu / n:.2f} s CPU per IMU)", flush=True)
    print(f"(1-minute load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs)")


def _wait(proc, timeout: float) -> bool:
    """True once the child has exited (still a zombie, so wait4 can read its usage); False after the timeout."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None:
            return True
        time.sleep(0.05)
    return False


if __name__ == "__main__":
    main()
