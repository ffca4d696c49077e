"""A run's size, estimated before it starts, so that what cannot fit is refused with the figure instead of
ending in MemoryError (or a full disk) hours later.

In memory: an NPZ output and the Python API's `simulate()` hold every sample (t, accel, gyro per IMU, quat per
IMU, truth); a CSV streams block by block and needs disk instead. Available memory is the kernel's
MemAvailable; free disk is that of the output's directory.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from imu_emulator.errors import ImuEmulatorError

# "%.17g" of a double is at most 24 characters (sign, 17 digits, point, "e-308"), plus its comma.
CSV_BYTES_PER_VALUE = 25
TRUTH_VALUES = 15          # position, velocity, euler, omega, alpha (3 each)


class RunSizeError(ImuEmulatorError):
    """The run would not fit in memory or on disk."""


def memory_bytes(n_samples: int, n_imus: int, quat: bool, truth: bool) -> int:
    """Bytes of the arrays that hold a whole run (float64)."""
    per_sample = 1 + n_imus * (6 + (4 if quat else 0)) + (TRUTH_VALUES if truth else 0)
    return 8 * n_samples * per_sample


def csv_bytes(n_samples: int, imu_names, truth: bool) -> int:
    """Upper bound on a CSV's size: one row per sample per IMU."""
    values = 7 + (12 if truth else 0)
    return sum(n_samples * (values * CSV_BYTES_PER_VALUE + len(name.encode()) + 2) for name in imu_names)


def available_memory() -> int | None:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _gib(n: float) -> str:
    return f"{n / 2 ** 30:.3g} GiB"


def check_memory(n_samples: int, n_imus: int, quat: bool, truth: bool, what: str) -> None:
    """RunSizeError when holding the whole run would take more than the memory available now."""
    need = memory_bytes(n_samples, n_imus, quat, truth)
    have = available_memory()
    if have is not None and need > have:
        raise RunSizeError(f"{what}: {n_samples} samples x {n_imus} IMU(s) take {_gib(need)} in memory, "
                           f"{_gib(have)} are available; write a .csv (it streams to disk), or shorten "
                           "scene.duration_s or lower scene.rate_hz")


def check_output(scene, output: str | Path, truth: bool, allow_large: bool = False) -> None:
    """Before `generate` runs: an NPZ must fit in memory (twice: the blocks, then the joined arrays); a CSV
    must fit on the disk of its directory unless `allow_large` (the estimate is an upper bound)."""
    output = Path(output)
    n = scene.n_samples
    if output.suffix.lower() == ".npz":
        check_memory(2 * n, len(scene.imus), False, truth, str(output))
        return
    if output.suffix.lower() != ".csv":
        return    # other formats (MCAP) are written by their own libraries; their size is not estimated here
    need = csv_bytes(n, scene.imu_names, truth)
    usage = shutil.disk_usage(output.parent if str(output.parent) else Path(os.curdir))
    free = usage.free
    # total 0: a pseudo file system (/proc, /dev) that reports no sizes; the writer's own errors speak there
    if usage.total and need > free and not allow_large:
        raise RunSizeError(f"{output}: {n} samples x {len(scene.imus)} IMU(s) make up to {_gib(need)} of CSV, "
                           f"{_gib(free)} are free there; shorten scene.duration_s or lower scene.rate_hz, "
                           "or pass --allow-large if you know it fits")
