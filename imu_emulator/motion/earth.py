"""The Earth under the motion: ECI and geodetic trajectories as ECEF expressions, and the geometry lines the
kernel runs after the motion whenever the Earth model is on.

With the Earth model on (frame ECEF or ECI, a geodetic trajectory, or any of effects.earth_rate,
effects.coriolis, effects.gravity with gravity_model = "wgs84"), the trajectory is Cartesian in the scene's
frame: ENU/NED is the tangent frame fixed to the Earth at [scene] origin, ECEF is ECEF; ECI and geodetic
trajectories are rewritten as ECEF in sympy (exact derivatives; sin/cos of omega_ie t take the motion's exact
phase reduction, so t far from zero stays exact). The attitude is relative to the local level frame at the
current position (NED, or ENU when the scene's frame is ENU), so the navigation stage works in that frame:
geometry_lines convert the position to geodetic (latitude, longitude, height), resolve velocity and
acceleration in local NED (e_vn.., e_an..), and hand the navigation stage the Earth-fixed acceleration in the
level axes as ax ay az. The Earth effects (imu_emulator/effects/earth_rate.py, coriolis.py, gravity.py) read:
    e_sl e_cl (sin, cos latitude), e_so e_co (longitude), e_h (height, m), e_w = sqrt(1 - e2 sin^2 L),
    e_rn e_re (R_N + h, R_E + h), e_vn e_ve e_vd (Earth-referenced velocity, local NED).
The formulas are written once, in NED (Groves 2nd ed. §2.4, §5.4); `level` maps NED components to the scene's
level axes (ENU: x = E, y = N, z = -D). Those helpers and the rates the Earth effects add (omega_ie^n: earth_rate,
rho: coriolis) live with the effects (imu_emulator/effects/_earth.py and the effect modules); this module reads
them for tangent attitude and [attitude] reference.

Tangent attitude (tangent_level_lines) follows the Earth-referenced velocity in the local level frame, with
the frame's own turning in its derivatives; [attitude] reference = "ECEF" | "ECI" (reference_lines) turns
an attitude given w.r.t. those axes into the local level one after R, w and alpha are formed.

ECI here has its axes on ECEF's at scene time t = 0 and turns by the Earth rotation angle theta = omega_ie t
about z (no precession, nutation or polar motion: the issue's ECI).
"""
from __future__ import annotations

import numpy as np

from imu_emulator.effects._earth import cross, level, ned
from imu_emulator.effects.coriolis import TRANSPORT_RATE, rho_lines
from imu_emulator.effects.earth_rate import EARTH_RATE, earth_rate_lines
from imu_emulator.geo import wgs84
from imu_emulator.motion import phases
from imu_emulator.scene.earth import position_frame

#: updates of the geodetic latitude after Bowring's start (tan L from the parametric latitude u, tan u =
#: a z / (b p)): the start is within 1e-13 rad at 10 km, 1e-9 at 1000 km, 4e-7 at 40 000 km, and each update
#: (tan L = z / (p (1 - e2 N / (N + h)))) squares the error times about e2, so two reach 1e-15 rad from the
#: ground to beyond geostationary height (imu_emulator.geo.frames runs the same scheme; tests/geo/test_frames.py)
GEODETIC_UPDATES = 2


def tangent_to_ecef(frame: str, origin) -> tuple[np.ndarray, np.ndarray]:
    """(r0, C): ECEF position of the frame's origin and the matrix whose columns are its axes in ECEF."""
    if frame in ("ECEF", "ECI"):     # ECI trajectories reach the kernel as ECEF (imu_emulator.motion.code)
        return np.zeros(3), np.eye(3)
    from imu_emulator.geo import frames   # numba (rotations) only when a kernel is generated
    local = frames.enu_from_ecef_matrix if frame == "ENU" else frames.ned_from_ecef_matrix
    return frames.geodetic_to_ecef(*origin), local(origin[0], origin[1]).T


def origin_terms(scene, number=repr):
    """The source of r0 and C (tangent_to_ecef) for the kernel: number(value) for each element, except the exact
    zeros (None: the term is left out, since 0 * x is not folded: x may be inf) and C's exact ones ("1": x itself).
    Which elements are 0 or 1 is the source's structure; the codegen passes a run-time parameter as `number`
    (imu_emulator.codegen.plan), so another origin reuses the kernel."""
    r0, c = tangent_to_ecef(position_frame(scene), scene.origin)
    return ([None if v == 0.0 else number(float(v)) for v in r0],
            [[None if v == 0.0 else "1" if v == 1.0 else number(float(v)) for v in row] for row in c])


