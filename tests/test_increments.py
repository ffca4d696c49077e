"""Integrated outputs (imu_emulator.increments): Δθ and Δv against the analytic integrals of a symbolic motion.

The reference is derived here with sympy from the definitions in DESIGN.md, independently of the kernel's
code: R = Rz(yaw) Ry(pitch) Rx(roll), [ω]× = Rᵀ dR/dt, f = Rᵀ(a − g) + ω×(ω×r) + α×r at the lever arm r,
sensor axes by the mounting rotation (scipy's Rotation). Each component is integrated symbolically; the
antiderivative is evaluated at the interval ends with 40-digit mpmath, so the reference's own error is far
below the 1e-12 asked of the emulator.
"""
from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
import sympy
from scipy.spatial.transform import Rotation

from imu_emulator import scene_from_dict
from imu_emulator.increments import DEFAULT_NODES, nodes
from imu_emulator.kernel import generate_source
from imu_emulator.simulation import Simulation

G0 = sympy.Rational("9.80665")
LEVER = (sympy.Rational(1, 10), sympy.Rational(-1, 20), sympy.Rational(1, 50))
MOUNT_RPY_DEG = (10.0, -20.0, 35.0)
RATE = 100
DURATION = 1.0

# The motion: text for the scene, and the same as sympy expressions of t (rationals, so nothing is rounded).
T = sympy.Symbol("t", real=True)
MOTION = {
    "x": ("0.5*t**2 + 0.3*sin(2.1*t)", sympy.Rational(1, 2) * T**2 + sympy.Rational(3, 10) * sympy.sin(sympy.Rational(21, 10) * T)),
    "y": ("cos(1.3*t)", sympy.cos(sympy.Rational(13, 10) * T)),
    "z": ("0.2*t**3", sympy.Rational(1, 5) * T**3),
    "roll": ("0.7*t", sympy.Rational(7, 10) * T),
    "pitch": ("0.2", sympy.Rational(1, 5)),
    "yaw": ("0.4*t + 0.1", sympy.Rational(2, 5) * T + sympy.Rational(1, 10)),
}


def scene(effects=("gravity", "lever_arm", "mounting"), rate_hz=RATE, duration_s=DURATION, t0=0.0, imu=None,
          seed=None, **motion):
    texts = {key: text for key, (text, _) in MOTION.items()}
    texts.update(motion)
    raw = {"scene": {"rate_hz": rate_hz, "duration_s": duration_s, "t0_s": t0},
           "trajectory": {a: texts[a] for a in "xyz"},
           "attitude": {"mode": "euler", **{a: texts[a] for a in ("roll", "pitch", "yaw")}},
           "imu": [{"name": "imu0", "lever_arm_m": [float(v) for v in LEVER], "mounting_rpy_deg": list(MOUNT_RPY_DEG),
                    **(imu or {})}],
           "effects": {name: True for name in effects}}
    if seed is not None:
        raw["scene"]["seed"] = seed
    return scene_from_dict(raw)


