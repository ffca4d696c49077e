"""The Earth under the IMU against closed forms (specs/earth.md; Groves 2nd ed. §2.4, §5.4; NIMA TR8350.2).

The references here are written from the spec's formulas with the spec's constants, in mpmath at 40 digits,
not imported from the package: a wrong constant or sign in imu_emulator.geo.wgs84 or the kernel shows up as a
mismatch.
"""
from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest

from imu_emulator import scene_from_dict
from imu_emulator.errors import SceneError
from imu_emulator.runtime.simulation import Simulation

mpmath.mp.dps = 40
A = mpmath.mpf(6378137)
F = 1 / mpmath.mpf("298.257223563")
E2 = F * (2 - F)
B = A * (1 - F)
OMEGA = mpmath.mpf("7.292115e-5")
GM = mpmath.mpf("3.986004418e14")
GAMMA_E, GAMMA_P = mpmath.mpf("9.7803253359"), mpmath.mpf("9.8321849378")


def gamma(lat_deg, h):
    """TR8350.2 eq. 4-1 (Somigliana) and 4-3 (height), from their constants."""
    s2 = mpmath.sin(mpmath.radians(lat_deg)) ** 2
    k = B * GAMMA_P / (A * GAMMA_E) - 1
    m = OMEGA ** 2 * A ** 2 * B / GM
    g0 = GAMMA_E * (1 + k * s2) / mpmath.sqrt(1 - E2 * s2)
    return g0 * (1 - 2 / A * (1 + F + m - 2 * F * s2) * h + 3 / A ** 2 * h ** 2)


def gamma_north(lat_deg, h):
    """North component of normal gravity at height h: -h / R_N dgamma_0/dL (gravity is curl-free, so
    dg_N/dh = dg_up/dx_N; Groves 2nd ed. eq. 2.142 gives the same to its rounding, -8.08e-9 h sin 2L), with
    dgamma_0/dL from mpmath's differentiation of Somigliana's formula above."""
    L = mpmath.radians(lat_deg)
    r_n = A * (1 - E2) / (1 - E2 * mpmath.sin(L) ** 2) ** mpmath.mpf(1.5)
    return -h / r_n * mpmath.diff(lambda x: gamma(mpmath.degrees(x), 0), L)


def earth_scene(frame="NED", lat=45.0, lon=10.0, h=0.0, trajectory=None, attitude=None, effects=None,
                rate_hz=10, duration_s=0.3, **head):
    return scene_from_dict({
        "scene": {"rate_hz": rate_hz, "duration_s": duration_s, "frame": frame, "gravity_model": "wgs84",
                  **({} if frame == "ECEF" else {"origin": {"lat_deg": lat, "lon_deg": lon, "height_m": h}}),
                  **head},
        "trajectory": trajectory or {"shape": "static"},
        "attitude": attitude or {"roll": "0", "pitch": "0", "yaw": "0"},
        "imu": [{"name": "imu0"}],
        "effects": effects or {"gravity": True, "earth_rate": True, "coriolis": True}})


def run(scene):
    out = Simulation(scene, attitude=False).run()
    return out.accel[0], out.gyro[0]


def test_normal_gravity_closed_values():
    from imu_emulator.geo import wgs84
    assert wgs84.normal_gravity(0.0, 0.0) == wgs84.GAMMA_E
    assert wgs84.normal_gravity(math.pi / 2, 0.0) == pytest.approx(wgs84.GAMMA_P, rel=2e-16)
    # the spec's value at 45°: 9.806 197 769...
    assert float(gamma(45, 0)) == pytest.approx(9.806197769, abs=1e-9)
    # TR8350.2 prints k = 0.00193185265241, derived from the defining constants; from the rounded gamma_e and
    # gamma_p it is 0.0019318526464 (3e-9 apart). The package forms k from gamma_e and gamma_p, which is what
    # makes gamma(90°, 0) = gamma_p exact (the issue asks for that)
    assert wgs84.K_SOMIGLIANA == pytest.approx(0.00193185265241, rel=5e-9)
    assert wgs84.M_RATIO == pytest.approx(0.00344978650684, rel=1e-11)


