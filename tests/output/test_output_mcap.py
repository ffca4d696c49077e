"""`generate -o run.mcap`: a ROS 2 bag read back with an independent reader: the mcap library's raw records
decoded by rosbags' own CDR deserializer (not mcap-ros2-support, which wrote it)."""
import calendar
import json

import numpy as np
import pytest

from imu_emulator import load_scene
from imu_emulator.cli import main
from imu_emulator.runtime.simulation import Simulation
from tests.support.paths import EXAMPLES



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


# REP 103 / REP 105, written here from the REPs, not from the module under test: FLU = diag(1, -1, -1) FRD, and
# ENU = the axes of NED swapped, z negated
FLU_FROM_FRD = np.diag([1.0, -1.0, -1.0])
ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
# the documented default instant of scene time 0: 2024-01-01T00:00:00Z
DEFAULT_EPOCH_NS = calendar.timegm((2024, 1, 1, 0, 0, 0)) * 10**9


def _vectors(msgs, field):
    return np.array([[getattr(getattr(d, field), a) for a in "xyz"] for _, d in msgs])


def _rotations(quaternions):
    from scipy.spatial.transform import Rotation
    return Rotation.from_quat([[q.x, q.y, q.z, q.w] for q in quaternions]).as_matrix()


def test_generated_bag_holds_every_imu_sample_and_truth_in_rep103_axes(tmp_path):
    """two_imus.toml is a NED scene: the bag has the same samples turned into forward-left-up IMUs and an ENU
    world, stamps on the default epoch, and /tf_static with imu1's lever arm and mounting (scipy's Rotation)."""
    from scipy.spatial.transform import Rotation
    scene_path = EXAMPLES / "two_imus.toml"
    bag = tmp_path / "run.mcap"
    assert main(["generate", str(scene_path), "-o", str(bag), "--truth", "--quiet"]) == 0
    scene = load_scene(scene_path)
    assert scene.frame == "NED"
    expected = Simulation(scene, truth=True, attitude=True).run()
    topics = read_bag(bag)
    assert set(topics) == {f"/imu/{n}" for n in scene.imu_names} | {"/truth/odometry", "/tf_static"}
    ns = expected.time_ns() + DEFAULT_EPOCH_NS
    for m, name in enumerate(scene.imu_names):
        msgs = topics[f"/imu/{name}"]
        assert len(msgs) == scene.n_samples
        np.testing.assert_array_equal(np.array([t for t, _ in msgs]), ns)
        stamps = np.array([d.header.stamp.sec * 10**9 + d.header.stamp.nanosec for _, d in msgs])
        np.testing.assert_array_equal(stamps, ns)
        assert {d.header.frame_id for _, d in msgs} == {name}
        np.testing.assert_array_equal(_vectors(msgs, "angular_velocity"), expected.gyro[m] @ FLU_FROM_FRD.T)
        np.testing.assert_array_equal(_vectors(msgs, "linear_acceleration"), expected.accel[m] @ FLU_FROM_FRD.T)
        # orientation: the FLU sensor frame w.r.t. ENU = ENU_FROM_NED C_ned_sensor FRD_FROM_FLU
        from scipy.spatial.transform import Rotation as R
        c_sensor = R.from_quat(expected.quat[m][:, [1, 2, 3, 0]]).as_matrix()
        np.testing.assert_allclose(_rotations([d.orientation for _, d in msgs]),
                                   ENU_FROM_NED @ c_sensor @ FLU_FROM_FRD, rtol=0, atol=1e-12)
        assert all(not d.angular_velocity_covariance.any() and not d.linear_acceleration_covariance.any()
                   for _, d in msgs)
    odom = topics["/truth/odometry"]
    assert {(d.header.frame_id, d.child_frame_id) for _, d in odom} == {("world", "base_link")}
    pos = np.array([[d.pose.pose.position.x, d.pose.pose.position.y, d.pose.pose.position.z] for _, d in odom])
    np.testing.assert_array_equal(pos, expected.truth["position"] @ ENU_FROM_NED.T)
    assert np.allclose(pos[:, 2], 50.0)           # height_m = -50 in NED: 50 m up
    w = np.array([[d.twist.twist.angular.x, d.twist.twist.angular.y, d.twist.twist.angular.z] for _, d in odom])
    np.testing.assert_array_equal(w, expected.truth["omega_body"] @ FLU_FROM_FRD.T)
    c_body = Rotation.from_euler("ZYX", expected.truth["euler"][:, ::-1]).as_matrix()
    np.testing.assert_allclose(_rotations([d.pose.pose.orientation for _, d in odom]),
                               ENU_FROM_NED @ c_body @ FLU_FROM_FRD, rtol=0, atol=1e-12)
    v = np.array([[d.twist.twist.linear.x, d.twist.twist.linear.y, d.twist.twist.linear.z] for _, d in odom])
    np.testing.assert_allclose(v, np.einsum("nji,nj->ni", c_body, expected.truth["velocity"]) @ FLU_FROM_FRD.T,
                               rtol=0, atol=1e-12)
    # /tf_static: one message at the first stamp, base_link -> each IMU
    (log_time, tf), = topics["/tf_static"]
    assert log_time == ns[0]
    by_child = {t.child_frame_id: t for t in tf.transforms}
    assert set(by_child) == {"imu0", "imu1"} and {t.header.frame_id for t in tf.transforms} == {"base_link"}
    assert all(t.header.stamp.sec * 10**9 + t.header.stamp.nanosec == ns[0] for t in tf.transforms)
    t0, t1 = by_child["imu0"].transform, by_child["imu1"].transform
    np.testing.assert_array_equal([t0.translation.x, t0.translation.y, t0.translation.z], [0, 0, 0])
    np.testing.assert_allclose(_rotations([t0.rotation])[0], np.eye(3), rtol=0, atol=1e-15)
    # imu1: lever arm (0, -0.3, 0) FRD = 0.3 m to the left; mounting roll 180, yaw 90 (z-y-x) in FRD
    np.testing.assert_allclose([t1.translation.x, t1.translation.y, t1.translation.z], [0.0, 0.3, 0.0], atol=0)
    mounting = Rotation.from_euler("ZYX", [90, 0, 180], degrees=True).as_matrix()
    np.testing.assert_allclose(_rotations([t1.rotation])[0], FLU_FROM_FRD @ mounting @ FLU_FROM_FRD, atol=1e-15)
    # the tf is what the samples carry: imu1's accelerations are imu0's seen through it, plus the lever arm's
    # (at rest in the turn: centripetal) terms; its gyro exactly imu0's rotated
    gyro0, gyro1 = _vectors(topics["/imu/imu0"], "angular_velocity"), _vectors(topics["/imu/imu1"], "angular_velocity")
    np.testing.assert_allclose(gyro1 @ _rotations([t1.rotation])[0].T, gyro0, rtol=0, atol=1e-12)
    meta = _metadata(bag)
    assert meta["scene_frame"] == "NED" and meta["axes"] == "rep103" and int(meta["start_ns"]) == DEFAULT_EPOCH_NS
    assert int(meta["seed"]) == scene.seed and json.loads(meta["versions"])["mcap"] == mcap_version()
    from imu_emulator.scene.digest import scene_digest
    assert meta["scene_sha256"] == scene_digest(scene)


