"""Flight and drive logs as sampled motion: PX4 ULog (`.ulg`), ArduPilot DataFlash (`.bin`), ROS 2 bags in
MCAP (`.mcap`). One small module per format reads it with the library the field uses (pyulog, pymavlink's
DFReader, mcap + mcap-ros2-support); this module holds what they share: the `LogMotion` they return, the
recorded IMU they can also return (for the replay's fidelity report), and the checks on time stamps.

A log's position and attitude come on their own time bases (PX4: position at 10 Hz, attitude at 30 Hz, both
irregular). Irregular stamps are fine (the spline methods take any spacing); a gap longer than `max_gap_s`
(default: 10 times the series' median step) is an error naming the time, because a spline across it would
invent a motion. Repeated time stamps (a message logged twice) are dropped and counted in `notes`.

Sources are chosen by name and overridable: "topic" or "topic:instance" (ULog multi-id, DataFlash core or
IMU instance), a topic name for MCAP.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imu_emulator.errors import DataError
from imu_emulator.scene.files import MAX_LOG_BYTES, check_regular

SUFFIXES = {".ulg": "ulog", ".bin": "dataflash", ".mcap": "ros2bag"}
GAP_FACTOR = 10.0


@dataclass(frozen=True)
class Series:
    name: str                  # where it came from ("vehicle_attitude", "NKQ1", "/odom"), for messages
    t: np.ndarray              # (n,) seconds on the log's clock, strictly increasing
    values: np.ndarray         # (n, 3) position in metres, or (n, 4) quaternion qw, qx, qy, qz


@dataclass(frozen=True)
class LogMotion:
    source: Path
    frame: str                                 # navigation frame of the log: "NED" (PX4, ArduPilot) or "ENU" (ROS)
    position: Series
    attitude: Series
    velocity: Series | None = None             # the estimator's own velocity, when logged (for checks)
    origin_lla: tuple[float, float, float] | None = None   # reference latitude, longitude (deg), altitude (m)
    notes: tuple[str, ...] = ()                # what was dropped or assumed, to be shown to the user


@dataclass(frozen=True)
class RecordedImu:
    name: str                  # "sensor_combined", "IMU", "/imu/data"
    t: np.ndarray              # (n,) seconds, same clock as LogMotion
    gyro: np.ndarray           # (n, 3) rad/s, body frame of the log (FRD for PX4/ArduPilot, FLU for ROS)
    accel: np.ndarray          # (n, 3) m/s^2 specific force, same frame


def log_kind(path) -> str | None:
    return SUFFIXES.get(Path(path).suffix.lower())


def _module(path):
    import importlib
    kind = log_kind(path)
    if kind is None:
        raise DataError(f"{Path(path).name}: not a flight log (expected {', '.join(SUFFIXES)})")
    return importlib.import_module(f"imu_emulator.scene.logs.{kind}")


def load_log(path, position_source: str | None = None, attitude_source: str | None = None) -> LogMotion:
    """Position and attitude of the vehicle from a log (gaps are checked by `window`, once the replayed
    span is known: a gap outside it does not matter)."""
    path = Path(path)
    check_regular(path, MAX_LOG_BYTES)
    return _module(path).read_motion(path, position_source, attitude_source)


def load_recorded_imu(path, source: str | None = None) -> RecordedImu | None:
    """The vehicle's own IMU from the log, or None when the log has none."""
    path = Path(path)
    check_regular(path, MAX_LOG_BYTES)
    return _module(path).read_imu(path, source)


def split_source(text: str | None, default: str) -> tuple[str, int | None]:
    """"topic:2" -> ("topic", 2); "topic" -> ("topic", None)."""
    text = default if text is None else text
    name, _, instance = text.partition(":")
    if instance:
        if not instance.isdigit():
            raise DataError(f"source {text!r}: the instance after ':' must be a number")
        return name, int(instance)
    return name, None


