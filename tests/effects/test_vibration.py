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
from tests.support import scenes

G0 = 9.80665


def scene(vibration, effects=("gravity", "vibration"), rate_hz=1000, duration_s=0.5, attitude=None, seed=1,
          **imu):
    return scenes.scene(rate_hz=rate_hz, duration_s=duration_s, seed=seed, trajectory=scenes.AT_ORIGIN,
                        attitude=attitude or None, imus=[{"name": "imu0", "vibration": vibration, **imu}],
                        effects=effects)


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


def assert_welch_matches(x, rate, level, at, outside=(), nperseg=NPERSEG, p=1e-3):
    """x's Welch PSD (Hann, non-overlapping segments) at each frequency of `at` is level(f) within the chi-square
    interval of its K segments: a Gaussian process's bin is level * chi2(2K) / 2K (two-sided p over all the
    frequencies tested, Bonferroni); at each frequency of `outside` it is below 1e-3 of level's largest value."""
    freqs, pxx = signal.welch(x, fs=rate, window="hann", nperseg=nperseg, noverlap=0, detrend="constant")
    k = x.size // nperseg
    lo, hi = stats.chi2.ppf([p / 2 / len(at), 1 - p / 2 / len(at)], 2 * k) / (2 * k)
    for f in at:
        i = int(np.argmin(np.abs(freqs - f)))
        ratio = pxx[i] / level(freqs[i])
        assert lo < ratio < hi, (f, ratio, lo, hi)
    peak = max(level(f) for f in at)
    for f in outside:
        assert pxx[int(np.argmin(np.abs(freqs - f)))] < 1e-3 * peak, f


#: frequencies inside the band, more than the filter's and Welch's resolution (2 Hz each here) from its edges
INSIDE = (60.0, 97.0, 151.0, 203.0, 257.0, 311.0, 353.0, 390.0)
OUTSIDE = (20.0, 35.0, 420.0, 600.0, 900.0)


def test_random_vibration_psd_level_by_welch_within_chi_square_interval(random_vibration):
    out = run(random_vibration)
    assert_welch_matches(out.accel[0, :, 0], RATE, lambda f: PSD_G2HZ * G0 ** 2, INSIDE, OUTSIDE)
    # the band's mean level, tighter: over n bins of K segments; Hann makes neighbouring bins correlated, so count
    # K (not 2K) degrees of freedom per bin (conservative), two-sided 1e-3
    freqs, pxx = signal.welch(out.accel[0, :, 0], fs=RATE, window="hann", nperseg=NPERSEG, noverlap=0)
    inside = (freqs > F_LO + 10) & (freqs < F_HI - 10)
    nu = out.accel.shape[1] // NPERSEG * int(inside.sum())
    lo, hi = stats.chi2.ppf([0.5e-3, 1 - 0.5e-3], nu) / nu
    assert lo < pxx[inside].mean() / (PSD_G2HZ * G0 ** 2) < hi
    # the y and z axes carry no vibration (weight 0): z is gravity exactly
    np.testing.assert_array_equal(out.accel[0, :, 1], 0.0)
    np.testing.assert_allclose(out.accel[0, :, 2], G0, rtol=1e-15)


def test_random_vibration_log_log_table_and_axis_weights_by_welch():
    # A rising then flat table on two axes, weights 1 and 0.25: level f -> s0 (f / f0)^(log(s1/s0) / log(f1/f0))
    # between breakpoints (the definition, written here), times the weight; x and y independent (their cross
    # spectrum's coherence stays small).
    table = [(40.0, 1e-3), (120.0, 2e-2), (300.0, 2e-2)]

    def level(f):
        for (f0, s0), (f1, s1) in zip(table, table[1:]):
            if f <= f1:
                return s0 * (f / f0) ** (math.log(s1 / s0) / math.log(f1 / f0))
    out = run(scene({"psd": [list(row) for row in table], "psd_lines": 512, "psd_axes": [1.0, 0.25, 0.0]},
                    rate_hz=1000, duration_s=60.0, seed=11))
    at = (50.0, 70.0, 90.0, 110.0, 150.0, 220.0, 280.0)
    assert_welch_matches(out.accel[0, :, 0], 1000, level, at, (15.0, 330.0, 450.0), nperseg=512)
    assert_welch_matches(out.accel[0, :, 1], 1000, lambda f: 0.25 * level(f), at, nperseg=512)
    freqs, coherence = signal.coherence(out.accel[0, :, 0], out.accel[0, :, 1], fs=1000, nperseg=512, noverlap=0)
    # independent Gaussian: the coherence of K segments is Beta(1, K - 1) per bin; its mean in the band is 1 / K
    band = (freqs > 50) & (freqs < 280)
    k = out.accel.shape[1] // 512
    assert coherence[band].mean() < 2.0 / k