@pytest.mark.parametrize("lat", [0.0, 45.0, 89.9, -60.0])
@pytest.mark.parametrize("h", [0.0, 10e3])
def test_static_level_facing_north_ned(lat, h):
    """NED, body forward-right-down: omega = omega_ie (cos L, 0, -sin L), f = (-g_N(L, h), 0, -gamma(L, h))."""
    f, w = run(earth_scene("NED", lat, 123.0, h))
    L = mpmath.radians(lat)
    want_w = np.array([float(OMEGA * mpmath.cos(L)), 0.0, float(-OMEGA * mpmath.sin(L))])
    want_f = np.array([-float(gamma_north(lat, h)), 0.0, -float(gamma(lat, h))])
    np.testing.assert_allclose(w, np.broadcast_to(want_w, w.shape), rtol=0, atol=1e-12 * float(OMEGA))
    np.testing.assert_allclose(f, np.broadcast_to(want_f, f.shape), rtol=0, atol=1e-12 * want_f[2] * -1)


@pytest.mark.parametrize("lat", [0.0, 45.0, 89.9, -60.0])
@pytest.mark.parametrize("h", [0.0, 10e3])
def test_static_level_facing_north_enu(lat, h):
    """ENU, body forward-left-up facing north (yaw 90° from east): omega = omega_ie (cos L, 0, sin L),
    f = (-g_N, 0, +gamma)."""
    f, w = run(earth_scene("ENU", lat, -75.0, h, attitude={"roll": "0", "pitch": "0", "yaw": "pi/2"}))
    L = mpmath.radians(lat)
    want_w = np.array([float(OMEGA * mpmath.cos(L)), 0.0, float(OMEGA * mpmath.sin(L))])
    want_f = np.array([-float(gamma_north(lat, h)), 0.0, float(gamma(lat, h))])
    np.testing.assert_allclose(w, np.broadcast_to(want_w, w.shape), rtol=0, atol=1e-12 * float(OMEGA))
    np.testing.assert_allclose(f, np.broadcast_to(want_f, f.shape), rtol=0, atol=1e-12 * want_f[2])


def test_static_far_above_the_ellipsoid():
    """The kernel's geodetic latitude (Bowring's start and two updates) holds to the rounding floor up high:
    at 9000 km the normal-gravity formula and the Earth rate still match their closed forms to 1e-12."""
    lat, h = 33.3, 9.0e6
    f, w = run(earth_scene("NED", lat, -20.0, h))
    L = mpmath.radians(lat)
    np.testing.assert_allclose(w[0], [float(OMEGA * mpmath.cos(L)), 0.0, float(-OMEGA * mpmath.sin(L))], rtol=0,
                               atol=1e-12 * float(OMEGA))
    np.testing.assert_allclose(f[0], [-float(gamma_north(lat, h)), 0.0, -float(gamma(lat, h))], rtol=0,
                               atol=1e-12 * abs(float(gamma(lat, h))))


