"""When a slower sensor (magnetometer, barometer) has a new reading among the IMU's samples.

Samples carry every sensor at the IMU's rate (the slower ones held between their own readings). A format that
marks new readings (MAVLink HIL_SENSOR's fields_updated bits) or sends a message only when one exists (a
DroneCAN node's StaticPressure) asks an `UpdateTicks` per sensor: a reading is new at the first sample of each
period of 1/rate on the sample clock, i.e. where floor(time_ns / period_ns) changes. The count continues across
blocks, so a stream cut into blocks flags the same samples as one block would.
"""
from __future__ import annotations

import math

import numpy as np


class UpdateTicks:
    """rate_hz None: every sample is new (the sensor runs at the sample rate)."""

    def __init__(self, rate_hz: float | None, name: str = "rate_hz"):
        if rate_hz is not None and not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"{name}: a positive number of Hz, got {rate_hz!r}")
        self.rate_hz = rate_hz
        self.period_ns = None if rate_hz is None else max(1, round(1e9 / rate_hz))
        self._last: int | None = None      # the period index of the previous sample

    def due(self, time_ns: np.ndarray) -> np.ndarray:
        """(n,) bool: sample i begins a new period (the first sample of a stream always does)."""
        n = len(time_ns)
        if self.period_ns is None:
            return np.ones(n, dtype=bool)
        ticks = np.floor_divide(np.asarray(time_ns, dtype=np.int64), self.period_ns)
        previous = np.empty(n, dtype=np.int64)
        if n:
            previous[0] = ticks[0] - 1 if self._last is None else self._last
            previous[1:] = ticks[:-1]
            self._last = int(ticks[-1])
        return ticks != previous