def test_random_vibration_same_bytes_for_any_block_size_and_new_phases_for_another_seed(random_vibration):
    whole = Simulation(random_vibration, attitude=False).block(0, 3000).accel
    sim = Simulation(random_vibration, attitude=False)
    parts = np.concatenate([sim.block(k, n).accel for k, n in ((0, 1), (1, 7), (8, 992), (1000, 2000))], axis=1)
    assert whole.tobytes() == parts.tobytes()
    other = scene_from_dict({**_raw(random_vibration, seed=8)})
    again = Simulation(other, attitude=False).block(0, 3000).accel
    assert np.abs(np.corrcoef(whole[0, :, 0], again[0, :, 0])[0, 1]) < 5 / math.sqrt(3000)


def test_fft_filtered_vibration_is_drawn_on_the_parts_axes_to_the_bit():
    # At rest without gravity the IMU reads the vibration alone. An ENU scene's body axes are the part's forward-
    # right-down axes turned half a turn about x (EmitContext.frd_sign): its y and z samples are the NED scene's
    # negated, to the last bit, x the same, over chunk boundaries (psd_lines 256: the FFT filler, 768 rows a chunk;
    # tests/firmware_protocols/test_axes_at_the_wire.py holds the direct form, at 16 lines, to the same).
    def at_rest(frame):
        return Simulation(scene_from_dict({
            "scene": {"rate_hz": 1000, "duration_s": 2.0, "seed": 5, "frame": frame},
            "trajectory": {"x": "0", "y": "0", "z": "0"},
            "imu": [{"name": "imu0", "vibration": {"psd": [["20 Hz", "0.01 g^2/Hz"], ["300 Hz", "0.01 g^2/Hz"]],
                                                   "angular_psd": [[20, 1e-4], [200, 1e-4]]}}],
            "effects": {"vibration": True}}), attitude=False).run()
    enu, ned = at_rest("ENU"), at_rest("NED")
    for name in ("accel", "gyro"):
        a, b = getattr(enu, name)[0], getattr(ned, name)[0]
        assert (b.std(axis=0) > 0).all()      # every axis vibrates: nothing trivially equal
        assert a[:, 0].tobytes() == b[:, 0].tobytes()
        assert a[:, 1:].tobytes() == (-b[:, 1:]).tobytes()


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
    # z read zero.
    out = run(scene({"angular_psd": [[f"{F_LO} Hz", f"{DEG_PSD} (deg/s)^2/Hz"], [f"{F_HI} Hz", f"{DEG_PSD} deg^2/s^2/Hz"]],
                     "psd_lines": 1000, "angular_psd_axes": [1.0, 0.0, 0.0]},
                    rate_hz=RATE, duration_s=SECONDS, seed=3))
    assert_welch_matches(out.gyro[0, :, 0], RATE, lambda f: DEG_PSD * math.radians(1) ** 2, INSIDE, OUTSIDE)
    np.testing.assert_array_equal(out.gyro[0, :, 1:], 0.0)