def test_equator_eastward_travel_eotvos_and_centripetal():
    """Along the equator at speed v, height 0, facing east (NED origin at 0°, 0°; the equator is the circle of
    radius a in the tangent frame's east-down plane). Local NED: f_D = v^2/a + 2 omega v - gamma_e (the up
    component drops by the Eötvös and centripetal terms); the level frame turns at omega_ie + v/a about north.
    Body (facing east, forward-right-down): x = east, y = south, z = down."""
    v = 250.0
    scene = earth_scene("NED", 0.0, 0.0, 0.0, rate_hz=20, duration_s=60.0,
                        trajectory={"x": "0", "y": f"{float(A)!r}*sin({v!r}*t/{float(A)!r})",
                                    "z": f"{float(A)!r}*(1 - cos({v!r}*t/{float(A)!r}))"},
                        attitude={"roll": "0", "pitch": "0", "yaw": "pi/2"})
    f, w = run(scene)
    want_fd = float(v ** 2 / A + 2 * OMEGA * v - GAMMA_E)
    want_wy = -float(OMEGA + v / A)
    assert np.max(np.abs(f[:, :2])) < 1e-12 * float(GAMMA_E)
    np.testing.assert_allclose(f[:, 2], want_fd, rtol=1e-12)
    assert np.max(np.abs(w[:, [0, 2]])) < 1e-12 * float(OMEGA)
    np.testing.assert_allclose(w[:, 1], want_wy, rtol=1e-12)


def test_effects_off_add_nothing_and_a_missing_origin_is_said():
    """Without Earth effects the origin changes nothing (flat, non-rotating frame as before); with them and no
    origin, the scene is refused naming the key."""
    flat = scene_from_dict({"scene": {"rate_hz": 10, "duration_s": 0.2, "frame": "NED"},
                            "trajectory": {"shape": "static"}, "imu": [{"name": "a"}], "effects": {"gravity": True}})
    with_origin = scene_from_dict({"scene": {"rate_hz": 10, "duration_s": 0.2, "frame": "NED",
                                             "origin": {"lat_deg": 30, "lon_deg": 5, "height_m": 0}},
                                   "trajectory": {"shape": "static"}, "imu": [{"name": "a"}],
                                   "effects": {"gravity": True}})
    from imu_emulator.codegen.generate import generate_source
    assert generate_source(flat, True, True) == generate_source(with_origin, True, True)
    with pytest.raises(SceneError, match=r"^scene.origin: effects.earth_rate needs the point where the ENU frame"):
        scene_from_dict({"scene": {"rate_hz": 10, "duration_s": 0.2}, "trajectory": {"shape": "static"},
                         "imu": [{"name": "a"}], "effects": {"earth_rate": True}})
    with pytest.raises(SceneError, match=r"scene.origin.lat_deg: 91.0 is out of range"):
        earth_scene("NED", 91.0)
    with pytest.raises(SceneError, match=r"scene.gravity_model: 'egm96' is not one of"):
        earth_scene("NED", gravity_model="egm96")


# --- the same motion in several frames -----------------------------------------------------------------

MOTION_NED = ("30*t + 2*sin(0.5*t)", "-12*t + 0.02*t**2", "-3*cos(0.2*t) - 0.5*t")   # north, east, down (m)
ATTITUDE = {"roll": "0.1*sin(0.7*t)", "pitch": "0.05 + 0.02*t", "yaw": "0.3*t"}       # w.r.t. local NED
ORIGIN = (-33.9, 151.2, 45.0)


def _ecef_expressions(north, east, down, origin=ORIGIN):
    """ECEF x, y, z expressions of a motion given in NED at `origin` (pymap3d: an independent r0 and axes)."""
    pymap3d = pytest.importorskip("pymap3d")
    r0 = pymap3d.geodetic2ecef(*origin)
    axes = [pymap3d.ned2ecef(*unit, *origin) for unit in np.eye(3)]   # the origin's N, E, D as ECEF points
    columns = [np.subtract(point, r0) for point in axes]
    return [f"{float(r0[i])!r} + {float(columns[0][i])!r}*({north}) + {float(columns[1][i])!r}*({east}) + "
            f"{float(columns[2][i])!r}*({down})"
            for i in range(3)]


