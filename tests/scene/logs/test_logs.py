"""Flight-log readers against the values the format's own library gives directly (pyulog, pymavlink's DFReader),
and a synthetic ROS 2 bag written with an independent writer (rosbags' CDR serializer + the mcap library)
replayed against the symbolic twin (tests/support/reference.py)."""

import numpy as np
import pytest
import sympy as sp
from scipy.spatial.transform import Rotation

from imu_emulator import scene_from_dict
from imu_emulator.errors import DataError, SceneError
from imu_emulator.scene.logs import load_log, load_recorded_imu
from tests.support.reference import imu_functions, t as T
from tests.support.paths import DATA

ULOG = DATA / "sample_appended_multiple.ulg"
BIN = DATA / "test.BIN"


def test_ulog_motion_and_imu_are_pyulogs():
    from pyulog import ULog
    ulog = ULog(str(ULOG))
    lp = ulog.get_dataset("vehicle_local_position").data
    va = ulog.get_dataset("vehicle_attitude").data
    sc = ulog.get_dataset("sensor_combined").data
    motion = load_log(ULOG)
    assert motion.frame == "NED"
    np.testing.assert_array_equal(motion.position.t, lp["timestamp"] * 1e-6)
    np.testing.assert_array_equal(motion.position.values, np.column_stack([lp["x"], lp["y"], lp["z"]]))
    np.testing.assert_array_equal(motion.velocity.values, np.column_stack([lp["vx"], lp["vy"], lp["vz"]]))
    np.testing.assert_array_equal(motion.attitude.t, va["timestamp"] * 1e-6)
    np.testing.assert_array_equal(motion.attitude.values, np.column_stack([va[f"q[{i}]"] for i in range(4)]))
    assert motion.origin_lla is None             # this log's estimator never set a reference point (all 0)
    imu = load_recorded_imu(ULOG)
    np.testing.assert_array_equal(imu.t, sc["timestamp"] * 1e-6)
    np.testing.assert_array_equal(imu.gyro, np.column_stack([sc[f"gyro_rad[{i}]"] for i in range(3)]))


def _dataflash(types):
    from pymavlink import DFReader
    reader = DFReader.DFReader_binary(str(BIN))
    out = {t: [] for t in types}
    while (m := reader.recv_match(type=list(types))) is not None:
        out[m.get_type()].append(m.to_dict())
    return out


def test_dataflash_motion_and_imu_are_dfreaders():
    msgs = _dataflash(["NKF1", "NKQ1", "IMU", "ATT", "POS", "ORGN"])
    motion = load_log(BIN)
    assert (motion.position.name, motion.attitude.name, motion.frame) == ("NKF1", "NKQ1", "NED")
    np.testing.assert_array_equal(motion.position.t, [m["TimeUS"] * 1e-6 for m in msgs["NKF1"]])
    np.testing.assert_array_equal(motion.position.values, [[m["PN"], m["PE"], m["PD"]] for m in msgs["NKF1"]])
    np.testing.assert_array_equal(motion.attitude.values, [[m[f"Q{i}"] for i in range(1, 5)] for m in msgs["NKQ1"]])
    o = [m for m in msgs["ORGN"] if m["Type"] == 0][-1]          # Type 0: the EKF origin (1: home)
    assert motion.origin_lla == (o["Lat"], o["Lng"], o["Alt"])
    imu = load_recorded_imu(BIN)
    np.testing.assert_array_equal(imu.gyro, [[m["GyrX"], m["GyrY"], m["GyrZ"]] for m in msgs["IMU"]])


