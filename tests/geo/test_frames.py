"""imu_emulator.geo.frames against independent implementations: pymap3d for geodetic/ECEF/local positions and
vectors, scipy's Rotation for attitude, mpmath for the Earth rotation angle far from t = 0."""
from __future__ import annotations

import mpmath
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_emulator.geo import frames

pymap3d = pytest.importorskip("pymap3d")


def _points(n=200, seed=5):
    """Random points, plus the poles, the antimeridian from both sides, the equator and heights from the sea
    floor to low orbit."""
    rng = np.random.default_rng(seed)
    lat = np.degrees(np.arcsin(rng.uniform(-1, 1, n)))
    lon = rng.uniform(-180, 180, n)
    h = rng.uniform(-1e4, 1e6, n)
    special = np.array([[90.0, 0.0, 0.0], [-90.0, 37.0, 100.0], [89.9999999, 180.0, 10.0], [0.0, 180.0, 0.0],
                        [0.0, -180.0, 5e3], [12.0, 179.9999999, 0.0], [-12.0, -179.9999999, 1e5],
                        [0.0, 0.0, 0.0], [45.0, 90.0, 1e4], [-60.0, -45.0, 1e4]])
    return np.vstack([np.column_stack([lat, lon, h]), special])


def _angle_diff_deg(a, b):
    return (np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0


def test_geodetic_ecef_round_trip_matches_pymap3d():
    pts = _points()
    ecef = frames.geodetic_to_ecef(pts[:, 0], pts[:, 1], pts[:, 2])
    want = np.array([pymap3d.geodetic2ecef(*p) for p in pts])
    np.testing.assert_allclose(ecef, want, rtol=0, atol=1e-6)
    back = frames.ecef_to_geodetic(want)   # pymap3d's ECEF (its forward formula is closed form, exact)
    # 1e-12 rad in latitude; longitude is undefined at the poles (compare it elsewhere)
    assert np.max(np.abs(np.radians(back[:, 0] - pts[:, 0]))) < 1e-12
    away = np.abs(pts[:, 0]) < 90.0
    assert np.max(np.abs(np.radians(_angle_diff_deg(back[away, 1], pts[away, 1])))) < 1e-12
    np.testing.assert_allclose(back[:, 2], pts[:, 2], rtol=0, atol=1e-6)
    # pymap3d's own inverse stops iterating earlier: it is within 2e-9 rad of the input, we within 1e-12
    theirs = np.array([pymap3d.ecef2geodetic(*x) for x in ecef])
    assert np.max(np.abs(np.radians(theirs[:, 0] - pts[:, 0]))) < 2e-9
    np.testing.assert_allclose(back[:, 2], theirs[:, 2], rtol=0, atol=1e-6)


@pytest.mark.parametrize("local", ["ned", "enu"])
def test_local_frames_match_pymap3d(local):
    rng = np.random.default_rng(9)
    origins = _points(20, seed=11)
    for origin in origins:
        pts = rng.normal(0, 2e4, (30, 3))
        to_ecef, from_ecef = getattr(frames, f"{local}_to_ecef"), getattr(frames, f"ecef_to_{local}")
        ecef = to_ecef(pts, origin)
        theirs = np.array([getattr(pymap3d, f"{local}2ecef")(*p, *origin) for p in pts])
        np.testing.assert_allclose(ecef, theirs, rtol=0, atol=1e-6)
        np.testing.assert_allclose(from_ecef(ecef, origin), pts, rtol=0, atol=1e-6)
        # vectors: the rotation alone (pymap3d's ecef2nedv / ecef2enuv)
        v = rng.normal(0, 100, 3)
        mine = getattr(frames, f"{local}_from_ecef_matrix")(origin[0], origin[1]) @ v
        np.testing.assert_allclose(mine, getattr(pymap3d, f"ecef2{local}v")(*v, origin[0], origin[1]), atol=1e-9)


def test_earth_rotation_angle_is_exact_far_from_zero():
    mpmath.mp.dps = 50
    w = mpmath.mpf("7.292115e-5")
    for t in (0.0, 1.0, 86164.0905, 3.0e7, 1.23456789e9, -5.5e8):
        want = float(mpmath.fmod(w * mpmath.mpf(t), 2 * mpmath.pi) % (2 * mpmath.pi))
        got = float(frames.earth_rotation_angle(t))
        assert abs(got - want) < 4e-16 * 2 * np.pi, t
    # ECI <-> ECEF: a rotation about z by that angle (scipy), and back
    t = np.array([0.0, 1e3, 3.0e7])
    x = np.array([[7e6, 1e5, -2e6]] * 3)
    angle = frames.earth_rotation_angle(t)
    np.testing.assert_allclose(frames.eci_to_ecef(x, t), Rotation.from_rotvec(np.outer(-angle, [0, 0, 1])).apply(x),
                               rtol=0, atol=1e-8)
    np.testing.assert_allclose(frames.ecef_to_eci(frames.eci_to_ecef(x, t), t), x, rtol=0, atol=1e-8)


def _attitudes():
    rng = np.random.default_rng(2)
    q = rng.normal(size=(300, 4))
    singular = Rotation.from_euler("ZYX", [[30, 90, 0], [-120, -90, 0], [180, 0, 0], [0, 0, 180], [0, 180, 0],
                                           [90, 45, 180], [179.9999, 0, 0]], degrees=True)
    return np.vstack([Rotation.from_quat(q).as_matrix(), singular.as_matrix()])


def test_attitude_conversions_match_scipy_and_round_trip():
    dcm = _attitudes()
    rot = Rotation.from_matrix(dcm)
    # quaternion: same rotation as scipy's, scalar first, w >= 0
    q = frames.quat_from_dcm(dcm)
    assert np.all(q[:, 0] >= 0)
    np.testing.assert_allclose(frames.dcm_from_quat(q), dcm, rtol=0, atol=1e-14)
    np.testing.assert_allclose(frames.to_scipy(q).as_matrix(), dcm, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.abs(np.sum(frames.from_scipy(rot) * q, axis=1)), 1.0, rtol=0, atol=1e-14)
    # Euler z-y-x: scipy's "ZYX" (intrinsic yaw, pitch, roll) gives the same matrix
    euler = frames.euler_zyx_from_dcm(dcm)
    np.testing.assert_allclose(frames.dcm_from_euler_zyx(euler), dcm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(Rotation.from_euler("ZYX", euler[:, ::-1]).as_matrix(), dcm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(frames.dcm_from_quat(frames.quat_from_euler_zyx(euler)), dcm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(frames.dcm_from_euler_zyx(frames.euler_zyx_from_quat(q)), dcm, rtol=0, atol=1e-12)


def test_enu_flu_attitude_as_ned_frd():
    """Level, facing north: yaw 90° in ENU (from east) is yaw 0 in NED."""
    enu = frames.dcm_from_euler_zyx([0.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(frames.ned_frd_dcm_from_enu_flu(enu), np.eye(3), atol=1e-15)
    dcm = _attitudes()[:20]
    np.testing.assert_allclose(frames.ned_frd_dcm_from_enu_flu(frames.ned_frd_dcm_from_enu_flu(dcm)), dcm,
                               atol=1e-15)
