"""Frame conversions, vectorized over leading axes: geodetic <-> ECEF <-> local NED/ENU <-> ECI, and attitude
as direction cosine matrix, z-y-x Euler angles and quaternion (with scipy's Rotation for the rest).

Conventions, stated in the names the way scipy's Rotation states its own:
- geodetic: latitude and longitude in degrees (WGS-84, imu_emulator.geo.wgs84), height above the ellipsoid in m.
- ECEF: WGS-84 Earth-centred Earth-fixed, metres. Local frames are tangent at an `origin` = (lat_deg, lon_deg,
  height_m): NED = north, east, down; ENU = east, north, up.
- ECI: axes on ECEF's at t = 0 s, turned by the Earth rotation angle omega_ie t about z (no precession,
  nutation or polar motion). The angle is reduced exactly, so t = 1e9 s is as good as t = 1 s.
- `ned_from_ecef_matrix(lat, lon)` is C_e^n: it maps ECEF components of a vector to NED components; its
  transpose maps back. Matrices named `x_from_y` map y-components to x-components.
- Attitude: R = Rz(yaw) Ry(pitch) Rx(roll) maps body axes to navigation axes (scipy:
  Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()). Quaternions are scalar first (w, x, y, z),
  Hamilton, q ⊗ v ⊗ q* maps body to navigation, w >= 0; scipy's are scalar last (`to_scipy`/`from_scipy`).
  DCM -> quaternion takes the largest of the four components (Shepperd), accurate near 180°.
"""
from __future__ import annotations

import numpy as np

from imu_emulator.geo import wgs84
from imu_emulator.geo.rotations import euler_to_matrix, matrix_to_euler, matrix_to_quat, quat_to_matrix

# Attitude, under names that say the convention (the implementations live in imu_emulator.geo.rotations).
dcm_from_euler_zyx = euler_to_matrix          # (..., 3) roll, pitch, yaw (rad) -> (..., 3, 3) body -> nav
euler_zyx_from_dcm = matrix_to_euler          # inverse; at pitch ±90° roll is 0 and yaw holds yaw ∓ roll
quat_from_dcm = matrix_to_quat                # (..., 3, 3) -> (..., 4) w, x, y, z with w >= 0
dcm_from_quat = quat_to_matrix                # normalizes first


def quat_from_euler_zyx(euler) -> np.ndarray:
    return quat_from_dcm(dcm_from_euler_zyx(euler))


def euler_zyx_from_quat(q) -> np.ndarray:
    return euler_zyx_from_dcm(dcm_from_quat(q))


def to_scipy(q):
    """Scalar-first quaternions (body -> nav) as a scipy Rotation (which stores scalar last)."""
    from scipy.spatial.transform import Rotation
    q = np.asarray(q, dtype=float)
    return Rotation.from_quat(np.concatenate([q[..., 1:], q[..., :1]], axis=-1))


def from_scipy(rotation) -> np.ndarray:
    """A scipy Rotation -> scalar-first quaternions with w >= 0."""
    q = np.asarray(rotation.as_quat())
    q = np.concatenate([q[..., 3:], q[..., :3]], axis=-1)
    return np.where(q[..., :1] < 0, -q, q)


# ENU/FLU <-> NED/FRD: x_N = y_E, y_E = x_N, z_D = -z_U; body forward-left-up <-> forward-right-down
NED_FROM_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FRD_FROM_FLU = np.diag([1.0, -1.0, -1.0])


def ned_frd_dcm_from_enu_flu(dcm) -> np.ndarray:
    """Body (forward-left-up) -> ENU attitude as body (forward-right-down) -> NED; its own inverse."""
    return NED_FROM_ENU @ np.asarray(dcm, dtype=float) @ FRD_FROM_FLU


# --- positions -------------------------------------------------------------------------------------------

def geodetic_to_ecef(lat_deg, lon_deg, h_m) -> np.ndarray:
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    sl = np.sin(lat)
    n = wgs84.A / np.sqrt(1.0 - wgs84.E2 * sl * sl)
    h_m = np.asarray(h_m, dtype=float)
    return np.stack([(n + h_m) * np.cos(lat) * np.cos(lon), (n + h_m) * np.cos(lat) * np.sin(lon),
                     (n * (1.0 - wgs84.E2) + h_m) * sl], axis=-1)