def series(name: str, where: str, t_us_or_s, values, scale: float = 1.0) -> tuple[Series, str | None]:
    """A Series from raw stamps (multiplied by `scale` to give seconds) with non-finite rows refused and
    repeated stamps dropped; the second element says how many were dropped, if any."""
    t = np.asarray(t_us_or_s, dtype=np.float64) * scale
    values = np.asarray(values, dtype=float)
    if t.size == 0:
        raise DataError(f"{where}: {name} has no samples")
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise DataError(f"{where}: {name}: non-finite value at t = {t[i]:.6f} s (sample {i})")
    order = np.argsort(t, kind="stable")
    if not (order == np.arange(t.size)).all():
        i = int(np.argmax(np.diff(t) < 0)) + 1
        raise DataError(f"{where}: {name}: time goes backwards at t = {t[i]:.6f} s (sample {i})")
    keep = np.concatenate([[True], np.diff(t) > 0])
    note = None
    if not keep.all():
        note = f"{name}: {int((~keep).sum())} sample(s) with a repeated time stamp dropped"
    return Series(name, t[keep], values[keep]), note


def window(s: Series, t_lo: float, t_hi: float, where: str, max_gap_s: float | None,
           margin: int = 20) -> Series:
    """The part of s that a replay of [t_lo, t_hi] uses (with `margin` samples either side, so the fit's
    ends lie outside the span), checked for gaps."""
    lo = max(int(np.searchsorted(s.t, t_lo, side="right")) - 1, 0)
    hi = min(int(np.searchsorted(s.t, t_hi, side="left")) + 1, s.t.size)
    i0, i1 = max(lo - margin, 0), min(hi + margin, s.t.size)
    # the margins stop at a gap: a gap outside the span does not matter (a replay split at gaps ends there)
    if s.t.size > 1:
        limit = gap_limit(s, max_gap_s)
        before = np.nonzero(np.diff(s.t[i0:lo + 1]) > limit)[0]
        if before.size:
            i0 += int(before[-1]) + 1
        after = np.nonzero(np.diff(s.t[hi - 1:i1]) > limit)[0]
        if after.size:
            i1 = hi + int(after[0])
    part = Series(s.name, s.t[i0:i1], s.values[i0:i1])
    check_gaps(part, where, max_gap_s)
    return part


def gap_limit(s: Series, max_gap_s: float | None) -> float:
    """The longest step between samples that is not a gap: max_gap_s, or GAP_FACTOR times the median step."""
    return GAP_FACTOR * float(np.median(np.diff(s.t))) if max_gap_s is None else max_gap_s


def segments(motion: "LogMotion", max_gap_s: float | None, t_lo: float | None = None,
             t_hi: float | None = None) -> list[tuple[float, float]]:
    """The spans [first, last] (s, log clock) where both position and attitude are logged without a gap, within
    [t_lo, t_hi] when given: a replay split at gaps runs one scene per span."""
    start = max(motion.position.t[0], motion.attitude.t[0])
    stop = min(motion.position.t[-1], motion.attitude.t[-1])
    if t_lo is not None:
        start = max(start, t_lo)
    if t_hi is not None:
        stop = min(stop, t_hi)
    holes = []
    for s in (motion.position, motion.attitude):
        steps = np.diff(s.t)
        for i in np.nonzero(steps > gap_limit(s, max_gap_s))[0]:
            holes.append((float(s.t[i]), float(s.t[i + 1])))
    spans, lo = [], float(start)
    for a, b in sorted(holes):
        if a > lo and a <= stop:
            spans.append((lo, a))
        lo = max(lo, b)
    if lo < stop:
        spans.append((lo, float(stop)))
    return spans


def check_gaps(s: Series, where: str, max_gap_s: float | None) -> None:
    if s.t.size < 2:
        raise DataError(f"{where}: {s.name} has {s.t.size} sample(s); a motion needs more")
    steps = np.diff(s.t)
    limit = gap_limit(s, max_gap_s)
    too_long = steps > limit
    if too_long.any():
        i = int(np.argmax(too_long))
        raise DataError(f"{where}: {s.name}: no sample for {steps[i]:.3f} s after t = {s.t[i]:.6f} s (longer "
                        f"than the {'given' if max_gap_s is not None else 'default'} max_gap_s = {limit:.3g} s; "
                        "raise trajectory.max_gap_s, or replay a part with scene.t0_s and scene.duration_s)")


def require(module: str, what: str):
    """Import an optional reader library, or say which extra provides it."""
    import importlib
    try:
        return importlib.import_module(module)
    except ImportError:
        raise DataError(f"reading {what} needs the Python package '{module.split('.')[0]}': "
                        "pip install 'imu-emulator[logs]'") from None