def _rot(axis, angle):
    c, s = sympy.cos(angle), sympy.sin(angle)
    return {"x": sympy.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": sympy.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": sympy.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def body_integrands():
    """ω and f at the IMU, body axes, as sympy expressions of t."""
    R = _rot("z", MOTION["yaw"][1]) * _rot("y", MOTION["pitch"][1]) * _rot("x", MOTION["roll"][1])
    skew = sympy.simplify(R.T * R.diff(T))
    omega = sympy.Matrix([skew[2, 1], skew[0, 2], skew[1, 0]])
    alpha = omega.diff(T)
    a = sympy.Matrix([MOTION[c][1] for c in "xyz"]).diff(T, 2)
    f = R.T * (a + sympy.Matrix([0, 0, G0]))          # ENU: g = (0, 0, -g0)
    r = sympy.Matrix(LEVER)
    f = f + omega.cross(omega.cross(r)) + alpha.cross(r)
    return [sympy.expand(sympy.expand_trig(e)) for e in omega], [sympy.expand(e) for e in f]


@pytest.fixture(scope="module")
def analytic():
    """(Δθ, Δv) in sensor axes for every sample of the scene, from the symbolic antiderivatives."""
    omega, f = body_integrands()
    ends = [mpmath.mpf(k) / RATE for k in range(-1, round(DURATION * RATE))]
    out = []
    for parts in (omega, f):
        body = np.empty((len(ends) - 1, 3))
        for c, e in enumerate(parts):
            F = sympy.integrate(e, T)
            assert not F.has(sympy.Integral), e
            g = sympy.lambdify(T, F, "mpmath")
            with mpmath.workdps(40):
                values = [g(t) for t in ends]
                body[:, c] = [float(b - a) for a, b in zip(values[:-1], values[1:])]
        m = Rotation.from_euler("ZYX", MOUNT_RPY_DEG[::-1], degrees=True).as_matrix()
        out.append(body @ m)                           # sensor = Mᵀ body, row-wise
    return out


def relative_error(actual, expected):
    return float(np.max(np.abs(actual - expected)) / np.max(np.abs(expected)))


def test_increments_match_the_analytic_integrals_to_1e12(analytic):
    out = Simulation(scene(), attitude=False, increments=DEFAULT_NODES).run()
    dtheta, dvel = analytic
    assert relative_error(out.dtheta[0], dtheta) < 1e-12
    assert relative_error(out.dvel[0], dvel) < 1e-12
    # not the rate times dt: that is off at the first order of the interval (a check that can fail)
    assert relative_error(out.gyro[0] / RATE, dtheta) > 1e-6


def test_block_cuts_and_far_time_do_not_change_the_increments():
    whole = Simulation(scene(), attitude=False, increments=3).run()
    sim = Simulation(scene(), attitude=False, increments=3)
    parts = [sim.block(k0, n) for k0, n in ((0, 7), (7, 50), (57, 43))]
    np.testing.assert_array_equal(np.concatenate([p.dtheta for p in parts], axis=1), whole.dtheta)
    np.testing.assert_array_equal(np.concatenate([p.dvel for p in parts], axis=1), whole.dvel)


def _quadrature_bound(count: int, omega_h: float) -> float:
    """Gauss–Legendre's error for ∫cos over an interval h, relative to h: c_N (ωh)^(2N) (module docstring)."""
    c = math.factorial(count) ** 4 / ((2 * count + 1) * math.factorial(2 * count) ** 3)
    return c * omega_h ** (2 * count)


@pytest.mark.parametrize("count", [2, 3, DEFAULT_NODES, 6])
def test_quadrature_error_stays_within_the_gauss_legendre_bound(count):
    # A yaw oscillation at 9 Hz sampled at 100 Hz (ωh = 0.57): gyro z = A w cos(w t), its integral is
    # A (sin w t_k − sin w t_k−1); the error must stay below the bound the docstring states, and the bound
    # falls with the number of nodes as it says.
    w, amp = 2 * math.pi * 9.0, 0.3
    sc = scene(effects=(), x="0", y="0", z="0", roll="0", pitch="0", yaw=f"{amp}*sin({w!r}*t)")
    out = Simulation(sc, attitude=False, increments=count).run()
    k = np.arange(out.dtheta.shape[1], dtype=float)
    with mpmath.workdps(30):
        exact = np.array([float(amp * (mpmath.sin(w * mpmath.mpf(i) / RATE) - mpmath.sin(w * mpmath.mpf(i - 1) / RATE)))
                          for i in k])
    error = np.max(np.abs(out.dtheta[0, :, 2] - exact)) / (amp * w / RATE)
    assert error <= _quadrature_bound(count, w / RATE) * 1.01 + 1e-15
    if count == DEFAULT_NODES:
        assert error < 1e-9


def test_nodes_are_gauss_legendre():
    # against the tabulated 3-point rule on [-1, 1]: ±sqrt(3/5), 0; weights 5/9, 8/9 (mapped to (0, 1))
    u, w = nodes(3)
    np.testing.assert_allclose(u, (1 + np.array([-math.sqrt(0.6), 0.0, math.sqrt(0.6)])) / 2, rtol=0, atol=1e-16)
    np.testing.assert_allclose(w, np.array([5, 8, 5]) / 18, rtol=0, atol=1e-16)


def test_kernel_without_increments_is_unchanged_and_with_them_names_the_outputs():
    sc = scene()
    off = generate_source(sc, True, False)
    on = generate_source(sc, True, False, DEFAULT_NODES)
    assert "out_dtheta" not in off and "inc_" not in off
    assert "out_dtheta, out_dvel" in on and f"for q in range({DEFAULT_NODES})" in on
