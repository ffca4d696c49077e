"""Closed loop: a strapdown integrator written here, independent of the kernel (ECEF mechanization, Groves 2nd
ed. §5.2: r' = v, v' = C_b^e f - 2 omega_ie x v + g(r), C_b^e' = C_b^e [omega_ib x] - [omega_ie x] C_b^e),
fed the emulator's rate samples for a 600 s manoeuvre at 100 Hz with every Earth effect on, must come back to
the true trajectory.

Rate samples are the values at the sample instants, so the integrator is RK4 over pairs of intervals (samples
k, k+1, k+2 are the start, middle and end of one 0.02 s step): its truncation error is O(h^5) per step, far
below the goal, so what is left is what the emulator got wrong. The same loop fed exact increments is below.

Gravity here is the spec's: Somigliana with TR8350.2's height term along the ellipsoid normal, plus its north
component off the ellipsoid, from geodetic coordinates computed below by Bowring's formula iterated (not
imu_emulator.geo.frames).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_emulator import scene_from_dict
from imu_emulator.runtime.simulation import Simulation

A, F, W = 6378137.0, 1 / 298.257223563, 7.292115e-5
E2 = F * (2 - F)
B = A * (1 - F)
GE, GP, GM = 9.7803253359, 9.8321849378, 3.986004418e14
K = B * GP / (A * GE) - 1
M = W * W * A * A * B / GM
OMEGA = np.array([0.0, 0.0, W])

ORIGIN = {"lat_deg": 45.0, "lon_deg": 7.0, "height_m": 300.0}
RATE, DURATION = 100, 600.0


def gravity_ecef(r):
    x, y, z = r
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1 - E2))
    for _ in range(5):
        n = A / math.sqrt(1 - E2 * math.sin(lat) ** 2)
        h = p * math.cos(lat) + z * math.sin(lat) - A * A / n
        lat = math.atan2(z, p * (1 - E2 * n / (n + h)))
    n = A / math.sqrt(1 - E2 * math.sin(lat) ** 2)
    h = p * math.cos(lat) + z * math.sin(lat) - A * A / n
    s2 = math.sin(lat) ** 2
    g = GE * (1 + K * s2) / math.sqrt(1 - E2 * s2) * (1 - 2 / A * (1 + F + M - 2 * F * s2) * h + 3 / A ** 2 * h * h)
    lon = math.atan2(y, x)
    down = np.array([-math.cos(lat) * math.cos(lon), -math.cos(lat) * math.sin(lon), -math.sin(lat)])
    north = np.array([-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat)])
    # off the ellipsoid gravity leans north by g_N = -h / R_N dgamma_0/dL (curl-free field; Groves eq. 2.142),
    # dgamma_0/dL here by a central difference of Somigliana's formula
    gamma0 = lambda x: GE * (1 + K * math.sin(x) ** 2) / math.sqrt(1 - E2 * math.sin(x) ** 2)   # noqa: E731
    r_n = A * (1 - E2) / (1 - E2 * s2) ** 1.5
    g_n = -h / r_n * (gamma0(lat + 1e-5) - gamma0(lat - 1e-5)) / 2e-5
    return g * down + g_n * north


def skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def derivative(state, f, w):
    r, v, c = state
    return (v, c @ f - 2 * np.cross(OMEGA, v) + gravity_ecef(r), c @ skew(w) - skew(OMEGA) @ c)


def rk4(state, f, w, h):
    """f, w: (3, 3) samples at the step's start, middle, end."""
    def add(s, d, k):
        return tuple(a + k * b for a, b in zip(s, d))
    k1 = derivative(state, f[0], w[0])
    k2 = derivative(add(state, k1, h / 2), f[1], w[1])
    k3 = derivative(add(state, k2, h / 2), f[1], w[1])
    k4 = derivative(add(state, k3, h), f[2], w[2])
    r, v, c = (s + h / 6 * (a + 2 * b + 2 * cc + d) for s, a, b, cc, d in zip(state, k1, k2, k3, k4))
    u, _, vt = np.linalg.svd(c)     # back onto the rotation group
    return r, v, u @ vt