def test_same_motion_in_ned_enu_and_ecef_gives_the_same_outputs():
    """Attitude is w.r.t. the local level frame at the current position in every frame, so the three scenes
    are one motion; f and omega agree to 1e-9 (the ECEF expressions round the position to ~1e-9 m)."""
    north, east, down = MOTION_NED
    common = dict(lat=ORIGIN[0], lon=ORIGIN[1], h=ORIGIN[2], rate_hz=50, duration_s=20.0)
    f_ned, w_ned = run(earth_scene("NED", trajectory=dict(zip("xyz", MOTION_NED)), attitude=ATTITUDE, **common))
    x, y, z = _ecef_expressions(north, east, down)
    f_ecef, w_ecef = run(earth_scene("ECEF", trajectory={"x": x, "y": y, "z": z}, attitude=ATTITUDE, **common))
    # ENU: x = east, y = north, z = up; body forward-left-up; yaw from east
    enu_att = {"roll": ATTITUDE["roll"], "pitch": f"-({ATTITUDE['pitch']})", "yaw": f"pi/2 - ({ATTITUDE['yaw']})"}
    f_enu, w_enu = run(earth_scene("ENU", trajectory={"x": east, "y": north, "z": f"-({down})"}, attitude=enu_att,
                                   **common))
    flip = np.array([1.0, -1.0, -1.0])     # forward-right-down from forward-left-up
    assert np.max(np.abs(f_ecef - f_ned)) < 1e-9 and np.max(np.abs(w_ecef - w_ned)) < 1e-9
    assert np.max(np.abs(f_enu * flip - f_ned)) < 1e-9 and np.max(np.abs(w_enu * flip - w_ned)) < 1e-9
    # and the Earth terms are really there: the motion differs from the flat, non-rotating answer
    flat_f, flat_w = run(scene_from_dict({"scene": {"rate_hz": 50, "duration_s": 20.0, "frame": "NED"},
                                          "trajectory": dict(zip("xyz", MOTION_NED)), "attitude": ATTITUDE,
                                          "imu": [{"name": "a"}], "effects": {"gravity": True}}))
    assert np.max(np.abs(flat_w - w_ned)) > 5e-5 and np.max(np.abs(flat_f - f_ned)) > 1e-3


@pytest.mark.parametrize("t0", [0.0, 3.0e7])
def test_eci_point_fixed_on_the_earth_is_static(t0):
    """A point fixed on the Earth, given in ECI (it turns with the Earth at omega_ie about z), reads like the
    static ECEF point, also at t = 3e7 s (omega t = 2188 rad), to 1e-12 relative."""
    pymap3d = pytest.importorskip("pymap3d")
    x0, y0, z0 = (float(v) for v in pymap3d.geodetic2ecef(*ORIGIN))
    w = "7.292115e-5*t"
    eci = {"x": f"{x0!r}*cos({w}) - {y0!r}*sin({w})", "y": f"{x0!r}*sin({w}) + {y0!r}*cos({w})", "z": repr(z0)}
    f, g = run(earth_scene("ECI", trajectory=eci, t0_s=t0, duration_s=0.5))
    f_ref, g_ref = run(earth_scene("NED", *ORIGIN, t0_s=t0, duration_s=0.5))
    np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-12 * 9.8)
    np.testing.assert_allclose(g, g_ref, rtol=0, atol=1e-12 * 7.3e-5)


def test_frames_refuse_what_is_not_built():
    with pytest.raises(SceneError, match=r"trajectory.shape: shapes are built in a local frame"):
        earth_scene("ECEF")
    with pytest.raises(SceneError, match=r"effects.coriolis: frame = \"ECI\" needs it"):
        earth_scene("ECI", trajectory={"x": "7e6", "y": "0", "z": "0"}, effects={"earth_rate": True})


# --- truth and output headers ---------------------------------------------------------------------------