def test_angular_psd_turns_gravity_by_the_integral_of_its_rate_and_the_attitude_with_it():
    # Angular PSD on x, body at rest (ENU, level): the axes turn by the angle a about x, so gravity reads
    # f = Rx(a)^T (0, 0, g) = (0, g sin a, g cos a) and a = atan2(f_y, f_z) is read back from the accelerometer
    # alone. The attitude is the exact rotation by a: (cos a/2, sin a/2, 0, 0). a is the rate's integral: its
    # Welch PSD is the rate's level / (2 pi f)^2 (chi-square interval), and its steps match the trapezoid of
    # the gyro (error (w T)^2 / 12 of the step: under 2 % for content below 80 Hz at 1 kHz).
    level = math.radians(2.0) ** 2
    out = run(scene({"angular_psd": [[20.0, level], [80.0, level]], "psd_lines": 512, "angular_psd_axes": [1, 0, 0]},
                    duration_s=40.0, attitude={"roll": "0", "pitch": "0", "yaw": "0"}, seed=5), attitude=True)
    a = np.arctan2(out.accel[0, :, 1], out.accel[0, :, 2])
    np.testing.assert_allclose(out.accel[0, :, 0], 0.0, atol=0)
    np.testing.assert_allclose(np.hypot(out.accel[0, :, 1], out.accel[0, :, 2]), G0, rtol=1e-14)
    np.testing.assert_allclose(out.quat[0], np.stack([np.cos(a / 2), np.sin(a / 2), 0 * a, 0 * a], axis=1),
                               rtol=0, atol=1e-13)
    assert_welch_matches(a, 1000, lambda f: level / (2 * np.pi * f) ** 2, (25.0, 40.0, 55.0, 75.0), nperseg=512)
    rate = out.gyro[0, :, 0]
    trapezoid = 0.5e-3 * (rate[1:] + rate[:-1])
    assert np.sqrt(np.mean((np.diff(a) - trapezoid) ** 2)) < 0.02 * np.sqrt(np.mean(np.diff(a) ** 2))


def test_linear_psd_velocity_is_the_coriolis_term_on_a_turning_body():
    # Linear PSD on x, the body turning about z at W (yaw = W t): w x d' = (0, W v, 0), so the IMU reads
    # f_y = 2 W v with v = d' the vibration's velocity, and f_x = a - W^2 d (W^2 d / a ~ (W / w)^2 < 1e-5).
    # v's Welch PSD is the table's / (2 pi f)^2, and its steps are the trapezoid of a (as above).
    big_w, level = 0.5, 0.02
    out = run(scene({"psd": [[20.0, level], [80.0, level]], "psd_lines": 512, "psd_axes": [1, 0, 0]},
                    duration_s=40.0, attitude={"roll": "0", "pitch": "0", "yaw": f"{big_w}*t"}, seed=6))
    v, acc = out.accel[0, :, 1] / (2 * big_w), out.accel[0, :, 0]
    assert_welch_matches(v, 1000, lambda f: level / (2 * np.pi * f) ** 2, (25.0, 40.0, 55.0, 75.0), nperseg=512)
    trapezoid = 0.5e-3 * (acc[1:] + acc[:-1])
    assert np.sqrt(np.mean((np.diff(v) - trapezoid) ** 2)) < 0.02 * np.sqrt(np.mean(np.diff(v) ** 2))


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
    # a PSD band reaching past Nyquist: one warning naming the table, its band above Nyquist and that band's share
    # of the power (a flat table: (2000 - 500) / (2000 - 20) of it)
    s = scene({"angular_psd": [["20 Hz", "1e-4 (deg/s)^2/Hz"], ["2 kHz", "1e-4 (deg/s)^2/Hz"]], "psd_lines": 64,
               "angular_psd_axes": [0, 1, 0]})
    assert s.warnings == (f"imu[0].vibration.angular_psd: its band above the Nyquist rate 500 Hz of rate_hz = 1000 "
                          f"(500 to 2000 Hz, {100 * 1500 / 1980:.3g} % of its power) folds into 0 to 500 Hz "
                          "(no anti-alias filter is simulated)",)
    # a band narrower than the filter resolves (256 taps at 1 kHz: bins every 3.906 Hz; 10 to 20 Hz holds the
    # bins at 11.7, 15.6 and 19.5 Hz): a warning that it is coarse, and how to fix it
    s = scene({"psd": [["10 Hz", 0.1], ["20 Hz", 0.1]]})
    assert s.warnings == ("imu[0].vibration.psd: its band 10 to 20 Hz holds 3 of the shaping filter's frequency "
                          "bins (every 3.90625 Hz at psd_lines = 256): it is realized coarsely or not at all; raise "
                          "psd_lines",)
    assert scene({"psd": [["10 Hz", 0.1], ["20 Hz", 0.1]], "psd_lines": 1024}).warnings == ()
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


