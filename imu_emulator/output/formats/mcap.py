"""Samples as a ROS 2 bag in MCAP (`-o run.mcap`): one `sensor_msgs/msg/Imu` topic per IMU (`/imu/<name>`,
frame_id = the IMU's name), and with truth a `nav_msgs/msg/Odometry` topic `/truth/odometry` (frame_id
"world", child "base_link": position and body attitude in the scene's navigation frame, twist in the body
frame as REP 147 / nav_msgs ask). Written with mcap-ros2-support (CDR), readable by `ros2 bag` and Foxglove
without a ROS installation; block by block, so memory does not grow with the run.

Covariances: given per IMU (gyro and accelerometer variance per axis, (rad/s)^2 and (m/s^2)^2) when a sensor
noise model supplies them (the noise effect's per-sample variance, effects.noise.variances), on the diagonal; otherwise all zeros, which sensor_msgs/Imu defines as "covariance
unknown" (-1 in element 0 would instead say "this field carries no data", and consumers would drop it).
Earth truth (a scene on the Earth, --truth): `/truth/navsatfix`, a `sensor_msgs/msg/NavSatFix` per sample (WGS-84
latitude and longitude in degrees, altitude = ellipsoidal height in m; status STATUS_FIX, covariance type
COVARIANCE_TYPE_KNOWN with zeros: the truth has no error), and `/truth/odometry_ecef`, a `nav_msgs/msg/Odometry`
with frame_id "earth" (REP 105's name for ECEF) and child "base_link_frd": ECEF position, the attitude of the
forward-right-down body w.r.t. ECEF, and as twist (in the body, as nav_msgs asks) the Earth-referenced
velocity and the body's rate w.r.t. the Earth, omega_eb.

Size: the uncompressed bytes of the CDR messages, their records and index entries; the file is compressed
(zstd) and comes out smaller, 0.1-0.7 of it.

Orientation: the sensor frame's attitude (the emulator's truth, sensor -> navigation) when the simulation
provides it, else orientation_covariance[0] = -1 ("no orientation estimate"), as the message asks.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from imu_emulator.errors import ImuEmulatorError
from imu_emulator.output.atomic import AtomicOutput, FinishOnExit, output_error
from imu_emulator.output.base import Contents, Format
from imu_emulator.runtime.samples import SampleBlock

_SEP = "=" * 80
_MSG_TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
_MSG_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
_MSG_QUAT = "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
_MSG_VEC = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
_MSG_POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"


def _definition(main: str, *deps: str) -> str:
    """A ROS 2 message definition as MCAP's ros2msg schema encoding wants it: the type, then every type it
    uses, each after a separator line."""
    return main + "".join(f"{_SEP}\n{d}" for d in deps)


IMU_DEFINITION = _definition(
    "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n"
    "geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n"
    "geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n",
    _MSG_HEADER, _MSG_TIME, _MSG_QUAT, _MSG_VEC)

ODOMETRY_DEFINITION = _definition(
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
    "geometry_msgs/TwistWithCovariance twist\n",
    _MSG_HEADER, _MSG_TIME,
    "MSG: geometry_msgs/PoseWithCovariance\ngeometry_msgs/Pose pose\nfloat64[36] covariance\n",
    "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    _MSG_POINT, _MSG_QUAT,
    "MSG: geometry_msgs/TwistWithCovariance\ngeometry_msgs/Twist twist\nfloat64[36] covariance\n",
    "MSG: geometry_msgs/Twist\ngeometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n", _MSG_VEC)


NAVSATFIX_DEFINITION = _definition(
    "std_msgs/Header header\nsensor_msgs/NavSatStatus status\nfloat64 latitude\nfloat64 longitude\n"
    "float64 altitude\nfloat64[9] position_covariance\nuint8 position_covariance_type\n",
    _MSG_HEADER, _MSG_TIME, "MSG: sensor_msgs/NavSatStatus\nint8 status\nuint16 service\n")
_COVARIANCE_TYPE_KNOWN = 3


def _stamps(ns) -> list[dict]:
    return [{"sec": int(t // 1_000_000_000), "nanosec": int(t % 1_000_000_000)} for t in ns]


def ros_name(name: str) -> str:
    """A ROS graph-name token from an IMU name: letters, digits and underscores, not starting with a digit."""
    token = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return token if token and not token[0].isdigit() else f"imu_{token}"


class McapWriter(FinishOnExit):
    """Like every output writer (imu_emulator.output.base.Writer), the bag appears at its path only once it is
    complete."""

    def __init__(self, path: str | Path, imu_names, truth: bool, covariances: dict | None = None,
                 earth_frame: str | None = None, attitude_reference: str = "local_level", effects=()):
        """earth_frame: the scene's frame when the truth carries the Earth keys (imu_emulator.motion.earth_truth);
        ENU's bodies are forward-left-up. attitude_reference and effects: the scene's, which say what the
        truth's body rate is relative to (_to_earth_rate)."""
        try:
            from mcap_ros2.writer import Writer
        except ImportError:
            raise ImuEmulatorError("writing .mcap needs mcap-ros2-support: pip install 'imu-emulator[logs]'") from None
        self.path = Path(path)
        self.imu_names = list(imu_names)
        self.truth = truth
        topics = [f"/imu/{ros_name(n)}" for n in self.imu_names]
        if len(set(topics)) != len(topics):
            raise ImuEmulatorError(f"{self.path}: IMU names {self.imu_names} give the same ROS topic twice")
        self.topics = topics
        self.covariances = covariances or {}
        self._out = AtomicOutput(self.path, "wb")
        self._file = self._out.file
        self._writer = Writer(self._file)
        self._imu_schema = self._writer.register_msgdef("sensor_msgs/msg/Imu", IMU_DEFINITION)
        self._odom_schema = self._writer.register_msgdef("nav_msgs/msg/Odometry", ODOMETRY_DEFINITION) if truth else None
        self.earth_frame = earth_frame if truth else None
        self.attitude_reference, self.effects = attitude_reference, frozenset(effects)
        self._fix_schema = (self._writer.register_msgdef("sensor_msgs/msg/NavSatFix", NAVSATFIX_DEFINITION)
                            if self.earth_frame else None)

    def _covariance(self, name: str, which: int) -> list[float]:
        variance = self.covariances.get(name)
        if variance is None:
            return [0.0] * 9
        return [float(x) for x in np.diag(np.broadcast_to(variance[which], 3)).ravel()]

    def write(self, block: SampleBlock) -> None:
        scene_ns = block.time_ns()
        for m, (name, topic) in enumerate(zip(self.imu_names, self.topics)):
            ns = scene_ns + block.imu_offset_ns(m)         # [[imu]] time_offset_s
            stamps = _stamps(ns)
            gyro_cov, acc_cov = self._covariance(name, 0), self._covariance(name, 1)
            no_orientation = [-1.0] + [0.0] * 8
            for j, stamp in enumerate(stamps):
                w, a = block.gyro[m, j], block.accel[m, j]
                if block.quat is not None:
                    q = block.quat[m, j]
                    orientation = {"x": float(q[1]), "y": float(q[2]), "z": float(q[3]), "w": float(q[0])}
                    orientation_cov = [0.0] * 9
                else:
                    orientation, orientation_cov = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}, no_orientation
                self._writer.write_message(topic, self._imu_schema, {
                    "header": {"stamp": stamp, "frame_id": ros_name(name)},
                    "orientation": orientation, "orientation_covariance": orientation_cov,
                    "angular_velocity": {"x": float(w[0]), "y": float(w[1]), "z": float(w[2])},
                    "angular_velocity_covariance": gyro_cov,
                    "linear_acceleration": {"x": float(a[0]), "y": float(a[1]), "z": float(a[2])},
                    "linear_acceleration_covariance": acc_cov}, log_time=int(ns[j]), publish_time=int(ns[j]))
        if self.truth:
            self._write_truth(block, scene_ns, _stamps(scene_ns))
        if self.earth_frame:
            self._write_earth_truth(block, scene_ns, _stamps(scene_ns))

    def _write_truth(self, block: SampleBlock, ns, stamps) -> None:
        from imu_emulator.geo.rotations import euler_to_matrix, matrix_to_quat
        tr = block.truth
        R = euler_to_matrix(tr["euler"])
        q = matrix_to_quat(R)
        v_body = np.einsum("nji,nj->ni", R, tr["velocity"])      # R^T v: twist is in the child (body) frame
        zeros36 = [0.0] * 36
        for j, stamp in enumerate(stamps):
            p, w = tr["position"][j], tr["omega_body"][j]
            self._writer.write_message("/truth/odometry", self._odom_schema, {
                "header": {"stamp": stamp, "frame_id": "world"}, "child_frame_id": "base_link",
                "pose": {"pose": {"position": {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])},
                                  "orientation": {"x": float(q[j, 1]), "y": float(q[j, 2]), "z": float(q[j, 3]),
                                                  "w": float(q[j, 0])}},
                         "covariance": zeros36},
                "twist": {"twist": {"linear": dict(zip("xyz", map(float, v_body[j]))),
                                    "angular": dict(zip("xyz", map(float, w)))},
                          "covariance": zeros36}}, log_time=int(ns[j]), publish_time=int(ns[j]))

    def _write_earth_truth(self, block: SampleBlock, ns, stamps) -> None:
        from imu_emulator.geo import frames
        from imu_emulator.geo.rotations import matrix_to_quat
        tr = block.truth
        llh, r_e, v_e = tr["geodetic"], tr["position_ecef"], tr["velocity_ecef"]
        c_eb = np.einsum("nji,njk->nik", frames.ned_from_ecef_matrix(llh[:, 0], llh[:, 1]),
                         frames.dcm_from_euler_zyx(tr["euler_ned"]))          # C_b^e = C_n^e C_b^n
        q = matrix_to_quat(np.ascontiguousarray(c_eb))
        v_b = np.einsum("nji,nj->ni", c_eb, v_e)
        w = tr["omega_body"] @ (frames.FRD_FROM_FLU if self.earth_frame == "ENU" else np.eye(3)).T   # to FRD
        w_eb = w + np.einsum("nji,nj->ni", frames.dcm_from_euler_zyx(tr["euler_ned"]), self._to_earth_rate(tr))
        zeros9, zeros36 = [0.0] * 9, [0.0] * 36
        for j, stamp in enumerate(stamps):
            self._writer.write_message("/truth/navsatfix", self._fix_schema, {
                "header": {"stamp": stamp, "frame_id": "earth"}, "status": {"status": 0, "service": 0},
                "latitude": float(llh[j, 0]), "longitude": float(llh[j, 1]), "altitude": float(llh[j, 2]),
                "position_covariance": zeros9, "position_covariance_type": _COVARIANCE_TYPE_KNOWN},
                log_time=int(ns[j]), publish_time=int(ns[j]))
            self._writer.write_message("/truth/odometry_ecef", self._odom_schema, {
                "header": {"stamp": stamp, "frame_id": "earth"}, "child_frame_id": "base_link_frd",
                "pose": {"pose": {"position": dict(zip("xyz", map(float, r_e[j]))),
                                  "orientation": {"x": float(q[j, 1]), "y": float(q[j, 2]), "z": float(q[j, 3]),
                                                  "w": float(q[j, 0])}},
                         "covariance": zeros36},
                "twist": {"twist": {"linear": dict(zip("xyz", map(float, v_b[j]))),
                                    "angular": dict(zip("xyz", map(float, w_eb[j])))},
                          "covariance": zeros36}}, log_time=int(ns[j]), publish_time=int(ns[j]))

    def _to_earth_rate(self, tr) -> np.ndarray:
        """What to add (in local NED) to the kernel's body rate w to get omega_eb. w is the rate w.r.t. the
        attitude's reference X less u, the part of X's rate that the named Earth effects add back
        (motion.earth.reference_lines): X = local level turns at rho = omega_en over the Earth, ECEF not at
        all, ECI at -omega_ie; u holds rho with coriolis and, for ECI, omega_ie with earth_rate."""
        rho, w_ie = tr["transport_rate_ned"], tr["earth_rate_ned"]
        if self.attitude_reference == "local_level":
            return rho
        added = rho if "coriolis" in self.effects else np.zeros_like(rho)
        if self.attitude_reference == "ECI":
            added = added + (w_ie if "earth_rate" in self.effects else 0.0) - w_ie
        return added

    def close(self) -> None:
        try:
            self._writer.finish()
        except OSError as exc:
            self._out.discard()
            raise output_error(self.path, exc) from None
        self._out.close()

    def discard(self) -> None:
        self._out.discard()


