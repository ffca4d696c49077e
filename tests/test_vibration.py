"""The vibration effect as motion of the IMU: sinusoidal lines against closed forms, the general case (a turning,
rolling body, linear and two-axis angular lines: coning) against a sympy derivation of the IMU's own motion, the
random part's PSD level against Welch's chi-square interval, and the vibration rectification of a quadratic
nonlinearity (K2 a0^2 / 2)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from scipy import signal, stats

from imu_emulator import scene_from_dict
from imu_emulator.errors import SceneError
from imu_emulator.runtime.simulation import Simulation

G0 = 9.80665


def scene(vibration, effects=("gravity", "vibration"), rate_hz=1000, duration_s=0.5, attitude=None, seed=1,
          **imu):
    return scene_from_dict({
        "scene": {"rate_hz": rate_hz, "duration_s": duration_s, "seed": seed},
        "trajectory": {"x": "0", "y": "0", "z": "0"},
        **({"attitude": attitude} if attitude else {}),
        "imu": [{"name": "imu0", "vibration": vibration, **imu}],
        "effects": {name: True for name in effects}})


def run(s, attitude=False):
    return Simulation(s, attitude=attitude).run()


def test_linear_and_angular_sines_against_closed_forms():
    # x: 2 g at 37 Hz, phase 30 deg (linear); y: 3 deg/s at 11 Hz (angular). A body at rest, ENU: the IMU's axes
    # are turned by b = -A_w / w cos(w t) about y, so f = Ry(b)^T (a_x, 0, g), omega = (0, A_w sin(w t), 0).
    out = run(scene({"sines": [{"axis": "x", "amplitude": "2 g", "frequency": "37 Hz", "phase": "30 deg"},
                               {"axis": "y", "amplitude": "3 deg/s", "frequency": "11 Hz"}]}))
    t = out.t_s
    a_x = 2 * G0 * np.sin(2 * np.pi * 37 * t + np.pi / 6)
    rate = math.radians(3)
    b = -rate / (2 * np.pi * 11) * np.cos(2 * np.pi * 11 * t)
    expected_f = np.stack([np.cos(b) * a_x - np.sin(b) * G0, 0 * t, np.sin(b) * a_x + np.cos(b) * G0], axis=1)
    np.testing.assert_allclose(out.accel[0], expected_f, rtol=0, atol=1e-12 * 2 * G0)
    np.testing.assert_allclose(out.gyro[0], np.stack([0 * t, rate * np.sin(2 * np.pi * 11 * t), 0 * t], axis=1),
                               rtol=0, atol=1e-12 * rate)


def _rot(axis, angle):
    c, s = sp.cos(angle), sp.sin(angle)
    return {"x": sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": sp.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def test_vibration_on_a_moving_body_is_the_imus_own_motion_sympy():
    """The IMU at body point d(t) (linear lines, body axes) with axes R_b R_v (angular lines on x and z, 90 deg
    apart: coning), the body rolling and turning: sympy differentiates the IMU's position and attitude directly
    (f = R^T (p'' + g e_z), omega = vee(R^T R')), independent of the kernel's lever-arm and rotation terms."""
    t = sp.symbols("t", real=True)
    lines = [("x", "linear", 3.0, 13.0, 0.4), ("y", "linear", 1.5, 7.0, 0.0), ("z", "linear", 2.0, 5.0, 1.0),
             ("x", "angular", 0.2, 9.0, 0.0), ("z", "angular", 0.2, 9.0, math.pi / 2), ("y", "angular", 0.1, 4.0, 0.3)]
    vib = {"sines": [{"axis": a, "kind": k, "amplitude": amp, "frequency": f, "phase": ph}
                     for a, k, amp, f, ph in lines]}
    out = run(scene(vib, rate_hz=200, duration_s=0.5,
                    attitude={"roll": "0.3*sin(0.5*t)", "pitch": "0.1*t", "yaw": "0.4*t"}))
    d = {a: sp.Integer(0) for a in "xyz"}
    ang = {a: sp.Integer(0) for a in "xyz"}
    for axis, kind, amp, f, ph in lines:
        w = 2 * sp.pi * f
        if kind == "linear":      # d'' = A sin(w t + ph)
            d[axis] += -amp / w ** 2 * sp.sin(w * t + ph)
        else:                     # angle' = A sin(w t + ph)
            ang[axis] += -amp / w * sp.cos(w * t + ph)
    r_b = _rot("z", 0.4 * t) * _rot("y", 0.1 * t) * _rot("x", 0.3 * sp.sin(0.5 * t))
    r_v = _rot("x", ang["x"]) * _rot("y", ang["y"]) * _rot("z", ang["z"])
    r = r_b * r_v
    p = r_b * sp.Matrix([d["x"], d["y"], d["z"]])
    f = r.T * (p.diff(t, 2) + sp.Matrix([0, 0, G0]))
    omega = r.T * r.diff(t)
    w_vec = sp.Matrix([omega[2, 1], omega[0, 2], omega[1, 0]])
    f_num, w_num = sp.lambdify(t, f, "numpy"), sp.lambdify(t, w_vec, "numpy")
    for j in (0, 17, 50, 99):
        tj = float(out.t_s[j])
        np.testing.assert_allclose(out.accel[0, j], np.ravel(f_num(tj)).astype(float), rtol=0, atol=1e-10)
        np.testing.assert_allclose(out.gyro[0, j], np.ravel(w_num(tj)).astype(float), rtol=0, atol=1e-12)


def test_quadratic_nonlinearity_dc_shift_under_a_sine_vibration_effect():
    a0, k2 = 20.0, 3e-3
    out = run(scene({"sines": [{"axis": "x", "amplitude": a0, "frequency": "50 Hz"}]},
                    effects=("gravity", "vibration", "nonlinearity"), duration_s=1.0,
                    accel={"nonlinearity": [k2, 0.0, 0.0]}))
    # 1000 samples = 50 whole periods, 20 samples each: the sampled mean of sin^2 is exactly 1/2, of sin 0
    assert abs(out.accel[0, :, 0].mean() - k2 * a0 ** 2 / 2) < 1e-12


PSD_G2HZ, F_LO, F_HI, RATE, SECONDS, NPERSEG = 0.01, 50.0, 400.0, 2000, 64.0, 1024


@pytest.fixture(scope="module")
def random_vibration():
    return scene({"psd": [[f"{F_LO} Hz", f"{PSD_G2HZ} g^2/Hz"], [f"{F_HI} Hz", f"{PSD_G2HZ} g^2/Hz"]],
                  "psd_lines": 1000, "psd_axes": [1.0, 0.0, 0.0]},
                 rate_hz=RATE, duration_s=SECONDS, seed=7)


def assert_flat_psd(x, level):
    """x's Welch PSD is `level` across [F_LO, F_HI] (chi-square intervals) and nothing outside."""
    freqs, pxx = signal.welch(x, fs=RATE, window="hann", nperseg=NPERSEG, noverlap=0, detrend="constant")
    inside = (freqs > F_LO + 10) & (freqs < F_HI - 10)     # away from the band edges' window leakage
    segments = x.size // NPERSEG
    # For a Gaussian process each bin is level * chi2(2K) / 2K over K non-overlapping segments. A sum of
    # sinusoids with random phases has no such spread from the lines' powers (they are exact), but the cross
    # terms of lines within one window bandwidth average out over the segments only where their beat is not near
    # a multiple of 1/T_seg, so a single bin can leave that interval; means over bins average the cross terms
    # (their signs are random). Hann makes neighbouring bins correlated: count K degrees of freedom per bin, half
    # of 2K. Checked: the band's mean (two-sided 1e-3) and the mean of each of 5 sub-bands (two-sided 1e-3 / 5,
    # Bonferroni), which also checks the spectrum is flat across the band.
    n_bins = int(inside.sum())
    nu = segments * n_bins
    lo, hi = stats.chi2.ppf([0.5e-3, 1 - 0.5e-3], nu) / nu
    assert lo * level < pxx[inside].mean() < hi * level, pxx[inside].mean() / level
    for part in np.array_split(pxx[inside], 5):
        nu = segments * part.size
        lo, hi = stats.chi2.ppf([0.1e-3, 1 - 0.1e-3], nu) / nu
        assert lo * level < part.mean() < hi * level, part.mean() / level
    # outside the band: nothing but the edges' leakage (far below the level)
    assert np.all(pxx[(freqs > F_HI + 20) | ((freqs < F_LO - 20) & (freqs > 0))] < 1e-3 * level)


def test_random_vibration_psd_level_by_welch_within_chi_square_interval(random_vibration):
    out = run(random_vibration)
    assert_flat_psd(out.accel[0, :, 0], PSD_G2HZ * G0 ** 2)
    # the y and z axes carry no vibration (weight 0): z is gravity exactly
    np.testing.assert_array_equal(out.accel[0, :, 1], 0.0)
    np.testing.assert_allclose(out.accel[0, :, 2], G0, rtol=1e-15)


def test_random_vibration_same_bytes_for_any_block_size_and_new_phases_for_another_seed(random_vibration):
    whole = Simulation(random_vibration, attitude=False).block(0, 3000).accel
    sim = Simulation(random_vibration, attitude=False)
    parts = np.concatenate([sim.block(k, n).accel for k, n in ((0, 1), (1, 7), (8, 992), (1000, 2000))], axis=1)
    assert whole.tobytes() == parts.tobytes()
    other = scene_from_dict({**_raw(random_vibration, seed=8)})
    again = Simulation(other, attitude=False).block(0, 3000).accel
    assert np.abs(np.corrcoef(whole[0, :, 0], again[0, :, 0])[0, 1]) < 5 / math.sqrt(3000)


def _raw(s, seed):
    """The random_vibration scene's dict with another seed."""
    return {"scene": {"rate_hz": RATE, "duration_s": SECONDS, "seed": seed},
            "trajectory": {"x": "0", "y": "0", "z": "0"},
            "imu": [{"name": "imu0", "vibration": {
                "psd": [[f"{F_LO} Hz", f"{PSD_G2HZ} g^2/Hz"], [f"{F_HI} Hz", f"{PSD_G2HZ} g^2/Hz"]],
                "psd_lines": 1000, "psd_axes": [1.0, 0.0, 0.0]}}],
            "effects": {"gravity": True, "vibration": True}}


@pytest.mark.parametrize("vibration, message", [
    ({"sines": [{"axis": "w", "amplitude": 1, "frequency": 5}]}, r"imu\[0\]\.vibration\.sines\[0\]\.axis"),
    ({"sines": [{"axis": "x", "amplitude": "1 m", "frequency": 5}]}, r"sines\[0\]\.amplitude: .*wrong dimension"),
    ({"sines": [{"axis": "x", "amplitude": 1, "frequency": 0}]}, r"sines\[0\]\.frequency: must be positive"),
    ({"psd": [[20, 0.1], [10, 0.1]]}, r"vibration\.psd\[1\]: frequencies must increase"),
    ({"psd": [[20, "0.1 g"], [40, 0.1]]}, r"vibration\.psd\[0\]\[1\]: .*wrong dimension"),
    ({"psd": [[20, 0.1], [40, 0.1]], "psd_lines": 2.5}, r"vibration\.psd_lines: expected a whole number"),
])
def test_bad_vibration_parameters_name_the_key(vibration, message):
    with pytest.raises(SceneError, match=message):
        scene(vibration)


def test_increments_integrate_a_sine_vibration():
    # Linear x line a0 sin(w t + p) on a body at rest, no gravity: dv_x over (t-T, t] is the closed-form integral
    # a0 (cos(w (t-T) + p) - cos(w t + p)) / w; the y/z increments and dtheta stay zero. The vibration's phases are
    # drawn once per run, so the quadrature may rerun its lines at every node.
    a0, f, p = 2 * G0, 37.0, math.radians(30)
    s = scene({"sines": [{"axis": "x", "amplitude": "2 g", "frequency": "37 Hz", "phase": "30 deg"}]},
              effects=("vibration",))
    out = Simulation(s, attitude=False, increments=8).run()
    t, w, T = out.t_s, 2 * np.pi * f, 1.0 / 1000
    expected = a0 * (np.cos(w * (t - T) + p) - np.cos(w * t + p)) / w
    np.testing.assert_allclose(out.dvel[0][:, 0], expected, rtol=0, atol=1e-12 * a0 * T)
    assert np.abs(out.dvel[0][:, 1:]).max() < 1e-15 and np.abs(out.dtheta[0]).max() < 1e-15


# --- angular random vibration, the attitude output, lines above Nyquist ---------------------------------------

DEG_PSD = 0.5     # (deg/s)^2/Hz


def test_angular_random_vibration_gyro_psd_by_welch_within_chi_square_interval():
    # Angular PSD on x only, body at rest: the relative rate about x is the gyro's x reading exactly (b = c = 0 in
    # the module's relative-rate formula), so its Welch PSD is the table's level converted to (rad/s)^2/Hz; y and
    # z read zero. Same chi-square intervals as the linear PSD (assert_flat_psd).
    out = run(scene({"angular_psd": [[f"{F_LO} Hz", f"{DEG_PSD} (deg/s)^2/Hz"], [f"{F_HI} Hz", f"{DEG_PSD} deg^2/s^2/Hz"]],
                     "psd_lines": 1000, "angular_psd_axes": [1.0, 0.0, 0.0]},
                    rate_hz=RATE, duration_s=SECONDS, seed=3))
    assert_flat_psd(out.gyro[0, :, 0], DEG_PSD * math.radians(1) ** 2)
    np.testing.assert_array_equal(out.gyro[0, :, 1:], 0.0)


def _fit_line(t, x, w):
    """Least squares x = p sin(w t) + q cos(w t): the amplitude and phase of a line A sin(w t + phi)."""
    basis = np.stack([np.sin(w * t), np.cos(w * t)], axis=1)
    (p, q), *_ = np.linalg.lstsq(basis, x, rcond=None)
    return math.hypot(p, q), math.atan2(q, p)


def test_angular_psd_single_line_turns_gravity_and_the_attitude_closed_form():
    # One line (psd_lines = 1) of a flat angular PSD S on x: at the band's geometric centre f0 = sqrt(f1 f2) with
    # amplitude A = sqrt(2 S (f2 - f1)) (the whole band's power in one line) and a phase phi drawn from the seed.
    # The phase is the one unknown: fitted from the gyro, whose amplitude must then be A. Body at rest (ENU, level):
    # angle a = -A / w cos(w t + phi), gravity seen through the turned axes f = Rx(a)^T (0, 0, g) =
    # (0, g sin a, g cos a), the attitude quaternion the exact rotation by a about x: (cos a/2, sin a/2, 0, 0).
    f1, f2, level = 20.0, 80.0, math.radians(2.0) ** 2
    out = run(scene({"angular_psd": [[f1, level], [f2, level]], "psd_lines": 1, "angular_psd_axes": [1, 0, 0]},
                    duration_s=0.5, attitude={"roll": "0", "pitch": "0", "yaw": "0"}, seed=5), attitude=True)
    t, w, amp = out.t_s, 2 * np.pi * math.sqrt(f1 * f2), math.sqrt(2 * level * (f2 - f1))
    fitted, phi = _fit_line(t, out.gyro[0, :, 0], w)
    assert abs(fitted - amp) < 1e-12 * amp
    np.testing.assert_allclose(out.gyro[0, :, 0], amp * np.sin(w * t + phi), rtol=0, atol=1e-12 * amp)
    a = -amp / w * np.cos(w * t + phi)
    np.testing.assert_allclose(out.accel[0], np.stack([0 * t, G0 * np.sin(a), G0 * np.cos(a)], axis=1),
                               rtol=0, atol=1e-12 * G0)
    np.testing.assert_allclose(out.quat[0], np.stack([np.cos(a / 2), np.sin(a / 2), 0 * t, 0 * t], axis=1),
                               rtol=0, atol=1e-14)


def test_angular_psd_line_is_an_angular_sine_line():
    # A one-line angular PSD and the angular sine at the same frequency, amplitude and phase are the same motion:
    # identical outputs and attitude (coning included: a second, sinusoidal axis turns with them).
    f1, f2, level = 20.0, 80.0, 1e-3
    base = {"roll": "0.2*sin(t)", "pitch": "0.1", "yaw": "0.3*t"}
    psd = run(scene({"angular_psd": [[f1, level], [f2, level]], "psd_lines": 1, "angular_psd_axes": [0, 0, 1],
                     "sines": [{"axis": "x", "kind": "angular", "amplitude": 0.05, "frequency": 33.0}]},
                    attitude=base, seed=9), attitude=True)
    w, amp = 2 * np.pi * math.sqrt(f1 * f2), math.sqrt(2 * level * (f2 - f1))
    # the line's phase is drawn from (seed, IMU, axis) alone: fit it where the gyro's z is that line only
    alone = run(scene({"angular_psd": [[f1, level], [f2, level]], "psd_lines": 1, "angular_psd_axes": [0, 0, 1]},
                      seed=9))
    _, phi = _fit_line(alone.t_s, alone.gyro[0, :, 2], w)
    sines = run(scene({"sines": [{"axis": "x", "kind": "angular", "amplitude": 0.05, "frequency": 33.0},
                                 {"axis": "z", "kind": "angular", "amplitude": amp, "frequency": math.sqrt(f1 * f2),
                                  "phase": phi}]},
                      attitude=base), attitude=True)
    # the fitted phase is exact to ~1e-13 rad, not to the bit: compare to 1e-9
    np.testing.assert_allclose(psd.gyro, sines.gyro, rtol=0, atol=1e-9)
    np.testing.assert_allclose(psd.accel, sines.accel, rtol=0, atol=1e-9)
    np.testing.assert_allclose(psd.quat, sines.quat, rtol=0, atol=1e-9)


def test_attitude_is_body_then_vibration_then_mounting_against_scipy():
    # Angular lines on all three axes, a turning body and a mounting rotation: the IMU's attitude is
    # R_b Rx(a) Ry(b) Rz(c) M, composed here by scipy's Rotation (independent of the kernel's quaternion code):
    # R_b = Rz(yaw) Ry(pitch) Rx(roll) is intrinsic "ZYX", R_v intrinsic "XYZ", M (z-y-x) intrinsic "ZYX".
    from scipy.spatial.transform import Rotation
    lines = [("x", 0.3, 9.0, 0.2), ("y", 0.2, 4.0, 1.0), ("z", 0.25, 13.0, -0.5)]
    out = run(scene({"sines": [{"axis": a, "kind": "angular", "amplitude": amp, "frequency": f, "phase": ph}
                               for a, amp, f, ph in lines]},
                    effects=("gravity", "vibration", "mounting"), rate_hz=200,
                    attitude={"roll": "0.3*sin(0.5*t)", "pitch": "0.1*t", "yaw": "0.4*t"},
                    mounting_rpy_deg=[5.0, -10.0, 30.0]), attitude=True)
    t = out.t_s
    angles = np.stack([-amp / (2 * np.pi * f) * np.cos(2 * np.pi * f * t + ph) for _, amp, f, ph in lines], axis=1)
    body = Rotation.from_euler("ZYX", np.stack([0.4 * t, 0.1 * t, 0.3 * np.sin(0.5 * t)], axis=1))
    expected = body * Rotation.from_euler("XYZ", angles) * Rotation.from_euler("ZYX", [30.0, -10.0, 5.0],
                                                                                 degrees=True)
    got = Rotation.from_quat(out.quat[0][:, [1, 2, 3, 0]])       # scipy is scalar-last
    assert np.max((got.inv() * expected).magnitude()) < 1e-12
    # and without angular lines the attitude is the body's with mounting, as before
    plain = run(scene({"sines": [{"axis": "x", "amplitude": "1 g", "frequency": 9.0}]},
                      effects=("gravity", "vibration", "mounting"), rate_hz=200,
                      attitude={"roll": "0.3*sin(0.5*t)", "pitch": "0.1*t", "yaw": "0.4*t"},
                      mounting_rpy_deg=[5.0, -10.0, 30.0]), attitude=True)
    mounted = body * Rotation.from_euler("ZYX", [30.0, -10.0, 5.0], degrees=True)
    assert np.max((Rotation.from_quat(plain.quat[0][:, [1, 2, 3, 0]]).inv() * mounted).magnitude()) < 1e-12


def test_lines_above_nyquist_warn_once_each_and_alias():
    # rate 1000 Hz: a 700 Hz line aliases to |700 - 1000| = 300 Hz; its samples are sin(2 pi 700 k / 1000) =
    # -sin(2 pi 300 k / 1000) exactly (what a part without an anti-alias filter reads). A 400 Hz line: no warning.
    s = scene({"sines": [{"axis": "x", "amplitude": 1.0, "frequency": "700 Hz"},
                         {"axis": "y", "amplitude": 1.0, "frequency": "400 Hz"}]}, effects=("vibration",))
    assert s.warnings == ("imu[0].vibration.sines[0]: 700 Hz (x, linear) is above the Nyquist rate 500 Hz of "
                          "rate_hz = 1000: it aliases to 300 Hz (no anti-alias filter is simulated)",)
    out = run(s)
    k = np.arange(out.t_s.size)
    np.testing.assert_allclose(out.accel[0, :, 0], -np.sin(2 * np.pi * 300 * k / 1000), rtol=0, atol=1e-11)
    # a PSD band reaching past Nyquist: one warning naming the table, how many of its lines and their band. The
    # lines sit at the log-cells' centres 20 * 100^((i + 1/2) / 64) Hz, i < 64.
    centres = 20.0 * 100.0 ** ((np.arange(64) + 0.5) / 64)
    above = centres[centres > 500.0]
    s = scene({"angular_psd": [["20 Hz", "1e-4 (deg/s)^2/Hz"], ["2 kHz", "1e-4 (deg/s)^2/Hz"]], "psd_lines": 64,
               "angular_psd_axes": [0, 1, 0]})
    assert s.warnings == (f"imu[0].vibration.angular_psd: {above.size} of 64 lines above the Nyquist rate 500 Hz of "
                          f"rate_hz = 1000 ({above[0]:.4g} to {above[-1]:.4g} Hz): they alias into 0 to 500 Hz "
                          "(no anti-alias filter is simulated)",)
    # a table with every weight 0 realizes no line: no warning
    assert scene({"psd": [["20 Hz", 0.1], ["2 kHz", 0.1]], "psd_axes": 0.0}).warnings == ()


def test_check_command_prints_the_nyquist_warning(tmp_path, capsys):
    from imu_emulator.cli import main
    path = tmp_path / "shaker.toml"
    path.write_text('[scene]\nrate_hz = 200\nduration_s = 1\n[trajectory]\nx = "0"\ny = "0"\nz = "0"\n'
                    '[[imu]]\nname = "a"\n[imu.vibration]\nsines = [{axis = "z", amplitude = "1 g", '
                    'frequency = "150 Hz"}]\n[effects]\nvibration = true\n')
    main(["check", str(path)])
    assert ("imu[0].vibration.sines[0]: 150 Hz (z, linear) is above the Nyquist rate 100 Hz of rate_hz = 200: "
            "it aliases to 50 Hz") in capsys.readouterr().out


def test_increments_integrate_an_angular_random_vibration_line():
    # A one-line angular PSD on y, body at rest: the rotation is about one fixed axis, so dtheta_y over (t-T, t] is
    # the angle's change a(t) - a(t-T), a = -A / w cos(w t + phi) (phi fitted from the gyro, as above); the
    # quadrature reruns the line at every node (its phase is drawn once per run).
    f1, f2, level = 30.0, 120.0, math.radians(1.0) ** 2
    s = scene({"angular_psd": [[f1, level], [f2, level]], "psd_lines": 1, "angular_psd_axes": [0, 1, 0]},
              effects=("vibration",), seed=4)
    out = Simulation(s, attitude=False, increments=8).run()
    t, w, T, amp = out.t_s, 2 * np.pi * math.sqrt(f1 * f2), 1.0 / 1000, math.sqrt(2 * level * (f2 - f1))
    _, phi = _fit_line(t, out.gyro[0, :, 1], w)
    expected = -amp / w * (np.cos(w * t + phi) - np.cos(w * (t - T) + phi))
    np.testing.assert_allclose(out.dtheta[0][:, 1], expected, rtol=0, atol=1e-11 * amp * T)
    assert np.abs(out.dtheta[0][:, [0, 2]]).max() < 1e-15 and np.abs(out.dvel[0]).max() < 1e-15
