"""Checks of scene values that name the key in their errors ("trajectory.x", "imu[1].lever_arm_m") and state the
bound or the choices: every loader of the scene's tables (imu_emulator.scene.load, sources, imus, earth, shapes) uses
them, so a value is refused in the same words wherever it is read."""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from imu_emulator.errors import SceneError

# Time stamps t0 + k/rate are float64: the spacing of floats at the latest stamp must stay below this
# fraction of the sample period, or stamps collide (t0_s = 1e16 s: spacing 2 s, every stamp equal).
TIME_RESOLUTION = 1e-3
_INF_HINT = " (TOML reads numbers beyond 1.8e308 as inf)"


def shown_key(key) -> str:
    """A key as an error message shows it: as written when it is a plain word, else repr'd, so that a key
    holding a newline cannot break the one-line message."""
    return key if isinstance(key, str) and key.isprintable() and key and key.strip() == key else repr(key)


def subtable(raw: Mapping, key: str, where: str = "") -> dict:
    value = raw.get(key, {})
    if not isinstance(value, Mapping):
        raise SceneError(f"{where}{key}: expected a table, got {type(value).__name__}")
    return dict(value)


def no_unknown(table: Mapping, allowed: set[str], where: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SceneError(f"{where}.{shown_key(unknown[0])}: unknown key (allowed: {', '.join(sorted(allowed))})")


def number(table: Mapping, key: str, where: str, default=None, positive=False, required=False,
           bound: float | None = None, unit: str = "") -> float:
    if key not in table:
        if required:
            raise SceneError(f"{where}.{key}: missing (a number is required)")
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where}.{key}: expected a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(f"{where}.{key}: must be a finite number, got {value}{_INF_HINT}")
    if positive and value <= 0:
        raise SceneError(f"{where}.{key}: must be positive, got {value}")
    if bound is not None and abs(value) > bound:
        raise SceneError(f"{where}.{key}: {value!r} is out of range (|value| <= {bound:g}{unit})")
    return value


def vector3(table: Mapping, key: str, where: str, bound: float, unit: str) -> tuple[float, float, float]:
    value = table.get(key, [0.0, 0.0, 0.0])
    if (not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 3
            or any(isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) for v in value)):
        raise SceneError(f"{where}.{key}: expected a list of three numbers, got {value!r}")
    if not all(math.isfinite(float(v)) for v in value):
        raise SceneError(f"{where}.{key}: values must be finite numbers (each |value| <= {bound:g}{unit}), "
                         f"got {value!r}{_INF_HINT}")
    if any(abs(float(v)) > bound for v in value):
        raise SceneError(f"{where}.{key}: {list(value)!r} is out of range (each |value| <= {bound:g}{unit})")
    return tuple(float(v) for v in value)


def choice(table: Mapping, key: str, where: str, choices, default):
    value = table.get(key, default)
    if value not in choices:
        raise SceneError(f"{where}.{key}: {value!r} is not one of {', '.join(map(repr, choices))}")
    return value


def check_bound(value, bound, where: str) -> None:
    if bound is None:
        return
    limit, unit = bound
    flat = np.ravel(np.asarray(value, dtype=float))
    if np.any(np.abs(flat) > limit):
        raise SceneError(f"{where}: {value!r} is out of range (each |value| <= {limit:g}{unit})")


def check_time_resolution(t0: float, duration: float, rate: float, key: str = "scene.t0_s") -> None:
    latest = max(abs(t0), abs(t0 + duration))
    dt = 1.0 / rate
    if float(np.spacing(latest)) > TIME_RESOLUTION * dt:
        # floats below 2**(e+1) are spaced 2**(e-52) apart at most
        limit = 2.0 ** (math.floor(52 + math.log2(TIME_RESOLUTION * dt)) + 1)
        raise SceneError(f"{key}: time stamps reach {latest:g} s, where float64 time stamps are "
                         f"{float(np.spacing(latest)):g} s apart, more than {TIME_RESOLUTION:g} of the sample "
                         f"period ({dt:g} s); at {rate:g} Hz keep |t0_s| + duration_s below {limit:g} s")
