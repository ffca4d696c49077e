"""What the Earth effects share: the geometry comes from the motion (imu_emulator.motion.earth, run whenever
the Earth model is on), the effects add NED vectors to the navigation stage's level-axes variables here."""
from __future__ import annotations

from imu_emulator.motion.earth import EARTH_EFFECTS, level, model_on, position_frame  # noqa: F401 (API)


def add(scene, target: str, n: str, e: str, d: str) -> list[str]:
    """Lines adding a NED vector to the level-axes variables target{x,y,z} (fn, wn or dwn)."""
    return [f"{target}{axis} += {value}" for axis, value in zip("xyz", level(scene, n, e, d)) if value != "0.0"]


def add_rate(scene, rate, derivative) -> list[str]:
    """Lines adding a rate of the navigation frame (a NED triple) to wn.. and the rate of change of its
    components to dwn.. (the lever arm's angular acceleration needs it: imu_emulator.motion.earth
    .inertial_rate_lines)."""
    return add(scene, "wn", *rate) + add(scene, "dwn", *derivative)
