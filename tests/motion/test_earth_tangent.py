"""Tangent attitude over the curved Earth: heading and pitch from the velocity in the local level frame at the
current position, in ECEF, geodetic and ENU/NED-with-origin scenes.

Two independent references:
- Groves 2nd ed. eq. 2.111 and 5.44 in mpmath: v_N = (R_N + h) L', v_E = (R_E + h) cos L lambda',
  heading = atan2(v_E, v_N), and a level body turning at heading' about down reads
  omega_ib^b = C_n^b (omega_ie^n + omega_en^n) + (0, 0, heading');
- the body's attitude in ECI, C_b^i(t) = R_z(omega_ie t) C_n^e(L, lambda) C_b^n(heading, pitch), built from
  the geodetic path alone in mpmath at 40 digits and differentiated numerically there: [omega_ib^b x] =
  (C_b^i)^T d/dt C_b^i. It knows nothing of transport rates or of the kernel's level-frame derivatives.
"""
from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest

from imu_emulator import scene_from_dict
from imu_emulator.errors import SceneError
from imu_emulator.runtime.simulation import Simulation
from tests.support.scenes import scene

mpmath.mp.dps = 40
A = 6378137.0
F = 1 / 298.257223563
E2 = F * (2 - F)
OMEGA = 7.292115e-5

# A great circle of the sphere of directions flown at constant angular rate and constant height: latitude and
# longitude of the unit vector cos(w t) p + sin(w t) q, inclination 50 deg, from longitude 20 deg.
# The path starts at angle P0 past the equator crossing (latitude 40 deg), where the heading turns visibly.
INC, RATE, P0, LON0, HEIGHT = 50.0, 250.0 / A, 1.0, 20.0, 1000.0
WT = f"({RATE!r}*t + {P0!r})"
LAT = f"asin(sin({INC!r}*pi/180)*sin{WT})*180/pi"
LON = f"{LON0!r} + atan2(cos({INC!r}*pi/180)*sin{WT}, cos{WT})*180/pi"
RATE_HZ, DURATION = 10, 600.0
EFFECTS = {"earth_rate": True, "coriolis": True}


def _ecef_strings():
    """The same path as ECEF x, y, z expressions (the WGS-84 geodetic -> ECEF formula written out, with
    sin L = sin(i) sin(w t) and cos L (cos lon, sin lon) = the unit vector's x, y, short enough for the
    expression limit)."""
    si, ci = math.sin(math.radians(INC)), math.cos(math.radians(INC))
    s0, c0 = math.sin(math.radians(LON0)), math.cos(math.radians(LON0))
    cw, sw = f"cos{WT}", f"sin{WT}"
    sl = f"{si!r}*{sw}"
    n = f"{A!r}/sqrt(1 - {E2!r}*({sl})**2)"
    return {"x": f"({n} + {HEIGHT!r})*({c0!r}*{cw} - {ci * s0!r}*{sw})",
            "y": f"({n} + {HEIGHT!r})*({s0!r}*{cw} + {ci * c0!r}*{sw})",
            "z": f"({n}*{1 - E2!r} + {HEIGHT!r})*{sl}"}


def _scene(frame, trajectory, origin=None, effects=EFFECTS, duration=DURATION, **extra):
    head = {"rate_hz": RATE_HZ, "duration_s": duration, "frame": frame, **extra}
    if origin is not None:
        head["origin"] = dict(zip(("lat_deg", "lon_deg", "height_m"), origin))
    return scene(**head, trajectory=trajectory, attitude={"mode": "tangent"}, imus=[{"name": "a"}], effects=effects)


def _run(scene):
    out = Simulation(scene, attitude=False, truth=True).run()
    return out.accel[0], out.gyro[0], out.truth


@pytest.fixture(scope="module")
def great_circle_outputs():
    """(t, {scene name: (f, w, truth)}) for the path as geodetic, ECEF and ENU/NED-at-an-origin scenes."""
    pymap3d = pytest.importorskip("pymap3d")
    ecef = _ecef_strings()
    origin = (10.0, 30.0, 50.0)
    r0 = np.array(pymap3d.geodetic2ecef(*origin))
    outs = {"geodetic": _run(_scene("NED", {"lat_deg": LAT, "lon_deg": LON, "height_m": repr(HEIGHT)})),
            "ECEF": _run(_scene("ECEF", ecef))}
    for frame, convert in (("ENU", pymap3d.enu2ecef), ("NED", pymap3d.ned2ecef)):
        # local = C^T (r - r0): C's columns are the origin's axes in ECEF (pymap3d: each unit vector as a point)
        c = np.column_stack([np.subtract(convert(*unit, *origin), r0) for unit in np.eye(3)])
        local = {axis: " + ".join(f"{float(c[j, i])!r}*({ecef['xyz'[j]]} - {float(r0[j])!r})" for j in range(3))
                 for i, axis in enumerate("xyz")}
        outs[frame] = _run(_scene(frame, local, origin=origin))
    t = np.arange(int(DURATION * RATE_HZ)) / RATE_HZ
    return t, outs


