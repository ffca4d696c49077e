"""`generate -o run.mcap`: a ROS 2 bag read back with an independent reader: the mcap library's raw records
decoded by rosbags' own CDR deserializer (not mcap-ros2-support, which wrote it)."""
from pathlib import Path

import numpy as np
import pytest

from imu_emulator import load_scene
from imu_emulator.cli import main
from imu_emulator.runtime.simulation import Simulation

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def read_bag(path):
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_HUMBLE)
    topics = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
            topics.setdefault(channel.topic, []).append(
                (message.log_time, store.deserialize_cdr(message.data, schema.name)))
    return topics


def test_generated_bag_holds_every_imu_sample_and_truth(tmp_path):
    scene_path = EXAMPLES / "two_imus.toml"
    bag = tmp_path / "run.mcap"
    assert main(["generate", str(scene_path), "-o", str(bag), "--truth", "--quiet"]) == 0
    scene = load_scene(scene_path)
    expected = Simulation(scene, truth=True).run()
    topics = read_bag(bag)
    assert set(topics) == {f"/imu/{n}" for n in scene.imu_names} | {"/truth/odometry"}
    ns = expected.time_ns()
    for m, name in enumerate(scene.imu_names):
        msgs = topics[f"/imu/{name}"]
        assert len(msgs) == scene.n_samples
        log_times = np.array([t for t, _ in msgs])
        np.testing.assert_array_equal(log_times, ns)
        stamps = np.array([d.header.stamp.sec * 10**9 + d.header.stamp.nanosec for _, d in msgs])
        np.testing.assert_array_equal(stamps, ns)
        assert {d.header.frame_id for _, d in msgs} == {name}
        gyro = np.array([[d.angular_velocity.x, d.angular_velocity.y, d.angular_velocity.z] for _, d in msgs])
        acc = np.array([[d.linear_acceleration.x, d.linear_acceleration.y, d.linear_acceleration.z] for _, d in msgs])
        np.testing.assert_array_equal(gyro, expected.gyro[m])
        np.testing.assert_array_equal(acc, expected.accel[m])
        quat = np.array([[d.orientation.w, d.orientation.x, d.orientation.y, d.orientation.z] for _, d in msgs])
        np.testing.assert_array_equal(quat, expected.quat[m])
        # no noise model in the scene: covariance unknown (all zeros, as sensor_msgs/Imu defines it)
        assert all(not d.angular_velocity_covariance.any() and not d.linear_acceleration_covariance.any()
                   for _, d in msgs)
    odom = topics["/truth/odometry"]
    pos = np.array([[d.pose.pose.position.x, d.pose.pose.position.y, d.pose.pose.position.z] for _, d in odom])
    np.testing.assert_array_equal(pos, expected.truth["position"])
    w = np.array([[d.twist.twist.angular.x, d.twist.twist.angular.y, d.twist.twist.angular.z] for _, d in odom])
    np.testing.assert_array_equal(w, expected.truth["omega_body"])
    # the body-frame linear twist has the navigation-frame speed
    v = np.array([[d.twist.twist.linear.x, d.twist.twist.linear.y, d.twist.twist.linear.z] for _, d in odom])
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), np.linalg.norm(expected.truth["velocity"], axis=1),
                               rtol=1e-12, atol=1e-12)


def test_a_generated_bag_replays(tmp_path):
    # generate a bag with truth, then replay it: its odometry drives the emulator, its Imu topic is the
    # recorded IMU. Same motion, so the figures must be near perfect.
    bag = tmp_path / "run.mcap"
    assert main(["generate", str(EXAMPLES / "helix.toml"), "-o", str(bag), "--truth", "--quiet"]) == 0
    overrides = tmp_path / "o.toml"
    overrides.write_text('[[imu]]\nname = "imu0"\nlever_arm_m = [-0.075, -0.075, 0.025]\n'
                         '[effects]\ngravity = true\nlever_arm = true\n')    # helix.toml's IMU
    report = tmp_path / "r"
    assert main(["replay", str(bag), "--scene", str(overrides), "--report", str(report), "--quiet"]) == 0
    import json
    figures = json.loads((report / "report.json").read_text())
    # the replay differentiates the 200 Hz odometry (spline5c) where generate had exact derivatives:
    # measured RMS differences ~3e-11 rad/s and ~1e-6 m/s^2 (bounds 100x)
    for c, bound in zip(figures["comparisons"], (1e-8, 1e-4)):
        assert c["quantity"] in ("gyro", "accel")
        assert max(a["rms_difference"] for a in c["axes"]) < bound, c
        assert min(a["correlation"] for a in c["axes"]) > 0.999999, c


def test_covariances_are_the_noise_models_per_sample_variances(tmp_path):
    """With the noise effect on, each Imu message carries diag(σ²) per axis, σ = N·√f_s (the noise density N
    discretized at the rate, specs/sensor-errors.md); computed here from the datasheet numbers, not from our
    code: gyro 0.014 °/s/√Hz (BMI088 preset) and accel 175 µg/√Hz, with a per-axis accel override."""
    import math
    rate = 200.0
    scene = tmp_path / "noisy.toml"
    scene.write_text(f"""
[scene]
rate_hz = {rate}
duration_s = 0.05
[trajectory]
x = "0"
y = "0"
z = "0"
[[imu]]
name = "a"
model = "bosch-bmi088"
[[imu]]
name = "b"
[imu.accel]
noise_density = ["100 ug/sqrt(Hz)", "200 ug/sqrt(Hz)", "300 ug/sqrt(Hz)"]
[effects]
gravity = true
noise = true
""")
    bag = tmp_path / "run.mcap"
    assert main(["generate", str(scene), "-o", str(bag), "--quiet"]) == 0
    topics = read_bag(bag)
    g = 9.80665
    expected = {"a": ([math.radians(0.014) ** 2 * rate] * 3, [(175e-6 * g) ** 2 * rate] * 3),
                "b": ([0.0] * 3, [(d * 1e-6 * g) ** 2 * rate for d in (100, 200, 300)])}
    for name, (gyro_var, acc_var) in expected.items():
        msgs = topics[f"/imu/{name}"]
        assert len(msgs) == 10
        for _, d in msgs:
            np.testing.assert_allclose(d.angular_velocity_covariance, np.diag(gyro_var).ravel(), rtol=1e-12, atol=0)
            np.testing.assert_allclose(d.linear_acceleration_covariance, np.diag(acc_var).ravel(), rtol=1e-12, atol=0)
