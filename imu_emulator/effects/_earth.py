"""What the Earth effects share: the geometry comes from the motion (imu_emulator.motion.earth, run whenever
the Earth model is on: scene.earth_model), the effects write their formulas once in NED and add them to the
navigation stage's level-axes variables here. The motion reads the same NED helpers and the effects' rates
(earth_rate.EARTH_RATE, coriolis.TRANSPORT_RATE) for tangent attitude and [attitude] reference."""
from __future__ import annotations

#: L' = v_N / (R_N + h), the latitude's rate (t_ld)
LATITUDE_RATE = "t_ld = e_vn / e_rn"


def level(scene, n: str, e: str, d: str) -> tuple[str, str, str]:
    """NED components as the scene's level axes (ENU for an ENU scene, NED otherwise)."""
    return (e, n, f"-({d})") if scene.frame == "ENU" else (n, e, d)


def cross(name: str, u: tuple[str, str, str], v: tuple[str, str, str]) -> list[str]:
    """name{n,e,d} = u x v (NED components)."""
    return [f"{name}n = {u[1]} * {v[2]} - {u[2]} * {v[1]}", f"{name}e = {u[2]} * {v[0]} - {u[0]} * {v[2]}",
            f"{name}d = {u[0]} * {v[1]} - {u[1]} * {v[0]}"]


def ned(name: str) -> tuple[str, str, str]:
    """The NED triple of variables name{n,e,d}."""
    return (f"{name}n", f"{name}e", f"{name}d")


def add(scene, target: str, n: str, e: str, d: str) -> list[str]:
    """Lines adding a NED vector to the level-axes variables target{x,y,z} (fn, wn or dwn)."""
    return [f"{target}{axis} += {value}" for axis, value in zip("xyz", level(scene, n, e, d)) if value != "0.0"]


def add_rate(scene, rate, derivative) -> list[str]:
    """Lines adding a rate of the navigation frame (a NED triple) to wn.. and the rate of change of its
    components to dwn.. (the lever arm's angular acceleration needs it: imu_emulator.motion.earth
    .inertial_rate_lines)."""
    return add(scene, "wn", *rate) + add(scene, "dwn", *derivative)