def _affine(out: str, r0, c, names) -> list[str]:
    """out{x,y,z} = r0 + C @ names from origin_terms' sources (r0 None: no offset)."""
    lines = []
    for i, axis in enumerate("xyz"):
        terms = [r0[i]] if r0 is not None and r0[i] is not None else []
        terms += [names[j] if c[i][j] == "1" else f"{c[i][j]} * {names[j]}" for j in range(3) if c[i][j] is not None]
        lines.append(f"{out}{axis} = {' + '.join(terms) or '0.0'}")
    return lines


def geometry_lines(scene, jerk: bool = False, origin=None) -> list[str]:
    """The Earth geometry, after the motion's lines: geodetic position, local-NED velocity and acceleration
    (e_*; and jerk e_jn.. with `jerk`), and ax ay az replaced by the Earth-fixed acceleration in the level
    axes (the navigation stage's f starts from them). `origin`: origin_terms' sources (default: literals)."""
    r0, c = origin or origin_terms(scene)
    a, e2 = repr(wgs84.A), repr(wgs84.E2)
    lines = _affine("e_r", r0, c, ("px", "py", "pz")) + _affine("e_v", None, c, ("vx", "vy", "vz"))
    lines += _affine("e_a", None, c, ("ax", "ay", "az"))
    if jerk:
        lines += _affine("e_j", None, c, ("jx", "jy", "jz"))
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
    for vec in ("v", "a", "j") if jerk else ("v", "a"):
        for axis, row in rows.items():
            terms = [f"({r}) * e_{vec}{c}" for r, c in zip(row, "xyz") if r is not None]
            lines.append(f"e_{vec}{axis} = {' + '.join(terms)}")
    fx, fy, fz = level(scene, "e_an", "e_ae", "e_ad")
    return lines + [f"ax = {fx}", f"ay = {fy}", f"az = {fz}"]


def tangent_level_lines(scene) -> list[str]:
    """Velocity and its first two time derivatives as components in the local level frame at the current
    position (t_v.., t_a.., t_j.. in the scene's level axes), for tangent attitude: heading and pitch
    follow the Earth-referenced velocity over the curved Earth. After geometry_lines(scene, jerk=True).

    The level frame turns at rho = omega_en^n relative to the Earth (C_e^n' = -[rho x] C_e^n), so the NED
    components v^n = C_e^n v^e change as v^n' = a^n - rho x v^n and v^n'' = j^n - rho x a^n - rho' x v^n -
    rho x v^n', with a^n, j^n the Earth-fixed acceleration and jerk resolved in NED (e_a.., e_j..).
    rho = (v_E / (R_E + h), -v_N / (R_N + h), -v_E tan L / (R_E + h)) (Groves 2nd ed. eq. 5.44), and rho'
    follows from L' = v_N / (R_N + h), h' = -v_D, dR_E/dL = a e2 sin L cos L / w^3 and
    dR_N/dL = 3 a (1 - e2) e2 sin L cos L / w^5 (w = sqrt(1 - e2 sin^2 L)). tan L: the level frame's
    heading is undefined at the poles."""
    lines = rho_lines()
    lines += cross("t_ra", ned("t_rh"), ned("e_a")) + cross("t_rd", ned("t_rh"), ned("t_d"))
    lines += cross("t_rq", ned("t_rp"), ned("e_v"))
    lines += [f"t_j{axis} = e_j{axis} - t_ra{axis} - t_rq{axis} - t_rd{axis}" for axis in "ned"]
    for out, src in (("t_v", "e_v"), ("t_a", "t_d"), ("t_j", "t_j")):
        lines += [f"{out}{axis} = {value}" for axis, value in zip("xyz", level(scene, *ned(src)))]
    return lines


#: the kernel's rate of the body w.r.t. the local level frame, body axes, where w is not it (reference_lines)
LEVEL_RATE = ("m_lx", "m_ly", "m_lz")


def _sum(name: str, vectors) -> list[str]:
    """name{n,e,d} = the sum of NED triples."""
    return [f"{name}{axis} = {' + '.join(v[i] for v in vectors)}" for i, axis in enumerate("ned")]