def ned_from_ecef(lat_deg, lon_deg):
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    return np.array([[-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)],
                     [-math.sin(lo), math.cos(lo), 0.0],
                     [-math.cos(la) * math.cos(lo), -math.cos(la) * math.sin(lo), -math.sin(la)]])


def body_to_ecef(truth, k):
    from scipy.spatial.transform import Rotation
    c_nb = Rotation.from_euler("ZYX", truth["euler_ned"][k, ::-1]).as_matrix()
    lat, lon, _ = truth["geodetic"][k]
    return ned_from_ecef(lat, lon).T @ c_nb


EVERYTHING = {"gravity": True, "earth_rate": True, "coriolis": True}


def _scene(duration_s, effects):
    return scene_from_dict({
        "scene": {"rate_hz": RATE, "duration_s": duration_s, "frame": "NED", "gravity_model": "wgs84",
                  "origin": ORIGIN},
        "trajectory": {"x": "3000*sin(2*pi*t/300)", "y": "50*t + 500*sin(2*pi*t/120)", "z": "-100*sin(2*pi*t/200)"},
        "attitude": {"roll": "0.3*sin(2*pi*t/20)", "pitch": "0.1*sin(2*pi*t/30)",
                     "yaw": "0.5*t/60 + 0.2*sin(2*pi*t/45)"},
        "imu": [{"name": "imu0"}],
        "effects": effects})


def closed_loop(duration_s=DURATION, effects=EVERYTHING):
    run = Simulation(_scene(duration_s, effects), attitude=False, truth=True).run()
    f, w, truth = run.accel[0], run.gyro[0], run.truth
    n = len(f) - 1 - (len(f) - 1) % 2
    state = (truth["position_ecef"][0].copy(), truth["velocity_ecef"][0].copy(), body_to_ecef(truth, 0))
    h = 2.0 / RATE
    for k in range(0, n, 2):
        state = rk4(state, f[k:k + 3], w[k:k + 3], h)
    r, v, c = state
    c_ne = ned_from_ecef(*truth["geodetic"][n, :2])
    error_ned = c_ne @ (r - truth["position_ecef"][n])
    from scipy.spatial.transform import Rotation
    # the rotation vector's length, not acos of the trace (which cannot resolve below ~1e-8 rad)
    attitude_deg = math.degrees(Rotation.from_matrix(c @ body_to_ecef(truth, n).T).magnitude())
    return float(np.hypot(*error_ned[:2])), float(abs(error_ned[2])), attitude_deg, n / RATE


@pytest.mark.slow
def test_closed_loop_600s_from_rate_samples():
    horizontal, vertical, attitude, span = closed_loop()
    print(f"closed loop over {span:g} s from rate samples (RK4): horizontal {horizontal:.3g} m, "
          f"vertical {vertical:.3g} m, attitude {attitude:.3g} deg")
    assert horizontal < 0.1 and attitude < 1e-5


def test_closed_loop_60s_from_rate_samples():
    """The fast twin of the 600 s run: same motion, same bounds (errors grow with time, so the bounds hold
    a fortiori)."""
    horizontal, vertical, attitude, _ = closed_loop(60.0)
    assert horizontal < 0.01 and attitude < 1e-6


def test_closed_loop_notices_a_missing_earth_term():
    """The loop is sharp: without the Coriolis and transport-rate terms in the samples it drifts off by
    metres within the same 60 s."""
    horizontal, _, attitude, _ = closed_loop(60.0, {"gravity": True, "earth_rate": True})
    assert horizontal > 1.0 and attitude > 1e-3


# --- fed exact increments (Simulation(..., increments=NODES)) -----------------------------------------------