def _closed_form(t):
    """(heading, omega_ib^b) from Groves eq. 2.111 and 5.44 in mpmath, for a level body (pitch 0)."""
    out_h, out_w = [], []
    inc, w, lon0 = mpmath.radians(INC), mpmath.mpf(RATE), mpmath.radians(LON0)
    e2, a, om = mpmath.mpf(E2), mpmath.mpf(A), mpmath.mpf(OMEGA)
    for tk in t:
        tk = mpmath.mpf(tk)
        lat = lambda s: mpmath.asin(mpmath.sin(inc) * mpmath.sin(w * s + P0))   # noqa: E731
        lon = lambda s: lon0 + mpmath.atan2(mpmath.cos(inc) * mpmath.sin(w * s + P0), mpmath.cos(w * s + P0))  # noqa
        L, dL, dlon = lat(tk), mpmath.diff(lat, tk), mpmath.diff(lon, tk)
        wgt = mpmath.sqrt(1 - e2 * mpmath.sin(L) ** 2)
        rn, re = a * (1 - e2) / wgt ** 3 + HEIGHT, a / wgt + HEIGHT
        vn, ve = rn * dL, re * mpmath.cos(L) * dlon
        heading = lambda s: mpmath.atan2(    # noqa: E731
            (a / mpmath.sqrt(1 - e2 * mpmath.sin(lat(s)) ** 2) + HEIGHT) * mpmath.cos(lat(s)) * mpmath.diff(lon, s),
            (a * (1 - e2) / mpmath.sqrt(1 - e2 * mpmath.sin(lat(s)) ** 2) ** 3 + HEIGHT) * mpmath.diff(lat, s))
        psi = mpmath.atan2(ve, vn)
        nav = [om * mpmath.cos(L) + ve / re, -vn / rn, -om * mpmath.sin(L) - ve * mpmath.tan(L) / re]
        c, s = mpmath.cos(psi), mpmath.sin(psi)
        body = [c * nav[0] + s * nav[1], -s * nav[0] + c * nav[1], nav[2] + mpmath.diff(heading, tk)]
        out_h.append(float(psi))
        out_w.append([float(x) for x in body])
    return np.array(out_h), np.array(out_w)


def test_great_circle_heading_pitch_and_gyro_closed_form(great_circle_outputs):
    """Pitch 0 (constant height), heading per eq. 2.111 and the gyros reading earth rate + transport rate +
    the heading's own turn, to 1e-12 rad/s (1.4e-8 of omega_ie) in the geodetic scene."""
    t, outs = great_circle_outputs
    f, w, truth = outs["geodetic"]
    idx = np.arange(0, t.size, 600)
    heading, want_w = _closed_form(t[idx])
    np.testing.assert_allclose(truth["euler_ned"][idx, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (truth["euler_ned"][idx, 2] - heading))), 0.0, atol=1e-11)
    np.testing.assert_allclose(w[idx], want_w, rtol=0, atol=1e-12)
    # the heading really turns (a great circle is not a rhumb line) and the Earth terms are there
    assert np.ptp(truth["euler_ned"][:, 2]) > 0.01 and np.max(np.abs(w[:, 1])) > 4e-5