def test_truth_geodetic_ned_velocity_and_earth_terms():
    """The Earth truth against pymap3d (geodetic, ECEF, NED velocity) and the spec's closed forms."""
    pymap3d = pytest.importorskip("pymap3d")
    scene = earth_scene("ENU", *ORIGIN, rate_hz=10, duration_s=30.0,
                        trajectory={"x": "40*t", "y": "25*t + 0.3*t**2", "z": "100 + 2*t"},
                        attitude={"roll": "0.2", "pitch": "-0.1", "yaw": "1.0 + 0.01*t"})
    tr = Simulation(scene, attitude=False, truth=True).run().truth
    pos, vel = tr["position"], tr["velocity"]
    want = np.array([pymap3d.enu2geodetic(*p, *ORIGIN) for p in pos])
    np.testing.assert_allclose(np.radians(tr["geodetic"][:, :2]), np.radians(want[:, :2]), rtol=0, atol=1e-11)
    np.testing.assert_allclose(tr["geodetic"][:, 2], want[:, 2], rtol=0, atol=1e-6)
    np.testing.assert_allclose(tr["position_ecef"], [pymap3d.enu2ecef(*p, *ORIGIN) for p in pos], rtol=0, atol=1e-6)
    v_ecef = np.array([pymap3d.enu2uvw(*v, ORIGIN[0], ORIGIN[1]) for v in vel])
    np.testing.assert_allclose(tr["velocity_ecef"], v_ecef, rtol=0, atol=1e-9)
    v_ned = np.array([pymap3d.ecef2nedv(*v, lat, lon) for v, (lat, lon, _) in zip(v_ecef, want)])
    np.testing.assert_allclose(tr["velocity_ned"], v_ned, rtol=0, atol=1e-9)
    lat = np.radians(want[:, 0])
    np.testing.assert_allclose(tr["earth_rate_ned"], np.column_stack(
        [float(OMEGA) * np.cos(lat), 0 * lat, -float(OMEGA) * np.sin(lat)]), rtol=0, atol=1e-18)
    np.testing.assert_allclose(tr["gravity_ned"][:, 2], [float(gamma(la, h)) for la, _, h in want], rtol=1e-12)
    np.testing.assert_allclose(tr["gravity_ned"][:, 0], [float(gamma_north(la, h)) for la, _, h in want], rtol=1e-9)
    # attitude w.r.t. local NED of a forward-right-down body: scipy's ZYX of the ENU/FLU attitude re-expressed
    from scipy.spatial.transform import Rotation
    enu = Rotation.from_euler("ZYX", tr["euler"][:, ::-1]).as_matrix()
    perm, flip = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1.0]]), np.diag([1.0, -1.0, -1.0])
    ned = Rotation.from_matrix(perm @ enu @ flip).as_euler("ZYX")[:, ::-1]
    np.testing.assert_allclose(tr["euler_ned"], ned, rtol=0, atol=1e-12)


def test_generate_writes_conventions_and_earth_columns(tmp_path):
    import csv

    from imu_emulator.cli import main
    scene = tmp_path / "s.toml"
    scene.write_text('[scene]\nrate_hz = 10\nduration_s = 1\nframe = "NED"\ngravity_model = "wgs84"\n'
                     'origin = { lat_deg = 45.0, lon_deg = 7.0, height_m = 200.0 }\n'
                     '[trajectory]\nx = "10*t"\n[[imu]]\nname = "a"\n'
                     '[effects]\ngravity = true\nearth_rate = true\ncoriolis = true\n')
    assert main(["generate", str(scene), "-o", str(tmp_path / "o.csv"), "--quiet", "--truth"]) == 0
    lines = (tmp_path / "o.csv").read_text().splitlines()
    comments = [line for line in lines if line.startswith("#")]
    assert any("NED tangent to the Earth at origin (45.0 deg, 7.0 deg, 200.0 m)" in c for c in comments)
    assert any("f = a - g" in c for c in comments)
    rows = list(csv.DictReader(line for line in lines if not line.startswith("#")))
    assert len(rows) == 10 and float(rows[0]["lat_deg"]) == pytest.approx(45.0, abs=1e-12)
    assert float(rows[5]["vn"]) == pytest.approx(10.0, rel=1e-6)
    assert main(["generate", str(scene), "-o", str(tmp_path / "o.npz"), "--quiet", "--truth"]) == 0
    with np.load(tmp_path / "o.npz") as data:
        assert data["geodetic"].shape == (10, 3) and any("f = a - g" in c for c in data["conventions"])