def _to_body(scene, name: str) -> list[str]:
    """name_b{0,1,2} = R^T (the NED triple name{n,e,d} in the level axes)."""
    lx, ly, lz = level(scene, *ned(name))
    return [f"{name}b{c} = r0{c} * ({lx}) + r1{c} * ({ly}) + r2{c} * ({lz})" for c in "012"]


def reference_lines(scene, angles: bool, index: int | None) -> list[str]:
    """Lines after R, w, alpha are formed from the scene's attitude relative to X = [attitude] reference (ECEF,
    or ECI with its rotation angle in phase slot `index`): they turn them into the attitude relative to the
    local level frame L at the current position, which the navigation stage works in.

    R_Lb = C_X^L R_Xb. The gyros then add R^T w_n, the level frame's rate the Earth effects name (omega_ie^n
    with earth_rate, rho = omega_en^n with coriolis), so w = omega_Xb - R^T u with u the part of omega_XL^L
    those effects add back: rho (coriolis) for X = ECEF, and omega_ie^n (earth_rate) + rho (coriolis) for ECI.
    The gyros read omega_Xb + omega_iX as far as the named effects reach (ECI: omega_ib; ECEF with earth_rate:
    omega_eb + omega_ie). alpha = d/dt w = alpha_Xb - (R^T u' - omega_Lb x R^T u), with u' the rate of change
    of u's components (EARTH_RATE, TRANSPORT_RATE) and omega_Lb = omega_Xb - R^T omega_XL^L (LEVEL_RATE, R's
    own rate: R' = R [omega_Lb x]; it equals w when u is all of omega_XL^L)."""
    eci = scene.attitude_reference == "ECI"
    lines = rho_lines() + earth_rate_lines()
    if eci:   # C_i^n = C_e^n R_z(-theta): C_e^n at the celestial longitude lon + theta
        lines += [f"m_co = e_co * cph{index} - e_so * sph{index}", f"m_so = e_so * cph{index} + e_co * sph{index}"]
    else:
        lines += ["m_co = e_co", "m_so = e_so"]
    rows = {"n": ("-e_sl * m_co", "-e_sl * m_so", "e_cl"), "e": ("-m_so", "m_co", "0.0"),
            "d": ("-e_cl * m_co", "-e_cl * m_so", "-e_sl")}
    lines += [f"m_{axis}{c} = {value}" for axis, row in rows.items() for c, value in zip("xyz", row)]
    level_rows = level(scene, "m_n", "m_e", "m_d")   # each a row name, "-(m_d)" for ENU's up
    for i, row in enumerate(level_rows):
        sign, name = ("-", row[2:-1]) if row.startswith("-(") else ("", row)
        for j in range(3):
            lines.append(f"q{i}{j} = {sign}({name}x * r0{j} + {name}y * r1{j} + {name}z * r2{j})")
    lines += [f"r{i}{j} = q{i}{j}" for i in range(3) for j in range(3)]
    frame_rate = [TRANSPORT_RATE] + ([EARTH_RATE] if eci else [])       # omega_XL^L
    lines += _sum("m_x", [rate for rate, _ in frame_rate]) + _to_body(scene, "m_x")
    lines += [f"{lw} = w{axis} - m_xb{c}" for lw, axis, c in zip(LEVEL_RATE, "xyz", "012")]
    u = [TRANSPORT_RATE] if "coriolis" in scene.effects else []
    if eci and "earth_rate" in scene.effects:
        u.append(EARTH_RATE)
    if u:
        lines += _sum("m_u", [rate for rate, _ in u]) + _sum("m_du", [derivative for _, derivative in u])
        lines += _to_body(scene, "m_u") + _to_body(scene, "m_du")
        lines += [f"w{axis} -= m_ub{c}" for c, axis in zip("012", "xyz")]
        lines += cross("m_wu", LEVEL_RATE, ("m_ub0", "m_ub1", "m_ub2"))
        lines += [f"al{axis} -= m_dub{c} - m_wu{ned_axis}" for c, axis, ned_axis in zip("012", "xyz", "ned")]
    if angles:
        lines += ["roll = math.atan2(r21, r22)", "pitch = math.atan2(-r20, math.hypot(r21, r22))",
                  "yaw = math.atan2(r10, r00)"]
    return lines


