"""ROS 2 bags in MCAP (`.mcap`), read with the `mcap` library and mcap-ros2-support's CDR decoder: no ROS
installation needed.

Motion from a `nav_msgs/msg/Odometry` topic (pose.pose) or a `geometry_msgs/msg/PoseStamped` topic (pose):
position in the message's frame and orientation child/body -> that frame. ROS's convention (REP 103) is
ENU for the world and forward-left-up for the body, so these logs are ENU. Recorded IMU: a
`sensor_msgs/msg/Imu` topic (angular_velocity, linear_acceleration). ROS quaternions are (x, y, z, w); they
are reordered to the scalar-first form here.

Times are the messages' header stamps, counted from the whole second at which the bag starts (a Unix time
of 1.7e9 s held in a double would carry 0.24 us of rounding into every stamp); the offset is in `notes`.
By default the first Odometry topic is used, else the first PoseStamped topic; `position_source` (or
`attitude_source`) names another topic.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imu_emulator.errors import DataError
from imu_emulator.scene.logs import LogMotion, RecordedImu, require, series

ODOMETRY = "nav_msgs/msg/Odometry"
POSE = "geometry_msgs/msg/PoseStamped"
IMU = "sensor_msgs/msg/Imu"


def _messages(path: Path, source: str | None, kinds: tuple[str, ...], what: str):
    """(topic, type, second offset, decoded messages in log order) of the chosen topic."""
    reader_mod = require("mcap.reader", "ROS 2 bags (MCAP)")
    decoder = require("mcap_ros2.decoder", "ROS 2 bags (MCAP)")
    try:
        with open(path, "rb") as f:
            reader = reader_mod.make_reader(f, decoder_factories=[decoder.DecoderFactory()])
            summary = reader.get_summary()
            if summary is None:
                raise DataError(f"{path.name}: MCAP file without a summary section (was it closed properly?)")
            types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
            topic = _choose(path, types, source, kinds, what)
            if topic is None:
                return None
            start = summary.statistics.message_start_time if summary.statistics else 0
            messages = [(m.log_time, d) for _, _, m, d in reader.iter_decoded_messages(topics=[topic])]
    except DataError:
        raise
    except Exception as exc:       # mcap raises its own error types, struct and zstd errors
        raise DataError(f"{path.name}: not a readable MCAP file ({exc})") from None
    return topic, types[topic], int(start // 1_000_000_000), messages


def _choose(path: Path, types: dict, source, kinds, what):
    if source is not None:
        if source not in types:
            raise DataError(f"{path.name}: no topic {source!r} (it has {', '.join(sorted(types)) or 'none'})")
        if types[source] not in kinds:
            raise DataError(f"{path.name}: topic {source!r} is {types[source]}, expected {' or '.join(kinds)}")
        return source
    for kind in kinds:
        for topic in sorted(types):
            if types[topic] == kind:
                return topic
    return None


def _stamps(messages, second0: int) -> np.ndarray:
    sec = np.array([d.header.stamp.sec for _, d in messages], dtype=np.int64)
    nsec = np.array([d.header.stamp.nanosec for _, d in messages], dtype=np.int64)
    if not sec.any() and not nsec.any():       # unstamped messages: the time they were logged
        log_ns = np.array([t for t, _ in messages], dtype=np.int64)
        sec, nsec = log_ns // 1_000_000_000, log_ns % 1_000_000_000
    return (sec - second0).astype(np.float64) + nsec * 1e-9


def _pose(d):
    return d.pose.pose if hasattr(d.pose, "pose") else d.pose


def read_motion(path: Path, position_source=None, attitude_source=None) -> LogMotion:
    found = _messages(path, position_source or attitude_source, (ODOMETRY, POSE), "pose")
    if found is None:
        raise DataError(f"{path.name}: no {ODOMETRY} or {POSE} topic in this bag")
    topic, _, second0, messages = found
    if attitude_source is not None and position_source is not None and attitude_source != position_source:
        raise DataError(f"{path.name}: position and attitude come from one pose topic here; "
                        f"got {position_source!r} and {attitude_source!r}")
    if not messages:
        raise DataError(f"{path.name}: topic {topic!r} has no messages")
    t = _stamps(messages, second0)
    poses = [_pose(d) for _, d in messages]
    position = np.array([[p.position.x, p.position.y, p.position.z] for p in poses])
    quat = np.array([[p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z] for p in poses])
    pos, note1 = series(topic, path.name, t, position)
    att, note2 = series(topic, path.name, t, quat)
    notes = [n for n in (note1, note2) if n] + [f"times are seconds after Unix time {second0} s"]
    return LogMotion(source=path, frame="ENU", position=pos, attitude=att, notes=tuple(notes))


def read_imu(path: Path, source=None) -> RecordedImu | None:
    found = _messages(path, source, (IMU,), "IMU")
    if found is None:
        return None
    topic, _, second0, messages = found
    t = _stamps(messages, second0)
    gyro = np.array([[d.angular_velocity.x, d.angular_velocity.y, d.angular_velocity.z] for _, d in messages])
    accel = np.array([[d.linear_acceleration.x, d.linear_acceleration.y, d.linear_acceleration.z]
                      for _, d in messages])
    keep = np.concatenate([[True], np.diff(t) > 0])
    return RecordedImu(topic, t[keep], gyro[keep], accel[keep])