def _metadata(path):
    from mcap.reader import make_reader
    with open(path, "rb") as f:
        records = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    return records["imu_emulator"]


def mcap_version():
    from importlib.metadata import version
    return version("mcap")


REST = """[scene]
rate_hz = 10
duration_s = 0.5
frame = "{frame}"
t0_s = {t0}
[trajectory]
x = "0"
y = "0"
z = "{z}"
[[imu]]
name = "fc"
[effects]
gravity = true
"""


@pytest.mark.parametrize("frame, z", [("ENU", "10"), ("NED", "-10")])
def test_a_level_imu_at_rest_reads_plus_g_up_and_ten_metres_up_is_plus_ten(tmp_path, frame, z):
    """REP 103 whatever the scene's frame: at rest and level, linear_acceleration = (0, 0, +g) in the IMU's FLU
    frame `fc`; 10 m up is odometry z = +10 in the ENU world; facing the scene's yaw 0 (ENU: east, NED: north)
    the body's orientation in ENU is a yaw of 0 or +90 degrees. Stamps start at the --start-time given,
    2026-03-01T12:00:00+01:00 (11:00 UTC) plus t0 = 2.5 s."""
    from scipy.spatial.transform import Rotation
    scene = tmp_path / "rest.toml"
    scene.write_text(REST.format(frame=frame, z=z, t0=2.5))
    bag = tmp_path / "rest.mcap"
    assert main(["generate", str(scene), "-o", str(bag), "--truth", "--quiet",
                 "--start-time", "2026-03-01T12:00:00+01:00"]) == 0
    topics = read_bag(bag)
    imu = topics["/imu/fc"]
    assert {d.header.frame_id for _, d in imu} == {"fc"}
    np.testing.assert_allclose(_vectors(imu, "linear_acceleration"), [[0.0, 0.0, 9.80665]] * 5, rtol=0, atol=1e-12)
    odom = [d for _, d in topics["/truth/odometry"]]
    np.testing.assert_allclose([[d.pose.pose.position.x, d.pose.pose.position.y, d.pose.pose.position.z]
                                for d in odom], [[0.0, 0.0, 10.0]] * 5, rtol=0, atol=1e-12)
    yaw = 0.0 if frame == "ENU" else 90.0
    np.testing.assert_allclose(_rotations([d.pose.pose.orientation for d in odom]),
                               [Rotation.from_euler("z", yaw, degrees=True).as_matrix()] * 5, rtol=0, atol=1e-12)
    np.testing.assert_allclose(_rotations([d.orientation for _, d in imu]),
                               [Rotation.from_euler("z", yaw, degrees=True).as_matrix()] * 5, rtol=0, atol=1e-12)
    start = calendar.timegm((2026, 3, 1, 11, 0, 0)) * 10**9 + 2_500_000_000
    np.testing.assert_array_equal([t for t, _ in imu], start + np.arange(5) * 100_000_000)
    assert all(d.header.stamp.sec * 10**9 + d.header.stamp.nanosec >= DEFAULT_EPOCH_NS for _, d in imu)