def test_increments_integrate_an_angular_random_vibration():
    # Angular PSD on y, body at rest: the rotation is about one fixed axis, so dtheta_y over (t-T, t] is the angle's
    # change b(t) - b(t-T), b read back from gravity (f = Ry(b)^T (0, 0, g) = (-g sin b, 0, g cos b)). Between
    # samples the angle is the cubic through (b, b') at both ends, whose derivative Gauss-Legendre integrates
    # exactly: to rounding.
    level = math.radians(1.0) ** 2
    s = scene({"angular_psd": [[30.0, level], [120.0, level]], "psd_lines": 256, "angular_psd_axes": [0, 1, 0]},
              seed=4)
    out = Simulation(s, attitude=False, increments=8).run()
    b = np.arctan2(-out.accel[0, :, 0], out.accel[0, :, 2])
    np.testing.assert_allclose(out.dtheta[0][1:, 1], np.diff(b), rtol=0, atol=1e-9 * np.abs(np.diff(b)).max())
    assert np.abs(out.dtheta[0][:, [0, 2]]).max() < 1e-15


def test_increments_integrate_a_linear_random_vibration():
    # Linear PSD on x on a body turning about z at W: v = f_y / 2W (previous test but one), and dvel_x over
    # (t-T, t] is the integral of f_x = a - W^2 d: v(t) - v(t-T) (the quintic through (d, d', d'') at both ends,
    # its a integrated exactly) less W^2 times d's integral, under 1e-4 of the step here.
    big_w, level = 0.5, 0.02
    s = scene({"psd": [[20.0, level], [80.0, level]], "psd_lines": 256, "psd_axes": [1, 0, 0]},
              attitude={"roll": "0", "pitch": "0", "yaw": f"{big_w}*t"}, seed=6)
    out = Simulation(s, attitude=False, increments=4).run()
    v = out.accel[0, :, 1] / (2 * big_w)
    np.testing.assert_allclose(out.dvel[0][1:, 0], np.diff(v), rtol=0, atol=1e-4 * np.abs(np.diff(v)).max())


@pytest.mark.slow
def test_random_vibration_is_the_same_in_a_per_imu_function_and_with_increments():
    # More IMUs than INLINE_IMUS: each IMU's lines are a function of their own, reading its own state slots; the
    # quadrature nodes of the increments fill and read the same chunk cache. IMU 0's outputs are then the bytes of
    # the single-IMU run without increments; another IMU has noise of its own.
    vib = {"psd": [["50 Hz", "0.01 g^2/Hz"], ["400 Hz", "0.01 g^2/Hz"]], "psd_axes": [1, 0, 0],
           "angular_psd": [[20, 1e-4], [80, 1e-4]], "angular_psd_axes": [0, 0, 1]}

    def many(n):
        return scene_from_dict({"scene": {"rate_hz": 1000, "duration_s": 2, "seed": 7},
                                "trajectory": {"x": "0", "y": "0", "z": "0"},
                                "imu": [{"name": f"i{m}", "vibration": vib} for m in range(n)],
                                "effects": {"gravity": True, "vibration": True}})
    from imu_emulator.codegen.generate import INLINE_IMUS
    one = run(many(1))
    separate = Simulation(many(INLINE_IMUS + 1), attitude=False, increments=4).run()
    assert one.accel[0].tobytes() == separate.accel[0].tobytes()
    assert one.gyro[0].tobytes() == separate.gyro[0].tobytes()
    assert np.abs(np.corrcoef(separate.accel[0, :, 0], separate.accel[INLINE_IMUS, :, 0])[0, 1]) < 5 / math.sqrt(2000)


