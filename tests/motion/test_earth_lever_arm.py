"""The lever arm with the Earth effects: an IMU at r from the reference point S feels
f_I = f_S + omega_ib x (omega_ib x r) + omega_ib' x r, with omega_ib the inertial rate (Earth rate and transport
rate included) and omega_ib' its derivative.

Independent reference, in ECI at 60 digits (mpmath): the IMU is at r_I^i = r_S^i + C_b^i r, so
    f_I = C_i^b (r_I^i'' - gamma^i) = f_S + C_i^b (C_b^i r)''     (gamma at S: the emulator's lever arm adds no
                                                                  gravity gradient, so gamma^i cancels)
    [omega_ib^b x] = C_i^b (C_b^i)'.
C_b^i(t) = R_z(omega_ie t) C_l^e(L(t), lon(t)) C_b^l(t) is built from the scene's own expressions (sympy ->
mpmath): the trajectory taken to ECEF through the origin's tangent axes, WGS-84 latitude and longitude by
fixed-point iteration to full precision, the level axes l (NED or ENU) at that point, the Euler angles (or, for
tangent attitude, heading and pitch of the Earth-referenced velocity in local NED). The derivatives are
central differences with h = 1e-12 s at 60 digits: truncation h^2/12 |u''''| ~ 1e-25, rounding 1e-60 / h^2 =
1e-36, both far below the double-precision kernel's ~1e-15.

Before the fix the kernel used alpha_nb (the body's angular acceleration relative to the level frame) in
alpha x r, missing d/dt (C_n^b omega_in^n) = -omega_nb x C_n^b omega_in^n + C_n^b (omega_in^n)': about
|omega_nb| |omega_ie| |r| = 1 rad/s * 7.3e-5 rad/s * 1 m = 7e-5 m/s^2 for the body spinning at 1 rad/s at
latitude 45 deg (test_spinning_at_rest_at_45_degrees asserts that size, >1e5 times its tolerance; the tests
here fail on the old code: 5e-5 m/s^2 off at rest, 4e-5 in the manoeuvres).
"""
from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest
import sympy

from imu_emulator import scene_from_dict
from imu_emulator.runtime.simulation import Simulation

DPS = 60
H = "1e-12"
# WGS-84 as TR8350.2 (and ../shared/specs/earth.md) state it
A, INV_F, OMEGA = "6378137", "298.257223563", "7.292115e-5"
GAMMA_E, GAMMA_P = "9.7803253359", "9.8321849378"
ARM = (0.48, -0.6, 0.64)       # |r| = 1 m
RATE_HZ, DURATION = 10, 3.0
CHECKED = (3, 14, 29)          # samples compared (and the increments over the interval ending there)
NODES = 8                      # Gauss-Legendre nodes of the reference's integrals: error ~ (w h)^16, nil here
# tolerances about 20x the largest error reached (f 5e-15, w 1.1e-16, dtheta 3e-17, dv 3.6e-16): double
# rounding of |f| ~ 10 m/s^2 and |w| ~ 1 rad/s; the kernel's 4-node quadrature errs by ~5.6e-10 (w h)^8, nil
TOL_F = 1e-13                  # m/s^2
TOL_W = 2e-15                  # rad/s
TOL_DTHETA = 1e-15             # rad over 0.1 s
TOL_DV = 1e-14                 # m/s over 0.1 s


def _mpf(x):
    return mp.mpf(x)


