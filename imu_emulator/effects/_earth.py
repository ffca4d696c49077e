"""The Earth under the navigation stage: the geometry the Earth effects share, printed once per kernel.

With the Earth model on (frame ECEF, or any of effects.earth_rate, effects.coriolis, effects.gravity with
gravity_model = "wgs84"), the trajectory is Cartesian in the scene's frame: ENU/NED is the tangent frame fixed
to the Earth at [scene] origin, ECEF is ECEF, and an ECI trajectory arrives here rewritten as ECEF (exactly, in
sympy: imu_emulator.motion). The attitude is relative to the local level frame at the current
position (NED, or ENU when the scene's frame is ENU), so the navigation stage works in that frame: the
prelude converts the position to geodetic (latitude, longitude, height), and resolves velocity and
acceleration in local NED (e_vn.., e_an..); f then starts as the Earth-fixed acceleration in the level frame.

The formulas are written once, in NED (Groves 2nd ed. §2.4, §5.4); `level` maps NED components to the scene's
level axes (ENU: x = E, y = N, z = -D). Variables the prelude defines, for the effects:
    e_sl e_cl (sin, cos latitude), e_so e_co (longitude), e_h (height, m), e_w = sqrt(1 - e2 sin^2 L),
    e_rn e_re (R_N + h, R_E + h), e_vn e_ve e_vd (Earth-referenced velocity, local NED).
"""
from __future__ import annotations

import numpy as np

from imu_emulator import wgs84

EARTH_EFFECTS = ("earth_rate", "coriolis")
#: updates of the geodetic latitude after Bowring's start (tan L from the parametric latitude u, tan u =
#: a z / (b p)): the start is within 1e-13 rad at 10 km, 1e-9 at 1000 km, 4e-7 at 40 000 km, and each update
#: (tan L = z / (p (1 - e2 N / (N + h)))) squares the error times about e2, so two reach 1e-15 rad from the
#: ground to beyond geostationary height (imu_emulator.frames runs the same scheme; tests/test_frames.py)
GEODETIC_UPDATES = 2
_DONE = "_earth_prelude_emitted"


def position_frame(scene) -> str:
    """The frame of the kernel's px..pz: the scene's, except ECEF for ECI (rewritten) and geodetic
    trajectories (converted to ECEF, imu_emulator.earth_motion)."""
    geodetic = getattr(scene.trajectory, "keys", ("x", "y", "z")) != ("x", "y", "z")
    return "ECEF" if geodetic or scene.frame in ("ECEF", "ECI") else scene.frame


def model_on(scene) -> bool:
    """Whether the navigation stage follows the Earth (see the module's docstring)."""
    return (position_frame(scene) == "ECEF" or any(name in scene.effects for name in EARTH_EFFECTS)
            or ("gravity" in scene.effects and scene.gravity_model == "wgs84"))


def level(scene, n: str, e: str, d: str) -> tuple[str, str, str]:
    """NED components as the scene's level axes (ENU for an ENU scene, NED otherwise)."""
    return (e, n, f"-({d})") if scene.frame == "ENU" else (n, e, d)


def tangent_to_ecef(frame: str, origin) -> tuple[np.ndarray, np.ndarray]:
    """(r0, C): ECEF position of the frame's origin and the matrix whose columns are its axes in ECEF."""
    if frame in ("ECEF", "ECI"):     # ECI trajectories reach the kernel as ECEF (imu_emulator.motion)
        return np.zeros(3), np.eye(3)
    from imu_emulator import frames   # numba (rotations) only when a kernel is generated
    local = frames.enu_from_ecef_matrix if frame == "ENU" else frames.ned_from_ecef_matrix
    return frames.geodetic_to_ecef(*origin), local(origin[0], origin[1]).T