def inertial_rate_lines(level_rate=("wx", "wy", "wz")) -> list[str]:
    """After the navigation stage: its rate w_n (wn.., level axes; the Earth effects add omega_ie^n and rho)
    and the rate of change of those components (dwn..) in body axes: wb.. = R^T w_n, which the gyros add to
    w, and gal.. = d/dt (w + R^T w_n) = alpha + R^T w_n' - omega_Lb x R^T w_n, the inertial angular
    acceleration the lever arm and vibration read (R' = R [omega_Lb x], omega_Lb = `level_rate`: w, or
    LEVEL_RATE with an [attitude] reference)."""
    lines = [f"wb{c} = r0{i} * wnx + r1{i} * wny + r2{i} * wnz" for i, c in enumerate("xyz")]
    for i, c in enumerate("xyz"):   # component i of omega_Lb x wb
        j, k = (i + 1) % 3, (i + 2) % 3
        cross = f"{level_rate[j]} * wb{'xyz'[k]} - {level_rate[k]} * wb{'xyz'[j]}"
        lines.append(f"gal{c} = al{c} + (r0{i} * dwnx + r1{i} * dwny + r2{i} * dwnz) - ({cross})")
    return lines


#: omega_ie as the exact decimal WGS-84 states (phase constants are formed from it exactly)
OMEGA_IE_TEXT = "7.292115e-5"


def sampled_eci_lines(scene, index: int) -> tuple[dict, list[str], list[str]]:
    """(constants, phase lines, lines) turning the kernel's sampled ECI p, v, a[, j] into ECEF in place.

    The Earth rotation angle theta = omega_ie t is phase slot `index`, reduced exactly like the symbolic
    path's periodic phases (imu_emulator.motion.phases). With R = R_z(-theta), r_e = R r_i and d/dt (R u) =
    R (u' - w x u), so the k-th derivative of r_e is R D^k r_i, D u = u' - w x u, w = (0, 0, omega_ie):
    v_e = R (v - w x r), a_e = R (a - 2 w x v + w x (w x r)), j_e = R (j - 3 w x a + 3 w x (w x v) - w x (w x (w x r)))."""
    import sympy

    constants = phases.phase_constants(sympy.Rational(OMEGA_IE_TEXT), sympy.Integer(0), scene, index)
    w = float(OMEGA_IE_TEXT)
    w2, w3 = repr(w * w), repr(w * w * w)
    parts = {"p": ("px", "py"),
             "v": (f"vx + {w!r} * py", f"vy - {w!r} * px"),
             "a": (f"ax + {2 * w!r} * vy - {w2} * px", f"ay - {2 * w!r} * vx - {w2} * py")}
    if scene.attitude_mode == "tangent":
        parts["j"] = (f"jx + {3 * w!r} * ay - {3 * w * w!r} * vx - {w3} * py",
                      f"jy - {3 * w!r} * ax - {3 * w * w!r} * vy + {w3} * px")
    s, c = f"sph{index}", f"cph{index}"
    lines = [f"u{prefix}{axis} = {value}" for prefix, (ux, uy) in parts.items() for axis, value in (("x", ux), ("y", uy))]
    for prefix in parts:
        lines += [f"{prefix}x = {c} * u{prefix}x + {s} * u{prefix}y", f"{prefix}y = {c} * u{prefix}y - {s} * u{prefix}x"]
    return constants, phases.phase_lines(index), lines


def eci_to_ecef(xyz, t):
    """[x, y, z] sympy expressions of t in ECI -> the same point in ECEF: r_e = R_z(-theta) r_i."""
    import sympy
    theta = sympy.Rational(OMEGA_IE_TEXT) * t
    c, s = sympy.cos(theta), sympy.sin(theta)
    x, y, z = xyz
    return [c * x + s * y, -s * x + c * y, z]


def geodetic_to_ecef(llh):
    """[lat_deg, lon_deg, height_m] sympy expressions of t -> WGS-84 ECEF x, y, z (closed form; sympy
    differentiates it exactly, and sin/cos of a latitude or longitude linear in t take the exact phase
    reduction)."""
    import sympy

    from imu_emulator.geo import wgs84
    lat, lon = (sympy.pi / 180 * e for e in llh[:2])
    h = llh[2]
    a, e2 = sympy.Float(wgs84.A, 30), sympy.Float(wgs84.E2, 30)
    n = a / sympy.sqrt(1 - e2 * sympy.sin(lat) ** 2)
    return [(n + h) * sympy.cos(lat) * sympy.cos(lon), (n + h) * sympy.cos(lat) * sympy.sin(lon),
            (n * (1 - e2) + h) * sympy.sin(lat)]
