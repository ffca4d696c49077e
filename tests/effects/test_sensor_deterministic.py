"""Deterministic sensor errors against closed forms (to 1e-12): scale factor, misalignment composed with mounting,
g-sensitivity, quadratic nonlinearity's DC shift, range saturation and its count, resolution steps.

The motions are chosen so the true sensor-frame values are known in closed form: a level body turning at a
constant yaw rate W about z while standing still has omega_b = (0, 0, W) and f_b = (0, 0, g) exactly (ENU);
the mounting rotation comes from scipy's Rotation (an independent implementation of the z-y-x convention).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_emulator import scene_from_dict
from imu_emulator.errors import SceneError
from imu_emulator.runtime.simulation import Simulation
from tests.support.scenes import scene, yaw_at

G0 = 9.80665
W = 0.7                       # rad/s yaw rate
MOUNT_RPY_DEG = (10.0, -20.0, 35.0)


def turning_scene(effects, gyro=None, accel=None, mounting=MOUNT_RPY_DEG, rate_hz=100, duration_s=0.2, **imu):
    return scene(rate_hz=rate_hz, duration_s=duration_s, attitude=yaw_at(W),
                 imus=[{"name": "imu0", "mounting_rpy_deg": list(mounting), "gyro": dict(gyro or {}),
                        "accel": dict(accel or {}), **imu}], effects=("gravity", "mounting", *effects))


def true_sensor_values(mounting=MOUNT_RPY_DEG):
    """omega and f in sensor axes: sensor = M^T body, M = Rz(yaw) Ry(pitch) Rx(roll) of the mounting."""
    roll, pitch, yaw = mounting
    m = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_matrix()
    return m.T @ np.array([0.0, 0.0, W]), m.T @ np.array([0.0, 0.0, G0])


def run(scene):
    sim = Simulation(scene, attitude=False)
    return sim.run(), sim


def assert_close(actual, expected):
    np.testing.assert_allclose(actual, np.broadcast_to(expected, actual.shape), rtol=1e-12, atol=1e-12)


def test_scale_factor_and_misalignment_compose_after_mounting():
    s_g, s_a = np.array([500e-6, -300e-6, 1e-3]), 0.003
    mis_g = np.array([[0.0, 1e-3, -2e-3], [0.5e-3, 0.0, 1.5e-3], [-1e-3, 2e-3, 0.0]])
    scene = turning_scene(("scale_factor", "misalignment"),
                          gyro={"scale_factor": ["500 ppm", "-300 ppm", "0.1 %"], "misalignment": mis_g.tolist()},
                          accel={"scale_factor": "0.3 %", "misalignment": "1 %"})
    out, _ = run(scene)
    omega, f = true_sensor_values()
    mis_a = 0.01 * (np.ones((3, 3)) - np.eye(3))   # one value fills every off-diagonal element
    assert_close(out.gyro[0], (np.eye(3) + np.diag(s_g) + mis_g) @ omega)
    assert_close(out.accel[0], (np.eye(3) + s_a * np.eye(3) + mis_a) @ f)


def test_misalignment_angles_per_axis_fill_their_rows():
    scene = turning_scene(("misalignment",), gyro={"misalignment": ["1 mrad", "2 mrad", "0.1 deg"]})
    out, _ = run(scene)
    omega, _ = true_sensor_values()
    rows = np.array([1e-3, 2e-3, np.radians(0.1)])
    assert_close(out.gyro[0], (np.eye(3) + rows[:, None] * (np.ones((3, 3)) - np.eye(3))) @ omega)


def test_g_sensitivity_adds_g_times_specific_force_to_the_gyros():
    full = [[0.1, 0.02, -0.03], [0.0, 0.05, 0.01], [0.04, 0.0, 0.2]]     # deg/s/g
    out, _ = run(turning_scene(("g_sensitivity",), gyro={"g_sensitivity": [[f"{v} deg/s/g" for v in row]
                                                                            for row in full]}))
    omega, f = true_sensor_values()
    per_si = np.radians(1.0) / G0
    assert_close(out.gyro[0], omega + per_si * np.array(full) @ f)
    out, _ = run(turning_scene(("g_sensitivity",), gyro={"g_sensitivity": "0.1 deg/s/g"}))
    assert_close(out.gyro[0], omega + 0.1 * per_si * f)     # one value: the diagonal


def vibration_scene(effects, accel, a0, freq, rate_hz, periods):
    # x = -a0/(2 pi f)^2 sin(2 pi f t): specific force along x is a0 sin(2 pi f t), level, no rotation
    amp = a0 / (2 * np.pi * freq) ** 2
    return scene(rate_hz=rate_hz, duration_s=periods / freq,
                 trajectory={"x": f"-{amp!r}*sin(2*pi*{freq!r}*t)", "y": "0", "z": "0"},
                 imus=[{"name": "imu0", "accel": accel}], effects=("gravity", *effects))


def test_quadratic_nonlinearity_rectifies_a_sine_vibration_into_k2_a0_squared_over_2():
    a0, k2 = 30.0, 2e-3          # m/s^2, 1/(m/s^2)
    out, _ = run(vibration_scene(("nonlinearity",), {"nonlinearity": [k2, 0.0, 0.0]}, a0, 50.0, 1000, 10))
    # the mean of sin^2 over whole periods sampled evenly (20 samples a period) is exactly 1/2
    assert abs(out.accel[0, :, 0].mean() - k2 * a0 ** 2 / 2) < 1e-12
    # and per sample: a + K2 a^2, the z axis (g) gets nothing with K2_z = 0
    t = out.t_s
    a = a0 * np.sin(2 * np.pi * 50.0 * t)
    np.testing.assert_allclose(out.accel[0, :, 0], a + k2 * a * a, atol=1e-11)
    assert_close(out.accel[0, :, 2], G0)
    # datasheet form: ug/g^2
    out2, _ = run(vibration_scene(("nonlinearity",), {"nonlinearity": "200 ug/g^2"}, a0, 50.0, 1000, 10))
    assert abs(out2.accel[0, :, 0].mean() - 200e-6 / G0 * a0 ** 2 / 2) < 1e-12


def test_nonlinearity_in_percent_of_full_scale_is_k2_x_over_fs():
    # a quadratic term reaching x of full scale FS at FS: K2 FS^2 = x FS, so K2 = x / FS (DC shift K2 a0^2 / 2)
    a0 = 30.0
    out, _ = run(vibration_scene(("nonlinearity",), {"nonlinearity_fs": ["0.5 %", 0, 0],
                                                      "nonlinearity_full_scale": "16 g"}, a0, 50.0, 1000, 10))
    assert abs(out.accel[0, :, 0].mean() - 0.005 / (16 * G0) * a0 ** 2 / 2) < 1e-12
    # the full scale from the range effect (8 g here), and the per-unit form adding to it
    out, _ = run(vibration_scene(("nonlinearity", "range"), {"nonlinearity_fs": ["0.5 %", 0, 0], "range": "8 g",
                                                               "nonlinearity": [1e-4, 0, 0]}, a0, 50.0, 1000, 10))
    assert abs(out.accel[0, :, 0].mean() - (0.005 / (8 * G0) + 1e-4) * a0 ** 2 / 2) < 1e-12
    with pytest.raises(SceneError, match=r"imu\[0\]\.accel\.nonlinearity_fs: needs a full scale on axis x"):
        vibration_scene(("nonlinearity",), {"nonlinearity_fs": "0.5 %"}, a0, 50.0, 1000, 10)
    with pytest.raises(SceneError, match=r"imu\[0\]\.accel\.nonlinearity_fs: needs a full scale"):
        run(vibration_scene(("nonlinearity",), {"nonlinearity_fs": "0.5 %", "range": "8 g"}, a0, 50.0, 1000, 10))


def ramp_scene(effects, gyro, accel, rate_hz=100, duration_s=2.0, t0=-1.0):
    # without gravity, accel z = t (z = t^3/6, untouched by the yaw) and gyro z = -t (yaw = -t^2/2): both cross
    # +-range within the run; the other axes read 0
    return scene(rate_hz=rate_hz, duration_s=duration_s, t0_s=t0, trajectory={"x": "0", "y": "0", "z": "t**3/6"},
                 attitude={"roll": "0", "pitch": "0", "yaw": "-t**2/2"},
                 imus=[{"name": "imu0", "gyro": gyro, "accel": accel}], effects=effects)


def test_range_saturates_exactly_at_full_scale_and_counts_per_axis():
    out, sim = run(ramp_scene(("range",), {"range": [1.0, 1.0, 0.5]}, {"range": [1.0, "1 g", "0.5 m/s^2"]}))
    t = out.t_s
    a_z, w_z = t, -t
    # whatever the true value beyond the range, the output is the range itself, bit for bit
    assert_close(out.accel[0, :, 2], np.clip(a_z, -0.5, 0.5))
    assert set(out.accel[0, np.abs(a_z) > 0.5, 2]) == {0.5, -0.5}
    assert_close(out.gyro[0, :, 2], np.clip(w_z, -0.5, 0.5))
    assert_close(out.accel[0, :, :2], 0.0)
    counts = sim.counts()["imu0"]
    assert counts["range.accel.z"] == int(np.sum(np.abs(a_z) > 0.5)) > 0
    assert counts["range.gyro.z"] == int(np.sum(np.abs(w_z) > 0.5)) > 0
    assert counts["range.accel.x"] == 0 and counts["range.gyro.x"] == 0
    # a value exactly at the range is not beyond it: t = -0.5 s and +0.5 s are on the grid (k = 50, 150)
    assert np.sum(np.abs(a_z) == 0.5) == 2
    assert counts["range.accel.z"] == int(np.sum(np.abs(a_z) >= 0.5)) - 2


def test_range_count_follows_the_run_across_blocks():
    scene = ramp_scene(("range",), {}, {"range": [0.0, 0.0, 0.5]})
    sim = Simulation(scene, attitude=False)
    for k0 in range(0, sim.n_samples, 7):
        sim.block(k0, min(7, sim.n_samples - k0))
    whole, at_once = run(scene)
    assert sim.counts() == at_once.counts()
    assert at_once.counts()["imu0"]["range.accel.z"] == int(np.sum(np.abs(whole.t_s) > 0.5))


def test_resolution_rounds_to_the_lsb_after_range():
    lsb_a, lsb_g = 0.0613, np.radians(0.061)   # 0.0613: no sample of the ramp is a tie
    out, _ = run(ramp_scene(("range", "resolution"), {"resolution": "0.061 deg/s"},
                            {"resolution": lsb_a, "range": [0.0, 0.0, 0.5]}, rate_hz=1000))
    t = out.t_s
    assert_close(out.accel[0, :, 2], lsb_a * np.round(np.clip(t, -0.5, 0.5) / lsb_a))
    assert_close(out.gyro[0, :, 2], lsb_g * np.round(-t / lsb_g))
    # a staircase: steps of exactly one LSB along the ramp, never further than half an LSB from the value
    steps = np.unique(np.round(np.diff(out.accel[0, :, 2]) / lsb_a, 9))
    assert set(steps) == {0.0, 1.0}
    assert np.all(np.abs(out.accel[0, :, 2] - np.clip(t, -0.5, 0.5)) <= lsb_a / 2 + 1e-12)


@pytest.mark.parametrize("table, key, value, message", [
    ("gyro", "range", -5.0, r"imu\[0\]\.gyro\.range: a full scale is positive"),
    ("accel", "resolution", "-1 mg", r"imu\[0\]\.accel\.resolution: the LSB is positive"),
    ("accel", "misalignment", "1 m/s", r"imu\[0\]\.accel\.misalignment: .* wrong dimension"),
    ("gyro", "g_sensitivity", "0.1 deg/s", r"imu\[0\]\.gyro\.g_sensitivity: .* wrong dimension"),
    ("gyro", "noise_density", "-0.01 deg/s/sqrt(Hz)", r"imu\[0\]\.gyro\.noise_density: a noise density is >= 0"),
    ("accel", "random_walk", "-1e-4 m/s^2/sqrt(s)", r"imu\[0\]\.accel\.random_walk: a random walk coefficient"),
])
def test_bad_values_name_the_key(table, key, value, message):
    with pytest.raises(SceneError, match=message):
        turning_scene(("range", "resolution", "misalignment", "g_sensitivity", "noise", "random_walk"),
                      **{table: {key: value}})


RANGE_SCENE = """
[scene]
rate_hz = 100
duration_s = 2.0
t0_s = -1.0
[trajectory]
x = "0"
y = "0"
z = "t**3/6"
[[imu]]
name = "imu0"
[imu.accel]
range = ["1 g", "1 g", "0.05 g"]
[effects]
range = true
"""


def test_generate_and_stream_show_the_range_saturation_counts(tmp_path, capsys):
    from imu_emulator.cli import main
    path = tmp_path / "range.toml"
    path.write_text(RANGE_SCENE)
    beyond = int(np.sum(np.abs(-1.0 + np.arange(200) / 100) > 0.05 * G0))   # accel z = t
    assert main(["generate", str(path), "-o", str(tmp_path / "out.csv")]) == 0
    assert f"range saturation: imu0 accel.x 0, imu0 accel.y 0, imu0 accel.z {beyond}" in capsys.readouterr().err
    stats = tmp_path / "stats.json"
    assert main(["stream", str(path), "--format", "bosch-mm7", "--to", f"file:{tmp_path / 'cap.log'}", "--speed", "0",
                 "--no-realtime", "--stats-json", str(stats)]) == 0
    assert f"range saturation: imu0 accel.x 0, imu0 accel.y 0, imu0 accel.z {beyond}" in capsys.readouterr().err
    import json
    assert json.loads(stats.read_text())["effect_counts"] == {
        "imu0": {"range.accel.x": 0, "range.accel.y": 0, "range.accel.z": beyond}}


def temperature_scene(imu, gyro=None, accel=None, rate_hz=10, duration_s=2000.0):
    return scene(rate_hz=rate_hz, duration_s=duration_s, attitude=yaw_at(W),
                 imus=[{"name": "imu0", "gyro": dict(gyro or {}), "accel": dict(accel or {}), **imu}],
                 effects=("gravity", "temperature"))


def test_temperature_coefficients_follow_a_warm_up_profile():
    # T(t) = 20 + 0.001 t + 15 (1 - exp(-t/300)); v = v_true (1 + s1 (T - T0)) + b1 (T - T0), T0 = 25
    scene = temperature_scene({"temperature_c": "20 + 0.001*t", "warmup_rise_c": 15, "warmup_tau_s": 300},
                              gyro={"bias_tc": ["0.015 deg/s/K", 0, 0], "scale_tc": [0, 0, "300 ppm/K"]},
                              accel={"bias_tc": "0.2 mg/K", "scale_tc": [0, 0, "0.01 %/degC"]})
    out, _ = run(scene)
    t = out.t_s
    temperature = 20 + 0.001 * t + 15 * (1 - np.exp(-t / 300))
    d = temperature - 25.0
    np.testing.assert_allclose(out.temperature_c[0], temperature, rtol=1e-12)
    np.testing.assert_allclose(out.gyro[0, :, 0], np.radians(0.015) * d, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out.gyro[0, :, 2], W * (1 + 300e-6 * d), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out.accel[0, :, 0], 0.2e-3 * G0 * d, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out.accel[0, :, 2], G0 * (1 + 1e-4 * d) + 0.2e-3 * G0 * d, rtol=1e-12, atol=1e-12)


def test_a_constant_temperature_reaches_the_samples_and_the_wire(tmp_path):
    scene = temperature_scene({"temperature_c": 41.5}, duration_s=1.0)
    out, _ = run(scene)
    assert np.all(out.temperature_c == 41.5)
    assert np.all(out.gyro[0, :, 2] == W)          # no coefficient: the profile alone costs the kernel nothing
    # the NPZ output carries it
    from imu_emulator.cli import main
    path = tmp_path / "hot.toml"
    path.write_text('[scene]\nrate_hz = 10\nduration_s = 1.0\n[trajectory]\nshape = "static"\n[[imu]]\nname = "a"\n'
                    'temperature_c = "30 + t"\n[effects]\ntemperature = true\n')
    assert main(["generate", str(path), "-o", str(tmp_path / "out.npz"), "--quiet"]) == 0
    data = np.load(tmp_path / "out.npz")
    np.testing.assert_allclose(data["temperature_c"][0], 30 + data["t"], rtol=1e-15)
    # and the wire: MAVLink HIGHRES_IMU's float temperature, decoded by pymavlink
    mavlink2 = pytest.importorskip("pymavlink.dialects.v20.common")
    capture = tmp_path / "wire.bin"
    assert main(["stream", str(path), "--format", "mavlink-highres", "--to", f"file:{capture}", "--speed", "0",
                 "--no-realtime", "--quiet"]) == 0
    import io
    messages = mavlink2.MAVLink(io.BytesIO()).parse_buffer(capture.read_bytes())
    assert [m.temperature for m in messages] == pytest.approx(30 + data["t"], rel=1e-6)   # float32 on the wire


CLOCK_MOTION = {"trajectory": {"x": "3*sin(2*pi*1.3*t) + 0.2*t**2", "y": "cos(2*pi*0.4*t)", "z": "0"},
                "attitude": {"roll": "0.3*sin(2*pi*0.7*t)", "pitch": "0.1*t", "yaw": "0.5*cos(2*pi*0.2*t)"}}


def clock_scene(rate_hz, duration_s, t0=0.0, clock=None, seed=0):
    return scene_from_dict({"scene": {"rate_hz": rate_hz, "duration_s": duration_s, "t0_s": t0, "seed": seed},
                            **CLOCK_MOTION, "imu": [{"name": "imu0", "lever_arm_m": [0.1, 0.2, -0.1], **(clock or {})}],
                            "effects": {"gravity": True, "lever_arm": True, **({"clock": True} if clock else {})}})


def test_clock_error_samples_the_motion_at_the_actual_instants():
    # +50 ppm (specs/sensor-errors.md: t_k = k dt (1 + ppm 1e-6)): sample k of the clocked scene is the motion
    # at (1 + 50e-6) k dt, which a scene at the rate f_s / (1 + 50e-6) samples exactly at its sample k
    rate, n = 200.0, 2000
    clocked = Simulation(clock_scene(rate, n / rate, clock={"clock_ppm": 50}), truth=True).run()
    reference = Simulation(clock_scene(rate / (1 + 50e-6), n / rate), truth=True).run()
    np.testing.assert_allclose(clocked.t_s, np.arange(n) / rate, rtol=1e-15)    # nominal stamps
    # to 1e-12 of each quantity's scale: t itself is known to an ulp (1.8e-15 s at 10 s), times the fastest
    # rate of change of a 200 m/s^2 term at 1.3 Hz gives ~2e-12 m/s^2; relative 1e-12 of the scale covers it
    for name in ("accel", "gyro"):
        got, want = getattr(clocked, name), getattr(reference, name)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.max(np.abs(want)))
    np.testing.assert_allclose(clocked.truth["position"], reference.truth["position"], rtol=0,
                               atol=1e-12 * np.max(np.abs(reference.truth["position"])))
    # and it is not the nominal motion: 50 ppm over 10 s is 0.5 ms, visible in the 1.3 Hz sine
    nominal = Simulation(clock_scene(rate, n / rate), truth=True).run()
    assert np.max(np.abs(clocked.accel - nominal.accel)) > 1e-3


def test_clock_jitter_moves_the_instants_by_seeded_normals():
    from imu_emulator.numerics.counter_rng import normals, stream_key
    rate, n, sigma = 100.0, 500, 2e-4
    clocked = Simulation(clock_scene(rate, n / rate, clock={"clock_jitter_s": sigma}, seed=7), truth=True).run()
    jitter = sigma * normals(np.uint64(stream_key(7, -1, "clock.jitter")), 0, n)
    # the position truth at the jittered instants, closed form
    t = np.arange(n) / rate + jitter
    np.testing.assert_allclose(clocked.truth["position"][:, 0], 3 * np.sin(2 * np.pi * 1.3 * t) + 0.2 * t ** 2,
                               rtol=0, atol=1e-12 * 8)
    np.testing.assert_allclose(clocked.truth["position"][:, 1], np.cos(2 * np.pi * 0.4 * t), rtol=1e-12, atol=1e-12)


def test_one_sample_clock_per_scene():
    with pytest.raises(SceneError, match=r"imu\[1\]\.clock_ppm: the IMUs of a scene share one sample clock"):
        raw = {"scene": {"rate_hz": 100, "duration_s": 1.0}, "trajectory": {"shape": "static"},
               "imu": [{"name": "a", "clock_ppm": 50}, {"name": "b", "clock_ppm": 20}], "effects": {"clock": True}}
        Simulation(scene_from_dict(raw))