def _c_bi(tk):
    """The body's attitude in ECI at time tk (mpmath, 40 digits), from the geodetic path alone:
    R_z(omega_ie t) C_n^e(L, lon) R_z(heading) R_y(pitch), heading and pitch from v^n = C_e^n dr^e/dt."""
    inc, w, lon0, e2, a = (mpmath.radians(INC), mpmath.mpf(RATE), mpmath.radians(LON0), mpmath.mpf(E2),
                           mpmath.mpf(A))

    def geodetic(s):
        lat = mpmath.asin(mpmath.sin(inc) * mpmath.sin(w * s + P0))
        return lat, lon0 + mpmath.atan2(mpmath.cos(inc) * mpmath.sin(w * s + P0), mpmath.cos(w * s + P0))

    def r_e(s):
        lat, lon = geodetic(s)
        n = a / mpmath.sqrt(1 - e2 * mpmath.sin(lat) ** 2)
        return mpmath.matrix([(n + HEIGHT) * mpmath.cos(lat) * mpmath.cos(lon),
                              (n + HEIGHT) * mpmath.cos(lat) * mpmath.sin(lon), (n * (1 - e2) + HEIGHT) * mpmath.sin(lat)])

    def rz(x):
        return mpmath.matrix([[mpmath.cos(x), -mpmath.sin(x), 0], [mpmath.sin(x), mpmath.cos(x), 0], [0, 0, 1]])

    lat, lon = geodetic(tk)
    sl, cl, so, co = mpmath.sin(lat), mpmath.cos(lat), mpmath.sin(lon), mpmath.cos(lon)
    c_ne = mpmath.matrix([[-sl * co, -so, -cl * co], [-sl * so, co, -cl * so], [cl, 0, -sl]])   # columns N, E, D
    v_e = mpmath.matrix([mpmath.diff(lambda s: r_e(s)[i], tk) for i in range(3)])
    v_n = c_ne.T * v_e
    psi = mpmath.atan2(v_n[1], v_n[0])
    theta = mpmath.atan2(-v_n[2], mpmath.sqrt(v_n[0] ** 2 + v_n[1] ** 2))
    ry = mpmath.matrix([[mpmath.cos(theta), 0, mpmath.sin(theta)], [0, 1, 0],
                        [-mpmath.sin(theta), 0, mpmath.cos(theta)]])
    return rz(mpmath.mpf(OMEGA) * tk) * c_ne * rz(psi) * ry


def test_great_circle_gyro_against_the_eci_attitude_differentiated(great_circle_outputs):
    """omega_ib^b from differentiating the body's ECI attitude numerically at 40 digits ([omega x] =
    C^T dC/dt, mpmath's differentiation): no transport-rate formula involved, at 5 times along the path."""
    t, outs = great_circle_outputs
    for tk in (0.0, 123.4, 300.0, 451.7, 599.9):
        tm = mpmath.mpf(tk)
        m = _c_bi(tm)
        dm = mpmath.matrix(3, 3)
        for i in range(3):
            for j in range(3):
                dm[i, j] = mpmath.diff(lambda s: _c_bi(s)[i, j], tm)
        om = m.T * dm
        want = np.array([float(om[2, 1]), float(om[0, 2]), float(om[1, 0])])
        np.testing.assert_allclose(outs["geodetic"][1][int(round(tk * RATE_HZ))], want, rtol=0, atol=1e-12)


def test_great_circle_same_in_every_frame(great_circle_outputs):
    """Geodetic, ECEF, ENU-at-an-origin and NED-at-an-origin scenes of one path give one f and omega to 1e-9
    (ENU's body axes are forward-left-up: y and z flip)."""
    t, outs = great_circle_outputs
    f0, w0, _ = outs["geodetic"]
    flip = np.array([1.0, -1.0, -1.0])
    for name, (f, w, _) in outs.items():
        s = flip if name == "ENU" else 1.0
        assert np.max(np.abs(f * s - f0)) < 1e-9, name
        assert np.max(np.abs(w * s - w0)) < 1e-9, name


def test_tangent_on_the_equator_reads_the_eotvos_closed_form():
    """Eastward along the equator at v, height 0, in ECEF with tangent attitude: heading 90 deg, and the
    existing closed form (f_D = v^2/a + 2 omega v - gamma_e, omega_y = -(omega + v/a)) holds."""
    v = 250.0
    x, y = (f"{A!r}*{fn}({v!r}*t/{A!r})" for fn in ("cos", "sin"))
    scene = _scene("ECEF", {"x": x, "y": y, "z": "0"}, effects={**EFFECTS, "gravity": True}, duration=30.0,
                   gravity_model="wgs84")
    f, w, truth = _run(scene)
    np.testing.assert_allclose(truth["euler_ned"][:, 2], math.pi / 2, atol=1e-12)
    np.testing.assert_allclose(f[:, 2], v ** 2 / A + 2 * OMEGA * v - 9.7803253359, rtol=1e-12)
    np.testing.assert_allclose(w[:, 1], -(OMEGA + v / A), rtol=1e-12)
    assert np.max(np.abs(w[:, [0, 2]])) < 1e-12 * OMEGA


def test_missing_origin_with_earth_effects_is_an_error():
    for effects in ({"earth_rate": True}, {"coriolis": True}, {"gravity": True}):
        head = {"rate_hz": 10, "duration_s": 1.0, "frame": "ENU", "gravity_model": "wgs84"}
        with pytest.raises(SceneError, match=r"^scene.origin: effects\.\w+ needs the point where the ENU frame"):
            scene_from_dict({"scene": head, "trajectory": {"shape": "static"}, "imu": [{"name": "a"}],
                             "effects": effects})
