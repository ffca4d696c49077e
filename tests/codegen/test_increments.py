"""Integrated outputs (imu_emulator.codegen.increments): Δθ and Δv against the analytic integrals of a symbolic motion.

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
from sympy.simplify.fu import TR8
from scipy.spatial.transform import Rotation

from imu_emulator import scene_from_dict
from imu_emulator.codegen.increments import DEFAULT_NODES, nodes
from imu_emulator.codegen.generate import generate_source
from imu_emulator.runtime.simulation import Simulation

G0 = sympy.Rational("9.80665")
LEVER = (sympy.Rational(1, 10), sympy.Rational(-1, 20), sympy.Rational(1, 50))
MOUNT_RPY_DEG = (10.0, -20.0, 35.0)
RATE = 100
DURATION = 1.0

# The motion: text for the scene, and the same as sympy expressions of t (rationals, so nothing is rounded).
T = sympy.Symbol("t", real=True)
MOTION = {
    "x": ("0.5*t**2 + 0.3*sin(2.1*t)",
          sympy.Rational(1, 2) * T**2 + sympy.Rational(3, 10) * sympy.sin(sympy.Rational(21, 10) * T)),
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
    skew = R.T * R.diff(T)
    omega = sympy.Matrix([sympy.trigsimp(sympy.expand(skew[i, j])) for i, j in ((2, 1), (0, 2), (1, 0))])
    alpha = omega.diff(T)
    a = sympy.Matrix([MOTION[c][1] for c in "xyz"]).diff(T, 2)
    f = R.T * (a + sympy.Matrix([0, 0, G0]))          # ENU: g = (0, 0, -g0)
    r = sympy.Matrix(LEVER)
    f = f + omega.cross(omega.cross(r)) + alpha.cross(r)
    # products of sines and cosines turned into sums (sympy's TR8): every term is then t^n sin/cos(c t + d),
    # which sympy integrates at once
    return [sympy.expand(TR8(sympy.expand(e))) for e in omega], [sympy.expand(TR8(sympy.expand(e))) for e in f]


@pytest.fixture(scope="module")
def analytic():
    """(Δθ, Δv) in sensor axes for every sample of the scene, from the symbolic antiderivatives."""
    omega, f = body_integrands()
    ends = [mpmath.mpf(k) / RATE for k in range(-1, round(DURATION * RATE))]
    out = []
    for parts in (omega, f):
        body = np.empty((len(ends) - 1, 3))
        for c, e in enumerate(parts):
            F = sympy.Add(*[sympy.integrate(term, T) for term in sympy.Add.make_args(e)])
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
    # the module that writes those lines is part of the cache key
    from imu_emulator.runtime.cache import generator_modules
    assert any(path.name == "increments.py" for path in generator_modules())


# --- sensor errors on the increments (module docstring of imu_emulator.codegen.increments) -----------------------

def _pair(effects, gyro=None, accel=None, truth=False, seed=None, **imu):
    """The same motion without and with the given sensor-stage effects."""
    clean = Simulation(scene(), attitude=False, increments=DEFAULT_NODES).run()
    sc = scene(effects=("gravity", "lever_arm", "mounting", *effects), seed=seed,
               imu={"gyro": dict(gyro or {}), "accel": dict(accel or {}), **imu})
    return clean, Simulation(sc, attitude=False, truth=truth, increments=DEFAULT_NODES).run()


def test_deterministic_errors_apply_to_the_increment_vectors():
    # closed form: Δθ' = (I + S + M) Δθ + b T + G Δv, Δv' = (I + S + M) Δv + b T, T = 1/rate
    s_g, mis_g = np.array([500e-6, -300e-6, 1e-3]), np.array([[0, 1e-3, -2e-3], [5e-4, 0, 1.5e-3], [-1e-3, 2e-3, 0]])
    b_g, b_a, s_a, g_sens = np.array([0.01, -0.02, 0.005]), np.array([0.1, 0.05, -0.2]), 0.003, 2e-3
    clean, out = _pair(("bias", "scale_factor", "misalignment", "g_sensitivity"),
                       gyro={"bias": b_g.tolist(), "scale_factor": s_g.tolist(), "misalignment": mis_g.tolist(),
                             "g_sensitivity": g_sens},
                       accel={"bias": b_a.tolist(), "scale_factor": s_a})
    th, dv = clean.dtheta[0], clean.dvel[0]
    want_th = th @ (np.eye(3) + np.diag(s_g) + mis_g).T + b_g / RATE + g_sens * dv
    want_dv = dv @ ((1 + s_a) * np.eye(3)).T + b_a / RATE
    np.testing.assert_allclose(out.dtheta[0], want_th, rtol=0, atol=1e-12 * np.abs(want_th).max())
    np.testing.assert_allclose(out.dvel[0], want_dv, rtol=0, atol=1e-12 * np.abs(want_dv).max())


def test_stateful_errors_add_the_realized_bias_times_the_interval_and_leave_the_samples_alone():
    gyro = {"bias": 0.01, "turn_on_bias_sd": 0.02, "random_walk": 0.05, "bias_instability": 0.003}
    accel = {"random_walk": 0.02, "bias_instability": 0.01, "bias_tc": 0.001}
    effects = ("bias", "random_walk", "bias_instability", "temperature")
    clean, out = _pair(effects, gyro=gyro, accel=accel, truth=True, seed=11, temperature_c="25 + 10*t")
    np.testing.assert_allclose(out.dtheta[0] - clean.dtheta[0], out.truth["gyro_bias"][0] / RATE, rtol=0, atol=1e-15)
    np.testing.assert_allclose(out.dvel[0] - clean.dvel[0], out.truth["accel_bias"][0] / RATE, rtol=0, atol=1e-15)
    # the increments' pass restores the state it advanced: the samples are those of a run without increments
    sc = scene(effects=("gravity", "lever_arm", "mounting", *effects), seed=11,
               imu={"gyro": gyro, "accel": accel, "temperature_c": "25 + 10*t"})
    plain = Simulation(sc, attitude=False).run()
    np.testing.assert_array_equal(out.gyro, plain.gyro)
    np.testing.assert_array_equal(out.accel, plain.accel)


def test_white_noise_on_an_increment_has_the_integrated_sigma():
    n_sec, density = 200.0, 0.01        # 20 000 intervals per axis at 100 Hz
    sc = scene(effects=("noise",), duration_s=n_sec, x="0", y="0", z="0", roll="0", pitch="0", yaw="0",
               seed=5, imu={"gyro": {"noise_density": density}, "accel": {"noise_density": 2 * density}})
    out = Simulation(sc, attitude=False, increments=2).run()
    # white noise of density N integrated over T has sigma N sqrt(T). The sample standard deviation of n
    # independent normals has relative standard error 1/sqrt(2(n - 1)) (chi-square); 60 000 values give
    # 0.29 %, and 5 of those (1.4 %) bound a false failure below 1e-6.
    tolerance = 5 / math.sqrt(2 * (out.dtheta[0].size - 1))
    assert np.std(out.dtheta[0]) == pytest.approx(density * math.sqrt(1 / RATE), rel=tolerance)
    assert np.std(out.dvel[0] - out.dvel[0].mean(axis=0)) == pytest.approx(   # gravity, mounted, is constant
        2 * density * math.sqrt(1 / RATE), rel=tolerance)
    # and the rate sample is the same draw: the increment over T divided by T
    np.testing.assert_allclose(out.dtheta[0] * RATE, out.gyro[0], rtol=1e-12, atol=1e-15)


# --- clock and sampled motion ---------------------------------------------------------------------------

W_YAW, A_YAW = 2 * math.pi * 1.3, 0.3


def _yaw_integral(t_end, t_start):
    """∫ gyro z = A (sin w t_end − sin w t_start) for yaw = A sin(w t), 30 digits."""
    with mpmath.workdps(30):
        return np.array([float(A_YAW * (mpmath.sin(W_YAW * mpmath.mpf(b)) - mpmath.sin(W_YAW * mpmath.mpf(a))))
                         for a, b in zip(t_start, t_end)])


def _yaw_scene(clock):
    return scene(effects=("clock",), x="0", y="0", z="0", roll="0", pitch="0", yaw=f"{A_YAW}*sin({W_YAW!r}*t)",
                 imu={"mounting_rpy_deg": [0, 0, 0], **clock}, seed=3)


def test_clock_error_integrates_between_the_actual_instants():
    from imu_emulator.effects.clock import offsets
    for clock in ({"clock_ppm": 200.0}, {"clock_jitter_s": 1e-4}):
        sc = _yaw_scene(clock)
        out = Simulation(sc, attitude=False, increments=DEFAULT_NODES).run()
        n = out.dtheta.shape[1]
        clk = offsets(sc, 3, -1, -1, n + 1)         # instants k = -1 .. n-1, run samples -1 .. n-1
        instants = (np.arange(-1, n) + clk) / RATE
        exact = _yaw_integral(instants[1:], instants[:-1])
        np.testing.assert_allclose(out.dtheta[0, :, 2], exact, rtol=0, atol=1e-12 * A_YAW * W_YAW / RATE)
        # consecutive intervals tile time: the sum is the integral from the first instant to the last
        assert float(np.sum(out.dtheta[0, :, 2])) == pytest.approx(
            float(_yaw_integral(instants[-1:], instants[:1])[0]), abs=1e-12)


def test_sampled_motion_increments_follow_the_fitted_curve():
    # The sampled path is fitted (spline5) to data of the symbolic twin; its rates converge to the twin's,
    # and so must its increments, to the same accuracy times the interval (they read node rows of `mot`).
    from tests.motion.test_kinematics import _sampled_scene, _symbolic_twin
    truth = Simulation(_symbolic_twin(), attitude=False, increments=3).run()
    sampled = Simulation(_sampled_scene(400, "spline5"), attitude=False, increments=3).run()
    interior = slice(100, -100)
    rate_error = np.abs(sampled.accel[0, interior] - truth.accel[0, interior]).max()
    inc_error = np.abs(sampled.dvel[0, interior] - truth.dvel[0, interior]).max()
    assert inc_error <= 2 * rate_error / 1000
    assert np.abs(truth.dvel[0] - truth.accel[0] / 1000).max() > 10 * inc_error   # not the rate times dt


def test_sampled_motion_starting_at_its_first_stamp_holds_it_over_the_first_interval():
    """The first sample's interval (t_-1, t_0] lies before waypoints' first stamp: the body is held in that
    stamp's state, so the first increments are that sample's rate and force times the interval (the integral of
    a constant). Before, the evaluation outside the data span failed, and every stream whose device carries
    increments (VectorNav, MIP) stopped at its start on such a scene."""
    raw = {"scene": {"rate_hz": 400, "frame": "NED"},
           "trajectory": {"shape": "waypoints", "positions_m": [[0, 0, 0], [3, 1, -2], [5, 4, -2]],
                          "times_s": [0, 1.5, 3], "attitudes_deg": [[0, 0, 30], [4, -3, 50], [0, 0, 90]],
                          "ends": "coast"},
           "imu": [{"name": "imu0"}], "effects": {"gravity": True}}
    block = Simulation(scene_from_dict(raw), increments=DEFAULT_NODES).block(0, 400)
    dt = 1 / 400
    np.testing.assert_allclose(block.dvel[0, 0], block.accel[0, 0] * dt, rtol=0, atol=1e-15)
    np.testing.assert_allclose(block.dtheta[0, 0], block.gyro[0, 0] * dt, rtol=0, atol=1e-15)
    assert np.abs(block.gyro[0, 0]).max() > 1e-3       # moving ("coast" ends): a held state, not a zero
    # the second interval lies inside the data: no longer the rate times dt
    assert np.abs(block.dvel[0, 1] - block.accel[0, 1] * dt).max() > 1e-9


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_generate_writes_the_increments(tmp_path, analytic, suffix):
    import pyarrow.csv as pa_csv

    from imu_emulator.cli import main
    path = tmp_path / "scene.toml"
    lines = ["[scene]", f"rate_hz = {RATE}", f"duration_s = {DURATION}", "[trajectory]"]
    lines += [f'{a} = "{MOTION[a][0]}"' for a in "xyz"] + ["[attitude]", 'mode = "euler"']
    lines += [f'{a} = "{MOTION[a][0]}"' for a in ("roll", "pitch", "yaw")]
    lines += ["[[imu]]", 'name = "imu0"', f"lever_arm_m = {[float(v) for v in LEVER]}",
              f"mounting_rpy_deg = {list(MOUNT_RPY_DEG)}", "[effects]", "gravity = true", "lever_arm = true",
              "mounting = true"]
    path.write_text("\n".join(lines) + "\n")
    out = tmp_path / f"out{suffix}"
    assert main(["generate", str(path), "-o", str(out), "--increments", "--quiet"]) == 0
    if suffix == ".csv":
        statement = sum(line.startswith("#") for line in out.read_text().splitlines())     # frames and units
        table = pa_csv.read_csv(out, read_options=pa_csv.ReadOptions(skip_rows=statement)).to_pydict()
        assert list(table)[8:14] == ["dtheta_x", "dtheta_y", "dtheta_z", "dvel_x", "dvel_y", "dvel_z"]
        dtheta = np.column_stack([table[f"dtheta_{a}"] for a in "xyz"])
        dvel = np.column_stack([table[f"dvel_{a}"] for a in "xyz"])
    else:
        with np.load(out) as data:
            dtheta, dvel = data["dtheta"][0], data["dvel"][0]
    assert relative_error(dtheta, analytic[0]) < 1e-12
    assert relative_error(dvel, analytic[1]) < 1e-12


def test_stateful_or_random_navigation_effects_are_refused():
    # The node loop reruns the navigation and body stages; an effect there that advanced state or drew
    # numbers would do so once per node. None exists today: a record built here stands for a future one.
    from imu_emulator.effects import EFFECTS, Effect, Stage
    from imu_emulator.errors import ImuEmulatorError
    from imu_emulator.codegen.increments import check_integrable
    check_integrable(EFFECTS.values())
    drifting = Effect(name="drift", description="", stage=Stage.BODY, order=5, emit=lambda ctx: [], state=("x",))
    with pytest.raises(ImuEmulatorError, match="effect 'drift' keeps state"):
        check_integrable([drifting])
