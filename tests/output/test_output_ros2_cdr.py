"""Every ROS 2 message the bag writer serializes a block at a time (imu_emulator.output.ros2), byte for byte
against rosbags' CDR serializer (an independent implementation of the ROS 2 message layouts, from the Humble
message files), and the MCAP around them read back by the mcap library with its CRC checks on."""
import io

import numpy as np
import pytest

from imu_emulator.output.ros2 import messages as msg
from imu_emulator.output.ros2.bag import BagFile

rosbags = pytest.importorskip("rosbags.typesys")
STORE = rosbags.get_typestore(rosbags.Stores.ROS2_HUMBLE)
T = STORE.types


def _time(ns):
    return T["builtin_interfaces/msg/Time"](sec=int(ns // 10**9), nanosec=int(ns % 10**9))


def _header(ns, frame):
    return T["std_msgs/msg/Header"](stamp=_time(ns), frame_id=frame)


def _vec(v):
    return T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _quat(q):      # x, y, z, w
    return T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def _write(channels_and_fills, n):
    """A bag with one block of n rows: channels_and_fills = [(topic, type, layout, fill(rows_view))]."""
    buffer = io.BytesIO()
    bag = BagFile(buffer, library="test")
    channels = [bag.channel(topic, kind, msg.DEFINITIONS[kind], layout) for topic, kind, layout, _ in
                channels_and_fills]
    rows = bag.rows(channels, n)
    for channel, (_, _, _, fill) in zip(channels, channels_and_fills):
        fill(rows[f"c{channel.id}"])
    bag.write_rows(rows)
    bag.finish()
    return buffer.getvalue()


def _messages(data):
    """{topic: [(log_time, publish_time, raw CDR bytes, schema name)]} with the mcap library, CRCs validated."""
    from mcap.reader import make_reader
    found = {}
    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    for schema, channel, message in reader.iter_messages(log_time_order=False):
        assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
        found.setdefault(channel.topic, []).append((message.log_time, message.publish_time, message.data,
                                                    schema.name))
    return found


RNG = np.random.default_rng(24)
N = 7
NS = 1_704_067_200 * 10**9 + np.arange(N, dtype=np.int64) * 2_500_001 + 999_999_999


def _stamp(rows):
    rows["sec"], rows["nanosec"] = NS // 10**9, NS % 10**9
    rows["log_time"] = rows["publish_time"] = NS


def test_imu_and_odometry_blocks_equal_rosbags_serialization_byte_for_byte():
    q, w, a = RNG.normal(size=(N, 4)), RNG.normal(size=(N, 3)), RNG.normal(size=(N, 3))
    p, v, r = RNG.normal(size=(N, 3)) * 1e5, RNG.normal(size=(N, 3)), RNG.normal(size=(N, 3))
    cov_g, cov_a = np.diag([1e-6, 2e-6, 3e-6]).ravel(), np.diag([4e-4, 5e-4, 6e-4]).ravel()
    no_orientation = [-1.0] + [0.0] * 8

    def fill_imu(rows):
        _stamp(rows)
        rows["orientation"], rows["angular_velocity"], rows["linear_acceleration"] = q, w, a

    def fill_odometry(rows):
        _stamp(rows)
        rows["position"], rows["orientation"], rows["linear"], rows["angular"] = p, q, v, r

    data = _write([("/imu/x", msg.IMU, msg.imu("x_frd", no_orientation, cov_g, cov_a), fill_imu),
                   ("/odom", msg.ODOMETRY, msg.odometry("world", "base_link"), fill_odometry)], N)
    found = _messages(data)
    Imu, Odometry = T["sensor_msgs/msg/Imu"], T["nav_msgs/msg/Odometry"]
    for j, (log, pub, raw, schema) in enumerate(found["/imu/x"]):
        assert (log, pub, schema) == (NS[j], NS[j], "sensor_msgs/msg/Imu")
        want = Imu(header=_header(NS[j], "x_frd"), orientation=_quat(q[j]),
                   orientation_covariance=np.array(no_orientation), angular_velocity=_vec(w[j]),
                   angular_velocity_covariance=cov_g, linear_acceleration=_vec(a[j]),
                   linear_acceleration_covariance=cov_a)
        assert bytes(STORE.serialize_cdr(want, "sensor_msgs/msg/Imu")) == raw
    P = T["geometry_msgs/msg/Pose"]
    for j, (_, _, raw, _) in enumerate(found["/odom"]):
        want = Odometry(
            header=_header(NS[j], "world"), child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](
                pose=P(position=T["geometry_msgs/msg/Point"](x=p[j, 0], y=p[j, 1], z=p[j, 2]),
                       orientation=_quat(q[j])), covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=_vec(v[j]), angular=_vec(r[j])), covariance=np.zeros(36)))
        assert bytes(STORE.serialize_cdr(want, "nav_msgs/msg/Odometry")) == raw