def test_dataflash_att_euler_and_pos_latlon_sources():
    import pymap3d
    msgs = _dataflash(["ATT", "POS", "ORGN"])
    motion = load_log(BIN, position_source="POS", attitude_source="ATT")
    att = msgs["ATT"]
    expected = Rotation.from_euler("ZYX", [[m["Yaw"], m["Pitch"], m["Roll"]] for m in att], degrees=True)
    got = Rotation.from_quat(motion.attitude.values[:, [1, 2, 3, 0]])
    assert (expected.inv() * got).magnitude().max() < 1e-12
    o = [m for m in msgs["ORGN"] if m["Type"] == 0][-1]
    lla = np.array([[m["Lat"], m["Lng"], m["Alt"]] for m in msgs["POS"]])
    ned = np.column_stack(pymap3d.geodetic2ned(lla[:, 0], lla[:, 1], lla[:, 2], o["Lat"], o["Lng"], o["Alt"]))
    np.testing.assert_allclose(motion.position.values, ned, rtol=0, atol=1e-9)
    # the EKF's own NED position and the converted POS fixes agree to the decimetre
    ekf = load_log(BIN)
    tt = ekf.position.t[(ekf.position.t > motion.position.t[0]) & (ekf.position.t < motion.position.t[-1])]
    pos = np.column_stack([np.interp(tt, motion.position.t, motion.position.values[:, i]) for i in range(3)])
    ref = np.column_stack([np.interp(tt, ekf.position.t, ekf.position.values[:, i]) for i in range(3)])
    assert np.abs(pos - ref).max() < 0.1


@pytest.mark.parametrize("kwargs, match", [
    ({"position_source": "nope"}, r"no topic 'nope' in this log \(it has "),
    ({"attitude_source": "vehicle_attitude:3"}, r"topic 'vehicle_attitude' has instances \[0\], not 3"),
])
def test_ulog_source_errors(kwargs, match):
    with pytest.raises(DataError, match=match):
        load_log(ULOG, **kwargs)


def test_scene_from_a_log_defaults_to_its_frame_attitude_and_span():
    scene = scene_from_dict({"scene": {"rate_hz": 100}, "trajectory": {"file": str(ULOG)}, "imu": [{}]})
    assert scene.frame == "NED" and scene.attitude_mode == "file" and scene.attitude.kind == "quaternion"
    motion = load_log(ULOG)
    first = max(motion.position.t[0], motion.attitude.t[0])
    last = min(motion.position.t[-1], motion.attitude.t[-1])
    assert scene.t0_s == first and scene.duration_s == pytest.approx(last - first)
    with pytest.raises(SceneError, match=r"scene\.frame: sample_appended_multiple\.ulg is a NED log"):
        scene_from_dict({"scene": {"rate_hz": 100, "frame": "ENU"}, "trajectory": {"file": str(ULOG)}, "imu": [{}]})


# --- a synthetic ROS 2 bag ---------------------------------------------------------------------------------

POSITION = ("2*cos(2*pi*0.25*t)", "2*sin(2*pi*0.25*t)", "0.3*sin(2*pi*0.5*t)")
EULER = ("0.3*sin(2*pi*0.6*t)", "0.2*cos(2*pi*0.4*t)", "0.8*t")
T0_UNIX = 1_700_000_000