def test_scene_axes_keep_the_scene_frames_and_say_so(tmp_path):
    """--ros-axes scene: a NED scene's vectors as they are, frame ids <imu>_frd, base_link_frd, world_ned."""
    scene = tmp_path / "rest.toml"
    scene.write_text(REST.format(frame="NED", z="-10", t0=0.0))
    bag = tmp_path / "rest.mcap"
    assert main(["generate", str(scene), "-o", str(bag), "--truth", "--quiet", "--ros-axes", "scene"]) == 0
    topics = read_bag(bag)
    assert {d.header.frame_id for _, d in topics["/imu/fc"]} == {"fc_frd"}
    np.testing.assert_allclose(_vectors(topics["/imu/fc"], "linear_acceleration")[:, 2], -9.80665, rtol=0, atol=1e-12)
    odom = [d for _, d in topics["/truth/odometry"]]
    assert {(d.header.frame_id, d.child_frame_id) for d in odom} == {("world_ned", "base_link_frd")}
    np.testing.assert_allclose([d.pose.pose.position.z for d in odom], -10.0, rtol=0, atol=1e-12)
    assert {t.child_frame_id for t in topics["/tf_static"][0][1].transforms} == {"fc_frd"}
    assert topics["/imu/fc"][0][0] == DEFAULT_EPOCH_NS         # t0 = 0: the first stamp is the epoch, never 0


@pytest.mark.parametrize("bad", ["yesterday", "1969-12-31T23:59:59Z", "2040-01-01T00:00:00Z"])
def test_a_bad_start_time_is_one_error_line(tmp_path, capsys, bad):
    with pytest.raises(SystemExit) as exit_info:
        main(["generate", str(EXAMPLES / "two_imus.toml"), "-o", str(tmp_path / "x.mcap"), "--start-time", bad])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("error: argument --start-time: ") and bad in err
    assert "Traceback" not in err and not (tmp_path / "x.mcap").exists()


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
