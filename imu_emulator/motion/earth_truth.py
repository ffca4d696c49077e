"""--truth for scenes on the Earth: where the body is on the ellipsoid, its velocity and attitude in local NED,
and the Earth terms the kernel added, computed from the kernel's truth with imu_emulator.geo.frames (numpy, after
the kernel: the kernel itself is unchanged).

Keys added to SampleBlock.truth (each (n, 3)), and their CSV columns:
    geodetic            lat_deg lon_deg height_m    WGS-84
    position_ecef       ex ey ez                     m
    velocity_ned        vn ve vd                     Earth-referenced velocity in local NED, m/s
    velocity_ecef       vex vey vez                  m/s
    euler_ned           roll_ned pitch_ned yaw_ned   body (forward-right-down) w.r.t. local NED, rad
    earth_rate_ned      wie_n wie_e wie_d            omega_ie in local NED, rad/s
    transport_rate_ned  wen_n wen_e wen_d            omega_en (the level frame turning over the Earth), rad/s
    coriolis_ned        cor_n cor_e cor_d            2 omega_ie x v, the term added to specific force, m/s^2
    gravity_ned         g_n g_e g_d                  gravity used (WGS-84 normal or the constant), m/s^2
For ECI scenes "position" and "velocity" are turned back from the kernel's ECEF into ECI; for geodetic
trajectories they are ECEF.
"""
from __future__ import annotations

import numpy as np

from imu_emulator.geo import frames
from imu_emulator.geo import wgs84

COLUMNS = {
    "geodetic": ("lat_deg", "lon_deg", "height_m"), "position_ecef": ("ex", "ey", "ez"),
    "velocity_ned": ("vn", "ve", "vd"), "velocity_ecef": ("vex", "vey", "vez"),
    "euler_ned": ("roll_ned", "pitch_ned", "yaw_ned"), "earth_rate_ned": ("wie_n", "wie_e", "wie_d"),
    "transport_rate_ned": ("wen_n", "wen_e", "wen_d"), "coriolis_ned": ("cor_n", "cor_e", "cor_d"),
    "gravity_ned": ("g_n", "g_e", "g_d"),
}
KEYS = tuple(COLUMNS)


def conventions(scene) -> list[str]:
    """The frame and sign conventions of this scene's output, one statement a line (CSV comments, NPZ
    metadata)."""
    level = "ENU" if scene.frame == "ENU" else "NED"
    body = "forward-left-up" if level == "ENU" else "forward-right-down"
    where = {"ENU": "ENU tangent to the Earth at origin", "NED": "NED tangent to the Earth at origin",
             "ECEF": "WGS-84 ECEF", "ECI": "ECI (axes on ECEF's at t = 0 s, turning at omega_ie about z)"}
    from imu_emulator.scene.earth import position_frame
    if position_frame(scene) == "ECEF" and scene.frame != "ECI":
        where[scene.frame] = "WGS-84 ECEF" + (" (from the geodetic trajectory)" if scene.frame != "ECEF" else "")
    lines = [f"frame: trajectory px py pz, vx vy vz in {where[scene.frame]}"
             + (f" ({scene.origin[0]!r} deg, {scene.origin[1]!r} deg, {scene.origin[2]!r} m)"
                if scene.origin is not None and scene.frame in ("ENU", "NED") else ""),
             f"attitude: roll pitch yaw z-y-x, body {body} w.r.t. local level {level} at the current position; "
             "quaternions scalar first, body -> navigation",
             "accelerometers: specific force f = a - g (+g up at rest: ENU z = +g, NED z = -g)",
             "gyros: omega_ib, body w.r.t. inertial space (Earth rate and transport rate included when on)",
             f"gravity: {scene.gravity_model}" + ("" if scene.gravity_model == "wgs84"
                                                   else f" {scene.gravity_mps2!r} m/s^2"),
             "effects: " + (", ".join(sorted(scene.effects)) or "none")]
    return lines


def fill(scene, t: np.ndarray, truth: dict) -> None:
    """Add the Earth keys to one block's truth, in place (the arrays exist: Simulation allocates KEYS)."""
    from imu_emulator.motion.earth import tangent_to_ecef
    from imu_emulator.scene.earth import position_frame
    position, velocity = truth["position"], truth["velocity"]
    r0, c = tangent_to_ecef(position_frame(scene), scene.origin)
    r_e = r0 + position @ c.T
    v_e = velocity @ c.T
    llh = frames.ecef_to_geodetic(r_e)
    c_en = frames.ned_from_ecef_matrix(llh[:, 0], llh[:, 1])
    v_n = np.einsum("nij,nj->ni", c_en, v_e)
    lat, h = np.radians(llh[:, 0]), llh[:, 2]
    w_ie = np.einsum("nij,j->ni", c_en, [0.0, 0.0, wgs84.OMEGA_IE])
    r_n, r_e_radius = wgs84.radii(lat)
    w_en = np.column_stack([v_n[:, 1] / (r_e_radius + h), -v_n[:, 0] / (r_n + h),
                            -v_n[:, 1] * np.tan(lat) / (r_e_radius + h)])
    g = (wgs84.normal_gravity(lat, h) if scene.gravity_model == "wgs84" else np.full(len(t), scene.gravity_mps2))
    dcm = frames.dcm_from_euler_zyx(truth["euler"])
    if scene.frame == "ENU":
        dcm = frames.ned_frd_dcm_from_enu_flu(dcm)
    truth["geodetic"][:] = llh
    truth["position_ecef"][:] = r_e
    truth["velocity_ned"][:] = v_n
    truth["velocity_ecef"][:] = v_e
    truth["euler_ned"][:] = frames.euler_zyx_from_dcm(dcm)
    truth["earth_rate_ned"][:] = w_ie
    truth["transport_rate_ned"][:] = w_en
    truth["coriolis_ned"][:] = 2.0 * np.cross(w_ie, v_n)
    g_n = wgs84.normal_gravity_north(lat, h) if scene.gravity_model == "wgs84" else np.zeros_like(g)
    truth["gravity_ned"][:] = np.column_stack([g_n, np.zeros_like(g), g])
    if scene.frame == "ECI":
        w = np.array([0.0, 0.0, wgs84.OMEGA_IE])
        truth["position"][:] = frames.ecef_to_eci(r_e, t)
        truth["velocity"][:] = frames.ecef_to_eci(v_e + np.cross(w, r_e), t)