def write_bag(path, times, drop=(), imu_times=None):
    """nav_msgs/Odometry at the given times (seconds after T0_UNIX), serialized by rosbags, framed by mcap;
    with imu_times, also a sensor_msgs/msg/Imu topic holding the exact IMU output (sympy twin, ENU, gravity)."""
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_HUMBLE)
    Odometry = store.types["nav_msgs/msg/Odometry"]
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    PoseWC, Pose = store.types["geometry_msgs/msg/PoseWithCovariance"], store.types["geometry_msgs/msg/Pose"]
    TwistWC, Twist = store.types["geometry_msgs/msg/TwistWithCovariance"], store.types["geometry_msgs/msg/Twist"]
    Point, Quat = store.types["geometry_msgs/msg/Point"], store.types["geometry_msgs/msg/Quaternion"]
    Vector3 = store.types["geometry_msgs/msg/Vector3"]
    fp = [sp.lambdify(T, sp.sympify(e, locals={"t": T}), "numpy") for e in POSITION]
    fe = [sp.lambdify(T, sp.sympify(e, locals={"t": T}), "numpy") for e in EULER]
    msgdef, _ = store.generate_msgdef("nav_msgs/msg/Odometry", ros_version=2)
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema("nav_msgs/msg/Odometry", "ros2msg", msgdef.encode())
        channel = writer.register_channel("/odom", "cdr", schema)
        for i, t in enumerate(times):
            if i in drop:
                continue
            x, y, z = (float(f(t)) for f in fp)
            roll, pitch, yaw = (float(f(t)) for f in fe)
            qx, qy, qz, qw = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()
            ns = int(round(t * 1e9))
            msg = Odometry(header=Header(stamp=Time(sec=T0_UNIX + ns // 10**9, nanosec=ns % 10**9), frame_id="odom"),
                           child_frame_id="base_link",
                           pose=PoseWC(pose=Pose(position=Point(x=x, y=y, z=z), orientation=Quat(x=qx, y=qy, z=qz, w=qw)),
                                       covariance=np.zeros(36)),
                           twist=TwistWC(twist=Twist(linear=Vector3(x=0., y=0., z=0.), angular=Vector3(x=0., y=0., z=0.)),
                                         covariance=np.zeros(36)))
            data = bytes(store.serialize_cdr(msg, "nav_msgs/msg/Odometry"))
            writer.add_message(channel, log_time=(T0_UNIX * 10**9 + ns), data=data,
                               publish_time=(T0_UNIX * 10**9 + ns))
        if imu_times is not None:
            Imu = store.types["sensor_msgs/msg/Imu"]
            imu_def, _ = store.generate_msgdef("sensor_msgs/msg/Imu", ros_version=2)
            imu_channel = writer.register_channel(
                "/imu", "cdr", writer.register_schema("sensor_msgs/msg/Imu", "ros2msg", imu_def.encode()))
            acc, gyro = imu_functions([sp.sympify(e, locals={"t": T}) for e in POSITION],
                                      [sp.sympify(e, locals={"t": T}) for e in EULER])(imu_times)
            for t, a, w in zip(imu_times, acc, gyro):
                ns = int(round(t * 1e9))
                msg = Imu(header=Header(stamp=Time(sec=T0_UNIX + ns // 10**9, nanosec=ns % 10**9), frame_id="imu"),
                          orientation=Quat(x=0., y=0., z=0., w=1.), orientation_covariance=np.zeros(9),
                          angular_velocity=Vector3(x=w[0], y=w[1], z=w[2]), angular_velocity_covariance=np.zeros(9),
                          linear_acceleration=Vector3(x=a[0], y=a[1], z=a[2]),
                          linear_acceleration_covariance=np.zeros(9))
                writer.add_message(imu_channel, log_time=T0_UNIX * 10**9 + ns, publish_time=T0_UNIX * 10**9 + ns,
                                   data=bytes(store.serialize_cdr(msg, "sensor_msgs/msg/Imu")))
        writer.finish()


def test_synthetic_bag_replays_to_the_symbolic_twin(tmp_path):
    rng = np.random.default_rng(5)
    times = np.cumsum(rng.uniform(0.008, 0.012, 400))       # irregular stamps, ~100 Hz
    bag = tmp_path / "run.mcap"
    write_bag(bag, times)
    scene = scene_from_dict({"scene": {"rate_hz": 200}, "trajectory": {"file": str(bag)},
                             "imu": [{"name": "a", "lever_arm_m": [0.1, 0.0, -0.05]}],
                             "effects": {"gravity": True, "lever_arm": True}})
    assert scene.frame == "ENU"
    from imu_emulator.runtime.simulation import Simulation
    out = Simulation(scene).run()
    ref = imu_functions([sp.sympify(e, locals={"t": T}) for e in POSITION],
                        [sp.sympify(e, locals={"t": T}) for e in EULER], lever=(0.1, 0.0, -0.05))
    acc, gyro = ref(out.t_s)             # the bag's clock starts at the whole second T0_UNIX
    inner = (out.t_s > out.t_s[0] + 0.3) & (out.t_s < out.t_s[-1] - 0.3)
    # spline5c at ~100 Hz on this motion, measured inside: 9.6e-5 m/s^2, 1.2e-7 rad/s (bounds 3x that); the
    # same bag with regular 10 ms stamps gives 4e-9 and 3e-12: the 8-12 ms jitter costs the spline dearly
    assert np.abs(out.accel[0] - acc)[inner].max() < 3e-4
    assert np.abs(out.gyro[0] - gyro)[inner].max() < 4e-7


def test_a_gap_in_the_bag_is_an_error_naming_the_time(tmp_path):
    times = 0.01 * np.arange(1, 301)
    bag = tmp_path / "gap.mcap"
    write_bag(bag, times, drop=range(150, 200))        # 0.5 s without a message after t = 1.50 s
    with pytest.raises(SceneError, match=r"/odom: no sample for 0\.510 s after t = 1\.500000 s"):
        scene_from_dict({"scene": {"rate_hz": 100}, "trajectory": {"file": str(bag)}, "imu": [{}]})
    # a replay of the part before the gap is fine
    scene = scene_from_dict({"scene": {"rate_hz": 100, "duration_s": 1.0},
                             "trajectory": {"file": str(bag)}, "imu": [{}]})
    assert scene.n_samples == 100


def test_replay_splits_at_a_gap_and_each_part_matches_the_symbolic_twin(tmp_path, capsys):
    """`replay --gaps split` (the default): one scene per part between gaps, written to one file; the stamps
    jump across the gap; inside each part the output is the sympy twin's (spline5c at 100 Hz, regular stamps:
    4e-9 m/s^2 and 3e-12 rad/s inside a whole bag, test above; bounds 1e-6 and 1e-9 leave room for the parts'
    ends, 0.3 s away)."""
    from imu_emulator.cli import main
    times = 0.01 * np.arange(1, 401)
    bag = tmp_path / "gap.mcap"
    write_bag(bag, times, drop=range(150, 200))        # nothing after t = 1.50 s until 2.01 s
    out = tmp_path / "out.npz"
    assert main(["replay", str(bag), "-o", str(out), "--scene", str(_overrides(tmp_path))]) == 0
    err = capsys.readouterr().err
    assert "replayed 2 parts" in err
    data = np.load(out)
    t = data["t"]
    first, second = t[t <= 1.5 + 1e-9], t[t > 1.5 + 1e-9]
    assert first.size and second.size and second[0] >= 2.01 - 1e-9
    np.testing.assert_allclose(np.diff(first), 0.01, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.diff(second), 0.01, rtol=0, atol=1e-9)
    assert first[-1] > 1.49 and second[-1] > 3.99
    ref = imu_functions([sp.sympify(e, locals={"t": T}) for e in POSITION],
                        [sp.sympify(e, locals={"t": T}) for e in EULER])
    for part in (first, second):
        inner = (t > part[0] + 0.3) & (t < part[-1] - 0.3)
        acc, gyro = ref(t[inner])
        assert np.abs(data["accel"][0][inner] - acc).max() < 1e-6
        assert np.abs(data["gyro"][0][inner] - gyro).max() < 1e-9


def test_replay_with_gaps_error_names_the_time(tmp_path, capsys):
    from imu_emulator.cli import main
    times = 0.01 * np.arange(1, 401)
    bag = tmp_path / "gap.mcap"
    write_bag(bag, times, drop=range(150, 200))
    code = main(["replay", str(bag), "-o", str(tmp_path / "out.csv"), "--gaps", "error",
                 "--scene", str(_overrides(tmp_path))])
    assert code == 2
    assert "/odom: no sample for 0.510 s after t = 1.500000 s" in capsys.readouterr().err
    assert not (tmp_path / "out.csv").exists()


def _overrides(tmp_path):
    path = tmp_path / "over.toml"
    path.write_text("[scene]\nrate_hz = 100\n")
    return path