def test_geodetic_trajectory_along_the_equator_and_as_ecef():
    """lat_deg, lon_deg, height_m expressions: eastward along the equator at v the closed form of the NED
    test above holds; and a general geodetic motion gives what its ECEF expression (pymap3d's formula for the
    same point, written out) gives, to 1e-9."""
    v = 250.0
    deg = f"{v!r}*t/{float(A)!r}*180/pi"
    equator = earth_scene("NED", rate_hz=20, duration_s=60.0,
                          trajectory={"lat_deg": "0", "lon_deg": deg, "height_m": "0"},
                          attitude={"roll": "0", "pitch": "0", "yaw": "pi/2"})
    assert equator.origin is None
    f, w = run(equator)
    np.testing.assert_allclose(f[:, 2], float(v ** 2 / A + 2 * OMEGA * v - GAMMA_E), rtol=1e-12)
    np.testing.assert_allclose(w[:, 1], -float(OMEGA + v / A), rtol=1e-12)
    assert np.max(np.abs(f[:, :2])) < 1e-12 * 9.8 and np.max(np.abs(w[:, [0, 2]])) < 1e-12 * 7.3e-5

    lat, lon, h = "-33.9 + 0.001*t", "151.2 + 0.002*sin(0.05*t)", "45 + 10*t"
    geo = earth_scene("NED", trajectory={"lat_deg": lat, "lon_deg": lon, "height_m": h}, attitude=ATTITUDE,
                      rate_hz=20, duration_s=20.0)
    e2, a = float(E2), float(A)
    n = f"({a!r}/sqrt(1 - {e2!r}*sin(({lat})*pi/180)**2))"
    ecef = {"x": f"({n} + {h})*cos(({lat})*pi/180)*cos(({lon})*pi/180)",
            "y": f"({n} + {h})*cos(({lat})*pi/180)*sin(({lon})*pi/180)",
            "z": f"({n}*(1 - {e2!r}) + {h})*sin(({lat})*pi/180)"}
    pymap3d = pytest.importorskip("pymap3d")
    np.testing.assert_allclose([eval(ecef[k], {"sqrt": math.sqrt, "sin": math.sin, "cos": math.cos, "pi": math.pi,
                                               "t": 3.0}) for k in "xyz"],
                               pymap3d.geodetic2ecef(-33.9 + 0.003, 151.2 + 0.002 * math.sin(0.15), 75.0), atol=1e-6)
    f_geo, w_geo = run(geo)
    f_ecef, w_ecef = run(earth_scene("ECEF", trajectory=ecef, attitude=ATTITUDE, rate_hz=20, duration_s=20.0))
    assert np.max(np.abs(f_geo - f_ecef)) < 1e-9 and np.max(np.abs(w_geo - w_ecef)) < 1e-9


def test_ecef_without_effects_still_resolves_acceleration_in_local_level():
    """The geometry comes with the motion, not with an effect: an ECEF scene with no effects named (no gravity)
    accelerating 0.5 m/s² north from rest, level and facing north, reads f = (0.5, 0, 0) in body axes (to
    the curvature of 0.25 m of travel, 4e-8)."""
    x, y, z = _ecef_expressions("0.25*t**2", "0", "0")
    f, w = run(earth_scene("ECEF", trajectory={"x": x, "y": y, "z": z}, effects={"lever_arm": False},
                           rate_hz=10, duration_s=1.0))
    np.testing.assert_allclose(f, np.broadcast_to([0.5, 0.0, 0.0], f.shape), rtol=0, atol=1e-7)
    assert np.max(np.abs(w)) < 1e-12    # no Earth rate named; the transport rate belongs to coriolis
