"""Time limits scaled to the machine, from one place.

A limit in a test only stops a hang; it asserts no speed (figures belong to the benchmarks in tools/). Limits are
written for an unloaded 2-core machine and multiplied by `factor()`: IMU_EMULATOR_TIMEOUT_SCALE if set, else how
much slower than that machine a fixed pure-Python loop runs here now (wall time, so a loaded machine or a busy
xdist worker counts), never below 1.
"""
from __future__ import annotations

import functools
import os
import time

#: Wall seconds of _calibration_loop() on the reference machine (AMD EPYC, 2 cores, min of 3 runs, load average about 4 from other sessions).
REFERENCE_S = 0.045


def _calibration_loop() -> float:
    start = time.perf_counter()
    total = 0
    for i in range(400_000):
        total += i * i % 7
    return time.perf_counter() - start


@functools.lru_cache(maxsize=1)
def factor() -> float:
    override = os.environ.get("IMU_EMULATOR_TIMEOUT_SCALE")
    if override:
        try:
            value = float(override)
        except ValueError:
            raise ValueError(f"IMU_EMULATOR_TIMEOUT_SCALE={override!r}: expected a number >= 1") from None
        if not value >= 1:
            raise ValueError(f"IMU_EMULATOR_TIMEOUT_SCALE={override!r}: expected a number >= 1")
        return value
    best = min(_calibration_loop() for _ in range(3))
    return max(1.0, best / REFERENCE_S)


def scaled(seconds: float) -> float:
    """A time limit of `seconds` on the reference machine, here."""
    return seconds * factor()