def test_hermite_interpolants_reproduce_polynomials_of_their_degree():
    # The quintic through (d, d', d'') at both ends of a step h reproduces any quintic, the cubic through (x, x')
    # any cubic, with their derivatives (in seconds: d/dt = d/du / h): numpy's Polynomial as the oracle.
    from numpy.polynomial import Polynomial
    from imu_emulator.numerics.shaped_noise import hermite3, hermite5
    h = 1e-3
    rng = np.random.default_rng(3)
    for degree, function in ((5, hermite5), (3, hermite3)):
        p = Polynomial(rng.normal(size=degree + 1), domain=[0, h], window=[0, h])   # p(t), t in seconds
        # (value, derivatives up to (degree - 1) / 2) at t = 0, then at t = h: the interpolants' arguments
        ends = [p.deriv(i)(t) if i else p(t) for t in (0.0, h) for i in range((degree + 1) // 2)]
        for u in (0.0, 0.13, 0.5, 0.87, 1.0):
            got = function(u, h, *ends)
            want = [p.deriv(i)(u * h) if i else p(u * h) for i in range(len(got))]
            np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("n", [2, 4, 64, 1024])
def test_fft_is_numpys_dft(n):
    # The in-place radix-2 transform against numpy.fft.fft on random complex input; round-off of a radix-2 FFT
    # grows as eps log2 n times the input's RMS per output (Higham, Accuracy and Stability, sec. 24.1), so 1e-14
    # of the largest output bounds it with room for n up to 2^20
    from imu_emulator.numerics.shaped_noise import fft, twiddles
    x = np.random.default_rng(n).normal(size=(2, n))
    state = np.concatenate([[3.0], x[0], x[1]])          # after an unrelated slot
    prm = np.array([5.0] + twiddles(n))
    fft(state, 1, 1 + n, n, prm, 1)
    want = np.fft.fft(x[0] + 1j * x[1])
    np.testing.assert_allclose(state[1:1 + n] + 1j * state[1 + n:], want, rtol=0, atol=1e-14 * np.abs(want).max())
    assert state[0] == 3.0


def _fill(fft, key, chunk, taps, h, offset):
    """Chunk `chunk` of the reversed taps h (orders x taps) by fill_chunk (fft) or fill_chunk_direct, its rows
    at state[offset:], after slots and parameters the call must not touch: (state, rows per chunk)."""
    from imu_emulator.numerics.shaped_noise import correlation_spectrum, fft_size, fill_chunk, fill_chunk_direct
    from imu_emulator.numerics.shaped_noise import twiddles
    orders = h.shape[0]
    if fft:
        n = fft_size(taps)
        size, tw = n - taps, twiddles(n)
        prm = np.array([7.0] + tw + [x for o in range(orders) for x in correlation_spectrum(h[o], n)])
        state = np.zeros(offset + (size + 1) * orders + 4 * n)
        fill_chunk(np.uint64(key), chunk, size, taps, orders, prm, 1 + len(tw), 1, state, offset,
                   offset + (size + 1) * orders)
    else:
        size = 32
        prm = np.concatenate([[7.0], h.ravel()])
        state = np.zeros(offset + (size + 1) * orders + size + taps)
        fill_chunk_direct(np.uint64(key), chunk, size, taps, orders, prm, 1, state, offset,
                          offset + (size + 1) * orders)
    return state, size


@pytest.mark.parametrize("fft, taps, orders", [(False, 16, 2), (False, 17, 3), (False, 40, 3), (True, 16, 2),
                                               (True, 17, 3), (True, 256, 3), (True, 1000, 2)])
def test_fill_chunk_is_the_convolution_of_the_streams_normals(fft, taps, orders):
    # Row r of chunk c is sample c * size - 1 + r of sum_i h_o[i] w[j - i], w_j = normal(key, j + taps): numpy's
    # direct convolution of counter_rng.normals as the oracle (even and odd tap counts, 2 and 3 orders: the FFT's
    # inverse transform carries two orders, the third one alone). The direct form's round-off is eps times the
    # sum of |h w| (about sqrt(taps) times a row); the FFT's about eps log2 n of the rows' scale (test above):
    # 1e-13 of the largest row bounds both.
    from imu_emulator.numerics.counter_rng import normals
    chunk, key = 3, 987654321
    h = np.random.default_rng(1).normal(size=(orders, taps))
    state, size = _fill(fft, key, chunk, taps, h[:, ::-1], 5)
    first = chunk * size - 1                                 # the run sample of row 0
    w = normals(key, first - taps + 1 + taps, size + taps)   # w_j for j = first - taps + 1 .. first + size
    assert not state[:5].any()                               # nothing written before the rows
    for o in range(orders):
        want = np.convolve(w, h[o], mode="valid")             # samples first .. first + size
        np.testing.assert_allclose(state[5 + o: 5 + (size + 1) * orders: orders], want, rtol=0,
                                   atol=1e-13 * np.abs(want).max())
