"""Whether a run held whole fits in memory, checked before it starts, so that what cannot fit is refused with
the figure instead of ending in MemoryError hours later.

An NPZ output and the Python API's `simulate()` hold every sample (t, accel, gyro per IMU, quat per IMU,
truth). Available memory is the kernel's MemAvailable. (The outputs' own sizes, and the disk check of a CSV,
are the output formats': imu_emulator.output.formats.)
"""
from __future__ import annotations

from imu_emulator.errors import ImuEmulatorError

TRUTH_VALUES = 15          # position, velocity, euler, omega, alpha (3 each)


class RunSizeError(ImuEmulatorError):
    """The run would not fit in memory or on disk."""


def memory_bytes(n_samples: int, n_imus: int, quat: bool, truth: bool, *, increments: bool = False,
                 temperature: bool = False, earth_truth: bool = False, bias_truth: bool = False) -> int:
    """Bytes of the arrays that hold a whole run (float64; Simulation.run's): t, accel and gyro, and per IMU
    quat, dtheta and dvel, temperature, realized biases (truth); the truth's own columns and the Earth truth."""
    per_imu = 6 + 4 * quat + 6 * increments + temperature + 6 * (truth and bias_truth)
    shared = TRUTH_VALUES if truth else 0
    if truth and earth_truth:    # earth_truth (frames, rotations) imported only for scenes on the Earth
        from imu_emulator.motion.earth_truth import KEYS
        shared += 3 * len(KEYS)
    return 8 * n_samples * (1 + n_imus * per_imu + shared)


def available_memory() -> int | None:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def gib(n: float) -> str:
    return f"{n / 2 ** 30:.3g} GiB"


def check_memory(n_samples: int, n_imus: int, quat: bool, truth: bool, what: str, **columns) -> None:
    """RunSizeError when holding the whole run would take more than the memory available now (`columns`: the
    optional groups memory_bytes counts)."""
    check_fits(memory_bytes(n_samples, n_imus, quat, truth, **columns), n_samples, n_imus, what)


def check_fits(need: int, n_samples: int, n_imus: int, what: str) -> None:
    """RunSizeError when `need` bytes are more than the memory available now."""
    have = available_memory()
    if have is not None and need > have:
        raise RunSizeError(f"{what}: {n_samples} samples x {n_imus} IMU(s) take {gib(need)} in memory, "
                           f"{gib(have)} are available; write a .csv (it streams to disk), or shorten "
                           "scene.duration_s or lower scene.rate_hz")