def _rz(a):
    c, s = mp.cos(a), mp.sin(a)
    return mp.matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _euler(roll, pitch, yaw):
    """Body -> level axes, z-y-x: R_z(yaw) R_y(pitch) R_x(roll)."""
    cr, sr, cp, sp = mp.cos(roll), mp.sin(roll), mp.cos(pitch), mp.sin(pitch)
    ry = mp.matrix([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = mp.matrix([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return _rz(yaw) * ry * rx


def _e2():
    f = 1 / _mpf(INV_F)
    return f * (2 - f)


def _geodetic_to_ecef(lat, lon, h):
    n = _mpf(A) / mp.sqrt(1 - _e2() * mp.sin(lat) ** 2)
    return mp.matrix([(n + h) * mp.cos(lat) * mp.cos(lon), (n + h) * mp.cos(lat) * mp.sin(lon),
                      (n * (1 - _e2()) + h) * mp.sin(lat)])


def _ecef_to_lat_lon(r):
    """Latitude by the fixed point tan L = z / (p (1 - e2 N / (N + h))), iterated until it stops moving."""
    p, e2, a = mp.sqrt(r[0] ** 2 + r[1] ** 2), _e2(), _mpf(A)
    lat = mp.atan2(r[2], p * (1 - e2))
    for _ in range(200):
        n = a / mp.sqrt(1 - e2 * mp.sin(lat) ** 2)
        h = p / mp.cos(lat) - n
        new = mp.atan2(r[2], p * (1 - e2 * n / (n + h)))
        if abs(new - lat) < mp.mpf(10) ** (-mp.mp.dps + 2):
            break
        lat = new
    return new, mp.atan2(r[1], r[0])


def _level_to_ecef(lat, lon, frame):
    """Columns: the level axes (N, E, D or E, N, U) at (lat, lon) in ECEF."""
    sl, cl, so, co = mp.sin(lat), mp.cos(lat), mp.sin(lon), mp.cos(lon)
    n, e = [-sl * co, -sl * so, cl], [-so, co, 0]
    d = [-cl * co, -cl * so, -sl]
    cols = (n, e, d) if frame == "NED" else (e, n, [-x for x in d])
    return mp.matrix([[cols[j][i] for j in range(3)] for i in range(3)])


def _functions(expressions: dict, derivative: bool = False):
    t = sympy.Symbol("t")
    exprs = [sympy.sympify(expressions[k]) for k in sorted(expressions)]
    if derivative:
        exprs = [sympy.diff(x, t) for x in exprs]
    fs = [sympy.lambdify(t, x, "mpmath") for x in exprs]
    return dict(zip(sorted(expressions), fs))


class Reference:
    """r_S^i(t) and C_b^i(t) of a scene, from its expressions (see the module docstring)."""

    def __init__(self, frame, origin, trajectory, attitude, reference="local_level"):
        self.frame, self.reference = frame, reference
        self.p, self.v = _functions(trajectory), _functions(trajectory, derivative=True)
        self.att = attitude if attitude == "tangent" else _functions(attitude)
        with mp.workdps(DPS):
            if frame == "ECEF":
                self.r0, self.c0 = mp.matrix([0, 0, 0]), mp.eye(3)
            else:
                lat, lon, h = (mp.radians(mp.mpf(float(origin[0]))), mp.radians(mp.mpf(float(origin[1]))),
                               mp.mpf(float(origin[2])))
                self.r0, self.c0 = _geodetic_to_ecef(lat, lon, h), _level_to_ecef(lat, lon, frame)

    def ecef(self, t):
        p = mp.matrix([self.p[k](t) for k in "xyz"])
        v = mp.matrix([self.v[k](t) for k in "xyz"])
        return self.r0 + self.c0 * p, self.c0 * v

    def body_to_eci(self, t):
        r_e, v_e = self.ecef(t)
        c_ie = _rz(_mpf(OMEGA) * t)
        if self.reference == "ECI":
            return c_ie * r_e, _euler(*(self.att[k](t) for k in ("roll", "pitch", "yaw")))
        if self.reference == "ECEF":
            return c_ie * r_e, c_ie * _euler(*(self.att[k](t) for k in ("roll", "pitch", "yaw")))
        lat, lon = _ecef_to_lat_lon(r_e)
        c_le = _level_to_ecef(lat, lon, "NED" if self.frame != "ENU" else "ENU")
        if self.att == "tangent":   # heading and pitch of the Earth-referenced velocity in local NED, roll 0
            v_n = _level_to_ecef(lat, lon, "NED").T * v_e
            c_bl = _euler(0, mp.atan2(-v_n[2], mp.sqrt(v_n[0] ** 2 + v_n[1] ** 2)), mp.atan2(v_n[1], v_n[0]))
        else:
            c_bl = _euler(*(self.att[k](t) for k in ("roll", "pitch", "yaw")))
        return c_ie * r_e, c_ie * c_le * c_bl

    def omega_ib(self, t):
        """[omega x] = C^T C' (body axes)."""
        h = _mpf(H)
        c = self.body_to_eci(t)[1]
        dc = (self.body_to_eci(t + h)[1] - self.body_to_eci(t - h)[1]) / (2 * h)
        w = c.T * dc
        return np.array([float(w[2, 1]), float(w[0, 2]), float(w[1, 0])]), w

    def lever(self, t, arm):
        """C_i^b (C_b^i r)'': the arm's part of the IMU's specific force (body axes); `arm` a triple or r(t)."""
        h = _mpf(H)
        r = arm if callable(arm) else (lambda s, c=mp.matrix([mp.mpf(float(x)) for x in arm]): c)
        u = [self.body_to_eci(t + s * h)[1] * r(t + s * h) for s in (-1, 0, 1)]
        acc = (u[0] - 2 * u[1] + u[2]) / h ** 2
        return self.body_to_eci(t)[1].T * acc

    def integral(self, f, t0, t1):
        """Gauss-Legendre (NODES) of a vector function over (t0, t1)."""
        xi, wi = np.polynomial.legendre.leggauss(NODES)
        half, mid = (t1 - t0) / 2, (t1 + t0) / 2
        return sum(mp.mpf(float(w)) * half * f(mid + half * mp.mpf(float(x))) for x, w in zip(xi, wi))


def _scene(frame, origin, trajectory, attitude, effects, reference=None):
    att = {"mode": "tangent"} if attitude == "tangent" else dict(attitude)
    if reference:
        att["reference"] = reference
    return scene_from_dict({
        "scene": {"rate_hz": RATE_HZ, "duration_s": DURATION, "frame": frame, "gravity_model": "wgs84",
                  **({"origin": {"lat_deg": origin[0], "lon_deg": origin[1], "height_m": origin[2]}}
                     if origin else {})},
        "trajectory": trajectory, "attitude": att,
        "imu": [{"name": "s"}, {"name": "arm", "lever_arm_m": list(ARM)}],
        "effects": {"gravity": True, **{name: True for name in effects}, "lever_arm": True}})


def _check(ref: Reference, scene):
    """The arm IMU's gyro and (f_arm - f_S) at CHECKED samples, and its increments over the intervals ending
    there, against the reference; returns the reference lever terms (for callers' own checks)."""
    out = Simulation(scene, attitude=False, truth=False, increments=4).run()
    levers = {}
    with mp.workdps(DPS):
        for k in CHECKED:
            t = mp.mpf(float(out.t_s[k]))
            w, _ = ref.omega_ib(t)
            np.testing.assert_allclose(out.gyro[1, k], w, rtol=0, atol=TOL_W)
            lever = ref.lever(t, ARM)
            levers[k] = lever
            np.testing.assert_allclose(out.accel[1, k] - out.accel[0, k], [float(x) for x in lever],
                                       rtol=0, atol=TOL_F)
            t_prev = t - _mpf(1) / RATE_HZ
            dtheta = ref.integral(lambda s: mp.matrix(ref.omega_ib(s)[0].tolist()), t_prev, t)
            dv = ref.integral(lambda s: ref.lever(s, ARM), t_prev, t)
            np.testing.assert_allclose(out.dtheta[1, k], [float(x) for x in dtheta], rtol=0, atol=TOL_DTHETA)
            np.testing.assert_allclose(out.dvel[1, k] - out.dvel[0, k], [float(x) for x in dv], rtol=0, atol=TOL_DV)
    return out, levers


def _somigliana(lat):
    """Normal gravity on the ellipsoid, spec's closed form: gamma_e (1 + k sin^2 L) / sqrt(1 - e2 sin^2 L)."""
    a, f = _mpf(A), 1 / _mpf(INV_F)
    k = a * (1 - f) * _mpf(GAMMA_P) / (a * _mpf(GAMMA_E)) - 1
    s2 = mp.sin(lat) ** 2
    return _mpf(GAMMA_E) * (1 + k * s2) / mp.sqrt(1 - _e2() * s2)


@pytest.mark.parametrize("frame", ["NED", "ENU"])
def test_spinning_at_rest_at_45_degrees(frame):
    """(a) At rest at 45 deg, spinning at 1 rad/s about its x axis, pitched 0.4 rad out of the level plane: the
    whole specific force at the arm, C_i^b (r_I^i'' - gamma^i) = C_i^b (C_b^i r)'' - C_l^b g^l with g^l the
    Somigliana gravity (h = 0: no north term, no height term), and the size of what the old code missed."""
    origin = (45.0, 10.0, 0.0)
    trajectory = {"x": "0", "y": "0", "z": "0"}
    attitude = {"roll": "t", "pitch": "0.4", "yaw": "0.7"}
    ref = Reference(frame, origin, trajectory, attitude)
    out, levers = _check(ref, _scene(frame, origin, trajectory, attitude, ("earth_rate", "coriolis")))
    with mp.workdps(DPS):
        gamma = _somigliana(mp.radians(45))
        g_level = mp.matrix([0, 0, gamma if frame == "NED" else -gamma])
        for k in CHECKED:
            t = mp.mpf(float(out.t_s[k]))
            c_bl = _euler(t, mp.mpf("0.4"), mp.mpf("0.7"))
            f = levers[k] - c_bl.T * g_level
            np.testing.assert_allclose(out.accel[1, k], [float(x) for x in f], rtol=0, atol=TOL_F)
            # what the old code left out: (-omega_nb x C_l^b omega_ie^l) x r (omega_ie^l is constant at rest)
            w_ie = mp.matrix([mp.cos(mp.radians(45)), 0, -mp.sin(mp.radians(45))]) * _mpf(OMEGA)
            if frame == "ENU":
                w_ie = mp.matrix([w_ie[1], w_ie[0], -w_ie[2]])
            w_ie_b = np.array([float(x) for x in c_bl.T * w_ie])
            missing = np.cross(-np.cross([1.0, 0.0, 0.0], w_ie_b), ARM)
            assert np.linalg.norm(missing) > 1e8 * TOL_F


MANOEUVRE = {"x": "150*t + 2*t**2 + 30*sin(0.5*t)", "y": "80*t - 40*cos(0.3*t)", "z": "-3*t + 5*sin(0.7*t)"}
TURNING = {"roll": "0.3*sin(0.9*t)", "pitch": "0.1 + 0.2*cos(0.6*t)", "yaw": "0.5*t + 0.2*sin(1.3*t)"}


def test_manoeuvre_in_ned_with_coriolis_and_earth_rate():
    """(b) A manoeuvre in NED at an origin: latitude changing (v_N ~ 150 m/s), transport rate and its rate
    non-zero, the body turning at ~0.5 rad/s."""
    origin = (30.0, -60.0, 500.0)
    ref = Reference("NED", origin, MANOEUVRE, TURNING)
    _check(ref, _scene("NED", origin, MANOEUVRE, TURNING, ("earth_rate", "coriolis")))


def test_ecef_frame_scene():
    """(c) The trajectory given in ECEF coordinates, attitude relative to local NED."""
    with mp.workdps(DPS):
        r0 = _geodetic_to_ecef(mp.radians(50), mp.radians(20), 300)
    x0, y0, z0 = (repr(float(x)) for x in r0)
    trajectory = {"x": f"{x0} + 120*t + 10*sin(0.4*t)", "y": f"{y0} - 90*t + 3*t**2",
                  "z": f"{z0} + 60*t - 20*cos(0.5*t)"}
    ref = Reference("ECEF", None, trajectory, TURNING)
    _check(ref, _scene("ECEF", None, trajectory, TURNING, ("earth_rate", "coriolis")))


def test_tangent_attitude_following_the_curvature():
    """Tangent attitude: heading and pitch follow the Earth-referenced velocity in local NED at the current
    position, so the body turns with the level frame as well as with the path."""
    origin = (-35.0, 140.0, 100.0)
    ref = Reference("NED", origin, MANOEUVRE, "tangent")
    _check(ref, _scene("NED", origin, MANOEUVRE, "tangent", ("earth_rate", "coriolis")))


@pytest.mark.parametrize("reference, effects", [
    ("ECEF", ("earth_rate", "coriolis")),
    ("ECEF", ("earth_rate",)),    # w = omega_eb is not R's rate omega_nb: alpha needs the latter (2e-9 off)
    ("ECI", ("earth_rate", "coriolis")),
    ("ECI", ("earth_rate",)),     # the level frame's own rate is then not what the gyros add back
    ("ECI", ("coriolis",)),
])
def test_attitude_given_relative_to_ecef_or_eci(reference, effects):
    """[attitude] reference = "ECEF" | "ECI": the gyros read omega_ib (ECI: whichever Earth effects are named;
    ECEF: with earth_rate), and the arm's terms follow from the ECI attitude."""
    origin = (60.0, 5.0, 0.0)
    ref = Reference("NED", origin, MANOEUVRE, TURNING, reference=reference)
    _check(ref, _scene("NED", origin, MANOEUVRE, TURNING, effects, reference=reference))


def test_linear_vibration_is_a_moving_lever_arm():
    """Linear vibration moves the IMU along d(t) in body axes (effects/vibration.py): its terms read the same
    omega_ib and omega_ib' as the lever arm, so f - f_S = C_i^b (C_b^i d)'' with d_x = -A/w^2 sin(w t),
    d_y = -A/w^2 sin(w t + phase). Slow, large lines (0.5 Hz, 1 m/s^2: |d| ~ 0.1 m) on the body spinning at
    1 rad/s at 45 deg: alpha_nb instead of omega_ib' is 4e-6 m/s^2 off (checked on the old code)."""
    origin = (45.0, 10.0, 0.0)
    trajectory = {"x": "0", "y": "0", "z": "0"}
    attitude = {"roll": "t", "pitch": "0.4", "yaw": "0.7"}
    lines = [{"axis": "x", "amplitude": 1.0, "frequency": 0.5}, {"axis": "y", "amplitude": 1.0, "frequency": 0.5,
                                                                   "phase": 1.0}]
    scene = scene_from_dict({
        "scene": {"rate_hz": RATE_HZ, "duration_s": DURATION, "frame": "NED", "gravity_model": "wgs84",
                  "origin": {"lat_deg": origin[0], "lon_deg": origin[1], "height_m": origin[2]}},
        "trajectory": trajectory, "attitude": attitude,
        "imu": [{"name": "s"}, {"name": "vib", "vibration": {"sines": lines}}],
        "effects": {"gravity": True, "earth_rate": True, "coriolis": True, "vibration": True}})
    out = Simulation(scene, attitude=False).run()
    ref = Reference("NED", origin, trajectory, attitude)
    with mp.workdps(DPS):
        w = 2 * mp.pi * mp.mpf("0.5")

        def d(t):
            return mp.matrix([-mp.sin(w * t) / w ** 2, -mp.sin(w * t + 1) / w ** 2, 0])
        for k in CHECKED:
            t = mp.mpf(float(out.t_s[k]))
            lever = ref.lever(t, d)
            np.testing.assert_allclose(out.accel[1, k] - out.accel[0, k], [float(x) for x in lever],
                                       rtol=0, atol=TOL_F)