def open_bag(path: Path, contents: Contents) -> McapWriter:
    """The bag of a run: no temperature, no increments (sensor_msgs/Imu has no field for them); the Earth truth
    when the contents carry it, whose body rate needs the scene's attitude reference and effects."""
    return McapWriter(path, contents.imu_names, contents.layout.truth, contents.covariances,
                      earth_frame=contents.frame if contents.layout.earth else None,
                      attitude_reference=contents.attitude_reference, effects=contents.effects)


# A message record (opcode 1 + length 8 + channel 2 + sequence 4 + log and publish time 16) and its message
# index entry (time 8 + offset 8); CDR: a 4-byte encapsulation header, strings as a uint32 length, the bytes
# and a NUL, doubles aligned to 8 from the header's end.
_MCAP_RECORD = 31 + 16


def _cdr_string_end(at: int, text: str) -> int:
    return at + 4 + len(text.encode()) + 1


def _align8(at: int) -> int:
    return -(-at // 8) * 8


def _imu_cdr_bytes(name: str) -> int:
    end = _cdr_string_end(8, ros_name(name))               # stamp, then frame_id
    return 4 + _align8(end) + 8 * (4 + 9 + 3 + 9 + 3 + 9)


_ODOMETRY_CDR = 4 + _align8(_cdr_string_end(_cdr_string_end(8, "world"), "base_link")) + 8 * (7 + 36 + 6 + 36)
_ODOMETRY_ECEF_CDR = 4 + _align8(_cdr_string_end(_cdr_string_end(8, "earth"), "base_link_frd")) + 8 * (7 + 36 + 6 + 36)
_NAVSATFIX_CDR = 4 + _align8(_cdr_string_end(8, "earth") + 1 + 2) + 8 * (3 + 9) + 1


def estimated_bytes(scene, truth: bool, increments: bool = False) -> int:
    """The messages of a run: one Imu per IMU per sample, with truth an Odometry, on the Earth a NavSatFix and
    an ECEF Odometry per sample (increments are not written)."""
    from imu_emulator.output.columns import scene_layout
    n = scene.n_samples
    earth = truth and scene_layout(scene, truth).earth
    return n * sum(_MCAP_RECORD + _imu_cdr_bytes(name) for name in scene.imu_names) + (
        n * (_MCAP_RECORD + _ODOMETRY_CDR) if truth else 0) + (
        n * (2 * _MCAP_RECORD + _ODOMETRY_ECEF_CDR + _NAVSATFIX_CDR) if earth else 0)


def carried(layout) -> tuple[str, ...]:
    """The schema's columns a bag holds as they are: each IMU's signals, the truth's position (the rest of the
    truth is there in other frames or forms: a quaternion, the twist in the body frame)."""
    from imu_emulator.output.columns import SAMPLES, TRUTH
    return SAMPLES.names + (TRUTH.names[:3] if layout.truth else ())


def read_columns(path: Path, names: tuple[str, ...]) -> dict | None:
    """`carried` columns and "t" (the IMU messages' stamps, s) and "imu" (the topics' names), rows IMU-fastest."""
    try:
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory
    except ImportError:
        raise ImuEmulatorError("reading .mcap needs mcap-ros2-support: pip install 'imu-emulator[logs]'") from None
    topics: dict[str, list] = {}
    with open(path, "rb") as f:
        for _, channel, _, ros_msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            topics.setdefault(channel.topic, []).append(ros_msg)
    imus = [topic for topic in topics if topic.startswith("/imu/")]     # in the IMUs' order: written first-to-last
    n = min((len(topics[topic]) for topic in imus), default=0)

    def rows(per_imu):                  # (n_imu, n) -> (n * n_imu,), IMU fastest
        return np.asarray(per_imu, dtype=np.float64).T.ravel()

    columns = {"t": rows([[m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in topics[t][:n]] for t in imus]),
               "imu": np.tile(np.array([t[len("/imu/"):] for t in imus], dtype=object), n)}
    for prefix, field in (("a", "linear_acceleration"), ("g", "angular_velocity")):
        for axis in "xyz":
            columns[prefix + axis] = rows([[getattr(getattr(m, field), axis) for m in topics[t][:n]] for t in imus])
    if "/truth/odometry" in topics:
        position = [m.pose.pose.position for m in topics["/truth/odometry"][:n]]
        for axis in "xyz":
            columns["p" + axis] = np.repeat([getattr(p, axis) for p in position], len(imus)).astype(np.float64)
    return {name: columns[name] for name in names} if set(names) <= set(columns) else None


FORMAT = Format("MCAP", (".mcap",), open_bag, estimated_bytes, order=30, margin=(0.1, 1.0),
                description="a ROS 2 bag's sensor_msgs/Imu", increments=False, attitude=True, columns=carried,
                read_columns=read_columns)