def gravitation_eci(r_i, t):
    """Gravitation (gravity plus the centripetal term it hides) in ECI, axes on ECEF's at t = 0."""
    c = np.array([[math.cos(W * t), math.sin(W * t), 0.0], [-math.sin(W * t), math.cos(W * t), 0.0], [0, 0, 1.0]])
    r_e = c @ r_i
    return c.T @ (gravity_ecef(r_e) + np.cross(OMEGA, np.cross(OMEGA, r_e)))


def closed_loop_increments(duration_s=DURATION, nodes=3, rate_times_dt=False):
    """ECI mechanization fed (dtheta, dvel) over (t_k-1, t_k]: attitude by rotation vector with two-sample
    coning, velocity with the rotation term and two-sample sculling (Savage 1998), gravitation and position by
    trapezoid with a predictor. Returns the errors at the end as closed_loop does. rate_times_dt feeds it the
    rate samples times the interval instead (what a driver without increments would do), for comparison."""
    from scipy.spatial.transform import Rotation
    scene = _scene(duration_s, EVERYTHING)
    run = Simulation(scene, attitude=False, truth=True, increments=nodes).run()
    h = 1.0 / RATE
    dth, dv, truth = run.dtheta[0], run.dvel[0], run.truth
    if rate_times_dt:
        dth, dv = run.gyro[0] * h, run.accel[0] * h
    r = truth["position_ecef"][0].copy()               # ECI = ECEF at t = 0
    v = truth["velocity_ecef"][0] + np.cross(OMEGA, r)
    c = body_to_ecef(truth, 0)
    n = len(dth) - 1
    g_prev = gravitation_eci(r, 0.0)
    for k in range(1, n + 1):
        a, b = dth[k], dv[k]
        a0, b0 = (dth[k - 1], dv[k - 1]) if k > 1 else (a, b)
        dv_i = c @ (b + 0.5 * np.cross(a, b) + (np.cross(a0, b) + np.cross(b0, a)) / 12.0)
        c = c @ Rotation.from_rotvec(a + np.cross(a0, a) / 12.0).as_matrix()
        v_pred = v + dv_i + g_prev * h
        g_new = gravitation_eci(r + 0.5 * h * (v + v_pred), k * h)
        v_new = v + dv_i + 0.5 * h * (g_prev + g_new)
        r = r + 0.5 * h * (v + v_new)
        v = v_new
        g_prev = gravitation_eci(r, k * h)
    t = n * h
    c_ie = np.array([[math.cos(W * t), math.sin(W * t), 0.0], [-math.sin(W * t), math.cos(W * t), 0.0], [0, 0, 1.0]])
    error_ned = ned_from_ecef(*truth["geodetic"][n, :2]) @ (c_ie @ r - truth["position_ecef"][n])
    attitude_deg = math.degrees(Rotation.from_matrix(c_ie @ c @ body_to_ecef(truth, n).T).magnitude())
    return float(np.hypot(*error_ned[:2])), float(abs(error_ned[2])), attitude_deg, t


@pytest.mark.slow
def test_closed_loop_600s_from_increments():
    """The issue's goal: 0.1 m horizontal, 1e-5 deg over 600 s at 100 Hz (measured: 3.0e-3 m horizontal,
    0.15 m vertical, 1.4e-9 deg; the same integrator fed rate x dt instead ends 806 m and 0.03 deg off)."""
    horizontal, vertical, attitude, span = closed_loop_increments()
    print(f"closed loop over {span:g} s from increments: horizontal {horizontal:.3g} m, vertical {vertical:.3g} m, "
          f"attitude {attitude:.3g} deg")
    naive = closed_loop_increments(rate_times_dt=True)
    print(f"the same integrator fed rate x dt: horizontal {naive[0]:.3g} m, vertical {naive[1]:.3g} m, "
          f"attitude {naive[2]:.3g} deg")
    assert horizontal < 0.1 and attitude < 1e-5


def test_closed_loop_60s_from_increments():
    horizontal, _, attitude, _ = closed_loop_increments(60.0)
    assert horizontal < 0.01 and attitude < 1e-6