@pytest.mark.parametrize("frame", ["earth", "imu_a", "gnss1"])   # string lengths move the alignment padding
def test_companion_and_fix_messages_equal_rosbags_serialization(frame):
    m, pressure = RNG.normal(size=(N, 3)) * 5e-5, 101325.0 + RNG.normal(size=N)
    llh, cov = RNG.normal(size=(N, 3)), np.abs(RNG.normal(size=(N, 9)))
    status = RNG.choice([-1, 0], size=N)

    def fill_mag(rows):
        _stamp(rows)
        rows["magnetic_field"] = m

    def fill_pressure(rows):
        _stamp(rows)
        rows["fluid_pressure"] = pressure

    def fill_fix(rows):
        _stamp(rows)
        rows["status"], rows["position"], rows["position_covariance"] = status, llh, cov

    def fill_truth_fix(rows):
        _stamp(rows)
        rows["position"] = llh

    data = _write([("/mag", msg.MAGNETIC_FIELD, msg.magnetic_field(frame), fill_mag),
                   ("/pressure", msg.FLUID_PRESSURE, msg.fluid_pressure(frame), fill_pressure),
                   ("/fix", msg.NAVSATFIX, msg.navsatfix_measured(frame), fill_fix),
                   ("/fix_unknown", msg.NAVSATFIX, msg.navsatfix_measured(frame, msg.COVARIANCE_TYPE_UNKNOWN),
                    fill_fix),
                   ("/truth/fix", msg.NAVSATFIX, msg.navsatfix_truth(frame), fill_truth_fix)], N)
    found = _messages(data)
    Status, Fix = T["sensor_msgs/msg/NavSatStatus"], T["sensor_msgs/msg/NavSatFix"]
    for j in range(N):
        want = {
            "/mag": T["sensor_msgs/msg/MagneticField"](header=_header(NS[j], frame), magnetic_field=_vec(m[j]),
                                                       magnetic_field_covariance=np.zeros(9)),
            "/pressure": T["sensor_msgs/msg/FluidPressure"](header=_header(NS[j], frame),
                                                            fluid_pressure=pressure[j], variance=0.0),
            "/fix": Fix(header=_header(NS[j], frame), status=Status(status=int(status[j]), service=1),
                        latitude=llh[j, 0], longitude=llh[j, 1], altitude=llh[j, 2], position_covariance=cov[j],
                        position_covariance_type=2),
            "/fix_unknown": Fix(header=_header(NS[j], frame), status=Status(status=int(status[j]), service=1),
                                latitude=llh[j, 0], longitude=llh[j, 1], altitude=llh[j, 2],
                                position_covariance=cov[j], position_covariance_type=0),
            "/truth/fix": Fix(header=_header(NS[j], frame), status=Status(status=0, service=0),
                              latitude=llh[j, 0], longitude=llh[j, 1], altitude=llh[j, 2],
                              position_covariance=np.zeros(9), position_covariance_type=3)}
        for topic, message in want.items():
            raw = found[topic][j][2]
            assert bytes(STORE.serialize_cdr(message, found[topic][j][3])) == raw, topic


def test_tf_message_with_several_transforms_equals_rosbags_serialization():
    children = ["a", "imu_long_name", "c_frd"]
    t, q = RNG.normal(size=(3, 3)), RNG.normal(size=(3, 4))

    def fill(rows):
        rows["log_time"] = rows["publish_time"] = NS[:1]
        for i in range(3):
            rows[f"sec{i}"], rows[f"nanosec{i}"] = NS[0] // 10**9, NS[0] % 10**9
            rows[f"translation{i}"], rows[f"rotation{i}"] = t[i], q[i]

    found = _messages(_write([("/tf_static", msg.TF_MESSAGE, msg.tf_message("base_link", children), fill)], 1))
    transforms = [T["geometry_msgs/msg/TransformStamped"](
        header=_header(NS[0], "base_link"), child_frame_id=child,
        transform=T["geometry_msgs/msg/Transform"](translation=_vec(t[i]), rotation=_quat(q[i])))
        for i, child in enumerate(children)]
    want = T["tf2_msgs/msg/TFMessage"](transforms=transforms)
    assert bytes(STORE.serialize_cdr(want, "tf2_msgs/msg/TFMessage")) == found["/tf_static"][0][2]


def test_many_chunks_index_every_message_in_time_order(monkeypatch):
    """A block larger than a chunk: the mcap library's indexed, time-ordered reading finds every message once,
    with the message index records and chunk indexes the writer built with numpy."""
    from mcap.reader import make_reader
    from imu_emulator.output.ros2 import bag as bag_module
    monkeypatch.setattr(bag_module, "CHUNK_BYTES", 4096)
    n = 1000
    ns = 10**18 + np.arange(n, dtype=np.int64) * 1000

    def fill(rows):
        rows["sec"], rows["nanosec"] = ns // 10**9, ns % 10**9
        rows["log_time"] = rows["publish_time"] = ns
        rows["fluid_pressure"] = np.arange(n)

    data = _write([("/p", msg.FLUID_PRESSURE, msg.fluid_pressure("b"), fill),
                   ("/q", msg.FLUID_PRESSURE, msg.fluid_pressure("bb"), fill)], n)
    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    summary = reader.get_summary()
    assert len(summary.chunk_indexes) > 10 and summary.statistics.message_count == 2 * n
    assert summary.statistics.channel_message_counts == {1: n, 2: n}
    times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
    assert times == sorted(times) and len(times) == 2 * n
    assert sorted(set(times)) == list(ns)