def _affine(out: str, r0, c, names) -> list[str]:
    """out{x,y,z} = r0 + C @ names, printed without the exact zeros (0 * x is not folded: x may be inf)."""
    lines = []
    for i, axis in enumerate("xyz"):
        terms = [repr(float(r0[i]))] if r0 is not None and r0[i] != 0.0 else []
        terms += [f"{float(c[i, j])!r} * {names[j]}" if c[i, j] != 1.0 else names[j]
                  for j in range(3) if c[i, j] != 0.0]
        lines.append(f"{out}{axis} = {' + '.join(terms) or '0.0'}")
    return lines


def prelude(ctx) -> list[str]:
    """The shared geometry, the first time an Earth effect asks in this kernel; nothing after that."""
    if getattr(ctx.plan, _DONE, False):
        return []
    setattr(ctx.plan, _DONE, True)
    scene = ctx.scene
    r0, c = tangent_to_ecef(position_frame(scene), scene.origin)
    a, e2 = repr(wgs84.A), repr(wgs84.E2)
    lines = _affine("e_r", r0, c, ("px", "py", "pz")) + _affine("e_v", None, c, ("vx", "vy", "vz"))
    lines += _affine("e_a", None, c, ("ax", "ay", "az"))
    lines += [
        "e_p = math.sqrt(e_rx * e_rx + e_ry * e_ry)",
        "if e_p > 0.0:",
        "    e_co = e_rx / e_p",
        "    e_so = e_ry / e_p",
        "else:",     # on the axis longitude is undefined: take 0
        "    e_co = 1.0",
        "    e_so = 0.0",
        # Bowring's start from the parametric latitude, then tan L = z / (p (1 - e2 N / (N + h))) with
        # h = p cos L + z sin L - a w (no 1/cos L anywhere: exact at the poles)
        f"e_iu = 1.0 / math.sqrt((e_p * {wgs84.B!r}) ** 2 + (e_rz * {a}) ** 2)",
        f"e_cu = e_p * {wgs84.B!r} * e_iu",
        f"e_su = e_rz * {a} * e_iu",
        f"e_s = e_rz + {repr(wgs84.EP2 * wgs84.B)} * e_su * e_su * e_su",
        f"e_c = e_p - {repr(wgs84.E2 * wgs84.A)} * e_cu * e_cu * e_cu",
    ]
    for i in range(GEODETIC_UPDATES + 1):
        lines += [
            "e_ir = 1.0 / math.sqrt(e_c * e_c + e_s * e_s)",
            "e_sl = e_s * e_ir",
            "e_cl = e_c * e_ir",
            f"e_w = math.sqrt(1.0 - {e2} * e_sl * e_sl)",
            f"e_h = e_p * e_cl + e_rz * e_sl - {a} * e_w",
        ]
        if i < GEODETIC_UPDATES:
            lines += [f"e_c = e_p * (1.0 - {e2} * {a} / ({a} + e_h * e_w))", "e_s = e_rz"]
    lines += [
        f"e_re = {a} / e_w + e_h",
        f"e_rn = {repr(wgs84.A * (1.0 - wgs84.E2))} / (e_w * e_w * e_w) + e_h",
    ]
    # local NED at the current position: rows of C_e^n
    rows = {"n": ("-e_sl * e_co", "-e_sl * e_so", "e_cl"), "e": ("-e_so", "e_co", None),
            "d": ("-e_cl * e_co", "-e_cl * e_so", "-e_sl")}
    for vec in ("v", "a"):
        for axis, row in rows.items():
            terms = [f"({r}) * e_{vec}{c}" for r, c in zip(row, "xyz") if r is not None]
            lines.append(f"e_{vec}{axis} = {' + '.join(terms)}")
    fx, fy, fz = level(scene, "e_an", "e_ae", "e_ad")
    return lines + [f"fnx = {fx}", f"fny = {fy}", f"fnz = {fz}"]


def add(scene, target: str, n: str, e: str, d: str) -> list[str]:
    """Lines adding a NED vector to the level-axes variables target{x,y,z} (fn or wn)."""
    return [f"{target}{axis} += {value}" for axis, value in zip("xyz", level(scene, n, e, d)) if value != "0.0"]
