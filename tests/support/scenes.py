"""Scenes built in code, one way: each test states what it varies (rates, motion, IMUs, effects) and this
assembles the table scene_from_dict validates, so no test keeps its own copy of the layout."""
from __future__ import annotations

from imu_emulator import scene_from_dict

STATIC = {"shape": "static"}
AT_ORIGIN = {"x": "0", "y": "0", "z": "0"}
LEVEL = {"roll": "0", "pitch": "0", "yaw": "0"}


def yaw_at(rate_rad_s: float) -> dict:
    """Level, turning about the vertical at a constant rate (rad/s)."""
    return {"roll": "0", "pitch": "0", "yaw": f"{rate_rad_s!r}*t"}


def scene_table(*, trajectory=STATIC, attitude=None, imus=({"name": "imu0"},), effects=(), **head) -> dict:
    """The raw table: [scene] from `head` (rate_hz, duration_s, seed, t0_s, frame, ...), `effects` either names
    (each switched on) or a table as written; no [attitude] unless given."""
    table = {"scene": dict(head), "trajectory": dict(trajectory), "imu": [dict(imu) for imu in imus],
             "effects": dict(effects) if isinstance(effects, dict) else {name: True for name in effects}}
    if attitude is not None:
        table["attitude"] = dict(attitude)
    return table


def scene(**parts):
    """The validated Scene of scene_table(**parts)."""
    return scene_from_dict(scene_table(**parts))