def ecef_to_geodetic(xyz) -> np.ndarray:
    """(..., 3) ECEF m -> (..., 3) latitude deg, longitude deg, height m: Bowring's start, then updates of
    tan L written with sin/cos (no 1/cos L: exact at the poles); the kernel's scheme (effects/_earth.py,
    which explains the count), with one update more."""
    xyz = np.asarray(xyz, dtype=float)
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    p = np.hypot(x, y)
    u = np.hypot(p * wgs84.B, z * wgs84.A)
    cu, su = p * wgs84.B / u, z * wgs84.A / u
    s, c = z + wgs84.EP2 * wgs84.B * su ** 3, p - wgs84.E2 * wgs84.A * cu ** 3
    for i in range(4):
        r = np.hypot(c, s)
        sl, cl = s / r, c / r
        w = np.sqrt(1.0 - wgs84.E2 * sl * sl)
        h = p * cl + z * sl - wgs84.A * w
        if i < 3:
            c, s = p * (1.0 - wgs84.E2 * wgs84.A / (wgs84.A + h * w)), z
    return np.stack([np.degrees(np.arctan2(s, c)), np.degrees(np.arctan2(y, x)), h], axis=-1)


def ned_from_ecef_matrix(lat_deg, lon_deg) -> np.ndarray:
    """C_e^n (..., 3, 3): rows are the north, east and down directions in ECEF."""
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    zero = np.zeros_like(sl)
    return np.stack([np.stack([-sl * co, -sl * so, cl], -1), np.stack([-so, co, zero], -1),
                     np.stack([-cl * co, -cl * so, -sl], -1)], axis=-2)


def enu_from_ecef_matrix(lat_deg, lon_deg) -> np.ndarray:
    return NED_FROM_ENU @ ned_from_ecef_matrix(lat_deg, lon_deg)


def ecef_to_ned(xyz, origin) -> np.ndarray:
    """ECEF positions -> NED at `origin` (lat deg, lon deg, h m)."""
    d = np.asarray(xyz, dtype=float) - geodetic_to_ecef(*origin)
    return np.einsum("ij,...j->...i", ned_from_ecef_matrix(origin[0], origin[1]), d)


def ned_to_ecef(ned, origin) -> np.ndarray:
    return geodetic_to_ecef(*origin) + np.einsum("ji,...j->...i", ned_from_ecef_matrix(origin[0], origin[1]),
                                                 np.asarray(ned, dtype=float))


def ecef_to_enu(xyz, origin) -> np.ndarray:
    return ecef_to_ned(xyz, origin) @ NED_FROM_ENU.T


def enu_to_ecef(enu, origin) -> np.ndarray:
    return ned_to_ecef(np.asarray(enu, dtype=float) @ NED_FROM_ENU.T, origin)


def local_to_ecef(position, frame: str, origin) -> np.ndarray:
    """Positions in a scene frame ("ENU" or "NED" tangent at origin, or "ECEF") -> ECEF."""
    if frame == "ECEF":
        return np.asarray(position, dtype=float)
    return enu_to_ecef(position, origin) if frame == "ENU" else ned_to_ecef(position, origin)


# --- ECI --------------------------------------------------------------------------------------------------

# omega_ie / 2pi as a double-double (hi + lo), from mpmath at 40 digits:
# x = mpmath.mpf("7.292115e-5") / (2 * mpmath.pi); hi = float(x); lo = float(x - hi)
_CYCLES_PER_S = 1.1605761478445564e-05
_CYCLES_LO = -4.75015178510118e-22


def earth_rotation_angle(t) -> np.ndarray:
    """omega_ie t reduced to [0, 2 pi), exact to the last bits for any float t: t times omega_ie/2pi as a
    double-double (Dekker's error-free product), the whole cycles dropped before rounding."""
    t = np.asarray(t, dtype=float)
    hi = _CYCLES_PER_S
    p = t * hi
    split = 134217729.0
    th = t * split - (t * split - t)
    tl = t - th
    hh = hi * split - (hi * split - hi)
    hl = hi - hh
    err = ((th * hh - p) + th * hl + tl * hh) + tl * hl
    cycles = (p - np.floor(p)) + (err + t * _CYCLES_LO)
    return 2.0 * np.pi * (cycles - np.floor(cycles))


def ecef_from_eci_matrix(t) -> np.ndarray:
    """C_i^e (..., 3, 3) at scene time t."""
    theta = earth_rotation_angle(t)
    c, s = np.cos(theta), np.sin(theta)
    zero, one = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, s, zero], -1), np.stack([-s, c, zero], -1), np.stack([zero, zero, one], -1)],
                    axis=-2)


def eci_to_ecef(xyz, t) -> np.ndarray:
    return np.einsum("...ij,...j->...i", ecef_from_eci_matrix(t), np.asarray(xyz, dtype=float))


def ecef_to_eci(xyz, t) -> np.ndarray:
    return np.einsum("...ji,...j->...i", ecef_from_eci_matrix(t), np.asarray(xyz, dtype=float))
