"""Samples as a ROS 2 bag in MCAP (`-o run.mcap`), in the axes and frames REP 103 and REP 105 ask for whatever the
scene's frame (imu_emulator.output.ros2.conventions): bodies forward-left-up, the world ENU; `--ros-axes scene`
keeps the scene's and names the frames for it (`<imu>_frd`, `base_link_frd`, `world_ned`).

Topics: `/imu/<name>` sensor_msgs/msg/Imu per IMU (frame_id the IMU's name); `/tf_static` (tf2_msgs/TFMessage,
latched: transient-local QoS) with one transform base_link -> <imu> per IMU, its lever arm and mounting (identity
where the scene's lever_arm or mounting effect is off, as the samples then carry none); with truth
`/truth/odometry` nav_msgs/msg/Odometry (frame_id "world", ENU; child "base_link"; twist in the body, REP 147);
on the Earth `/truth/navsatfix` (WGS-84 degrees and ellipsoidal height; STATUS_FIX, COVARIANCE_TYPE_KNOWN with
zeros: the truth has no error) and `/truth/odometry_ecef` (frame_id "earth", ECEF; twist the Earth-referenced
velocity and the body's rate w.r.t. the Earth, omega_eb). Companion sensors, when the run has their columns:
`/imu/<name>/mag` sensor_msgs/MagneticField (tesla, the IMU's frame) and `/imu/<name>/pressure`
sensor_msgs/FluidPressure (Pa), one per new reading (mag_new, baro_new: at the sensor's own rate, as a driver
publishes them; every sample for a run without those columns), `/imu/<name>/fix` sensor_msgs/NavSatFix of the GNSS receiver, one per new
solution (gnss_new), STATUS_NO_FIX or STATUS_FIX from gnss_fix, SERVICE_GPS, a diagonal covariance from its
1-sigma accuracies (COVARIANCE_TYPE_DIAGONAL_KNOWN; UNKNOWN without them). Shared (not per IMU) companion
columns go to `/mag`, `/pressure`, `/gnss/fix` in base_link.

Stamps: start + t (conventions: `--start-time`, default 2024-01-01T00:00:00Z; never 0), header stamp = log time
= publish time. A metadata record "imu_emulator" states the scene's digest, seed, versions, the start, the frame
conversion and the Earth conventions.

Covariances: per IMU (gyro and accelerometer variance per axis) on the diagonal when a noise model supplies them
(effects.noise.variances), else all zeros, which sensor_msgs/Imu defines as "covariance unknown".
Orientation: the sensor frame's attitude when the simulation provides it, else orientation_covariance[0] = -1.

Written a block at a time (output.ros2.bag: whole blocks of messages serialized as numpy rows, zstd chunks), no
mcap-ros2-support needed to write; read back (`plot`, `replay`) with mcap and mcap-ros2-support.
Size: the uncompressed bytes of the message records and their index entries; the file is compressed and comes
out smaller, 0.1-0.7 of it.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from imu_emulator.errors import ImuEmulatorError
from imu_emulator.output.atomic import AtomicOutput, FinishOnExit, output_error
from imu_emulator.output.base import Contents, Format
from imu_emulator.output.run_record import run_metadata
from imu_emulator.runtime.samples import SampleBlock

METADATA_NAME = "imu_emulator"
GAUSS_TO_TESLA = 1e-4
#: rosbag2's QoS for a latched topic (transient local, keep all): `ros2 bag play` republishes /tf_static so
TF_STATIC_QOS = ("- history: 3\n  depth: 0\n  reliability: 1\n  durability: 1\n  deadline:\n    sec: 2147483647\n"
                 "    nsec: 4294967295\n  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n  liveliness: 1\n"
                 "  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n"
                 "  avoid_ros_namespace_conventions: false\n")
#: the companion columns (written by the effects that make them; names shared with the other formats)
MAG, PRESSURE = ("mag_x", "mag_y", "mag_z"), "pressure_pa"
MAG_NEW, BARO_NEW = "mag_new", "baro_new"
GNSS = ("gnss_lat_deg", "gnss_lon_deg", "gnss_h_m")
GNSS_FIX, GNSS_NEW = "gnss_fix", "gnss_new"
GNSS_ACCURACY = ("gnss_horizontal_accuracy_m", "gnss_vertical_accuracy_m")


def ros_name(name: str) -> str:
    """A ROS graph-name token from an IMU name: letters, digits and underscores, not starting with a digit."""
    token = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return token if token and not token[0].isdigit() else f"imu_{token}"


def _stamp(rows, ns: np.ndarray) -> None:
    rows["sec"], rows["nanosec"] = ns // 1_000_000_000, ns % 1_000_000_000
    rows["log_time"] = rows["publish_time"] = ns


class McapWriter(FinishOnExit):
    """Like every output writer (imu_emulator.output.base.Writer), the bag appears at its path only once it is
    complete. Channels are declared with the first block (whether it carries attitudes and which companion
    columns decides them)."""

    def __init__(self, path: str | Path, contents: Contents):
        from imu_emulator.output.ros2.bag import BagFile
        from imu_emulator.output.ros2.conventions import DEFAULT_START_NS, axes_for
        self.path = Path(path)
        self.contents = contents
        self.imu_names = list(contents.imu_names)
        self.tokens = [ros_name(n) for n in self.imu_names]
        if len(set(self.tokens)) != len(self.tokens):
            raise ImuEmulatorError(f"{self.path}: IMU names {self.imu_names} give the same ROS topic twice")
        self.layout = contents.layout
        self.truth = contents.layout.truth
        self.earth = contents.layout.earth
        self.axes = axes_for(contents.frame, contents.ros_axes)
        self.earth_axes = axes_for("ECEF", contents.ros_axes)      # the Earth truth's body is FRD, its world ECEF
        self.start_ns = DEFAULT_START_NS if contents.start_ns is None else int(contents.start_ns)
        self.covariances = contents.covariances or {}
        self._out = AtomicOutput(self.path, "wb")
        self._bag = BagFile(self._out.file, library="imu-emulator")
        self._bag.metadata(METADATA_NAME, self._metadata())
        self._dense = self._sparse = None

    def _metadata(self) -> dict[str, str]:
        from imu_emulator.output.ros2.conventions import DEFAULT_START
        values = {key: value if isinstance(value, str) else json.dumps(value, sort_keys=True)
                  for key, value in (self.contents.metadata or {}).items()}
        values.update(start_ns=str(self.start_ns), default_start=DEFAULT_START, axes=self.contents.ros_axes,
                      scene_frame=self.contents.frame or "ENU",
                      frames=f"bodies and IMUs {'FLU' if self.axes.suffix == '' else 'the scene body axes'}, "
                             f"world {self.axes.world_id} (REP 103/105 unless axes = scene); stamps = start_ns + "
                             "scene time")
        if self.contents.conventions:
            values["conventions"] = "\n".join(self.contents.conventions)
        return values

    # -- channels -------------------------------------------------------------------------------------------
    def _declare(self, block: SampleBlock) -> None:
        from imu_emulator.output.columns import named_columns
        from imu_emulator.output.ros2 import messages as msg
        bag, axes = self._bag, self.axes
        columns = named_columns(block, self.layout) if len(block) else {}
        self._tf_static(block)
        orientation_cov = [0.0] * 9 if block.quat is not None else [-1.0] + [0.0] * 8
        self._imus = []
        for name, token in zip(self.imu_names, self.tokens):
            gyro_cov, acc_cov = self._covariance(name, 0), self._covariance(name, 1)
            self._imus.append(bag.channel(f"/imu/{token}", msg.IMU, msg.DEFINITIONS[msg.IMU],
                                          msg.imu(axes.imu_frame(token), orientation_cov, gyro_cov, acc_cov)))
        self._odometry = (bag.channel("/truth/odometry", msg.ODOMETRY, msg.DEFINITIONS[msg.ODOMETRY],
                                      msg.odometry(axes.world_id, axes.base_link)) if self.truth else None)
        if self.earth:
            self._fix_truth = bag.channel("/truth/navsatfix", msg.NAVSATFIX, msg.DEFINITIONS[msg.NAVSATFIX],
                                          msg.navsatfix_truth("earth"))
            self._odometry_ecef = bag.channel("/truth/odometry_ecef", msg.ODOMETRY, msg.DEFINITIONS[msg.ODOMETRY],
                                              msg.odometry("earth", self.earth_axes.base_link))
        # companions: per IMU -> a topic per IMU, shared -> one topic in base_link
        # a reading per new one where the run says which are new (mag_new, baro_new), as a driver publishes
        # them; every sample where it does not (dense, with the IMU messages)
        self._companions = []
        for kind, names, new, topic, schema, layout in (
                ("mag", MAG, MAG_NEW, "mag", msg.MAGNETIC_FIELD, msg.magnetic_field),
                ("pressure", (PRESSURE,), BARO_NEW, "pressure", msg.FLUID_PRESSURE, msg.fluid_pressure)):
            if all(n in columns for n in names):
                self._companions.append((kind, names, new if new in columns else None, self._companion_channels(
                    columns[names[0]][0], topic, schema, layout)))
        self._gnss = None
        if all(n in columns for n in GNSS + (GNSS_NEW,)):
            accuracy = all(n in columns for n in GNSS_ACCURACY)
            kind = msg.COVARIANCE_TYPE_DIAGONAL_KNOWN if accuracy else msg.COVARIANCE_TYPE_UNKNOWN
            self._gnss = (accuracy, self._companion_channels(
                columns[GNSS[0]][0], "fix", msg.NAVSATFIX, lambda frame: msg.navsatfix_measured(frame, kind),
                shared_topic="/gnss/fix"))
        self._dense = self._imus + ([self._odometry] if self._odometry else []) + (
            [self._fix_truth, self._odometry_ecef] if self.earth else []) + [
            c for _, _, new, channels in self._companions if new is None for c in channels]

    def _companion_channels(self, per_imu: bool, topic: str, schema: str, layout, shared_topic: str | None = None):
        from imu_emulator.output.ros2.messages import DEFINITIONS
        if per_imu:
            return [self._bag.channel(f"/imu/{token}/{topic}", schema, DEFINITIONS[schema],
                                      layout(self.axes.imu_frame(token))) for token in self.tokens]
        return [self._bag.channel(shared_topic or f"/{topic}", schema, DEFINITIONS[schema],
                                  layout(self.axes.base_link))]

    def _covariance(self, name: str, which: int) -> list[float]:
        variance = self.covariances.get(name)
        if variance is None:
            return [0.0] * 9
        return [float(x) for x in np.diag(np.broadcast_to(variance[which], 3)).ravel()]

    def _tf_static(self, block: SampleBlock) -> None:
        """One latched TFMessage at the first sample: base_link -> each IMU, translation the lever arm and
        rotation the mounting (sensor -> body), in the bag's body axes."""
        from imu_emulator.geo.rotations import matrix_to_quat
        from imu_emulator.output.ros2 import messages as msg
        frames = [self.axes.imu_frame(token) for token in self.tokens]
        channel = self._bag.channel("/tf_static", msg.TF_MESSAGE, msg.DEFINITIONS[msg.TF_MESSAGE],
                                    msg.tf_message(self.axes.base_link, frames),
                                    metadata={"offered_qos_profiles": TF_STATIC_QOS})
        placements = self.contents.placements or [(np.zeros(3), np.eye(3))] * len(frames)
        rows = self._bag.rows([channel], 1)
        r = rows[f"c{channel.id}"]
        ns = self.start_ns + (int(block.time_ns()[0]) if len(block) else 0)
        self._check_stamps(np.array([ns]))
        r["log_time"] = r["publish_time"] = ns
        for i, (lever_arm, mounting) in enumerate(placements):
            r[f"sec{i}"], r[f"nanosec{i}"] = divmod(ns, 1_000_000_000)
            r[f"translation{i}"] = self.axes.body_vectors(np.asarray(lever_arm, float))
            q = matrix_to_quat(np.ascontiguousarray(self.axes.rotation(np.asarray(mounting, float))))
            r[f"rotation{i}"] = np.roll(q, -1)                     # x, y, z, w
        self._bag.write_rows(rows)

    def _check_stamps(self, ns: np.ndarray) -> None:
        if len(ns) and (ns.min() < 0 or ns.max() >= 2**31 * 10**9):
            raise ImuEmulatorError(f"{self.path}: time stamps fall outside 1970-01-01 .. 2038-01-19 (ROS time's "
                                   "int32 seconds): choose another --start-time")

    # -- blocks ---------------------------------------------------------------------------------------------
    def write(self, block: SampleBlock) -> None:
        if self._dense is None:
            self._declare(block)
        n = len(block)
        if n == 0:
            return
        axes = self.axes
        scene_ns = block.time_ns() + np.int64(self.start_ns)
        self._check_stamps(scene_ns)
        rows = self._bag.rows(self._dense, n)
        imu_ns = []
        for m, channel in enumerate(self._imus):
            r = rows[f"c{channel.id}"]
            ns = scene_ns + np.int64(block.imu_offset_ns(m))        # [[imu]] time_offset_s
            self._check_stamps(ns)
            imu_ns.append(ns)
            _stamp(r, ns)
            r["angular_velocity"] = axes.body_vectors(block.gyro[m])
            r["linear_acceleration"] = axes.body_vectors(block.accel[m])
            r["orientation"] = axes.quaternions(block.quat[m]) if block.quat is not None else (0.0, 0.0, 0.0, 1.0)
        if self._odometry is not None:
            self._write_truth(rows[f"c{self._odometry.id}"], block, scene_ns)
        if self.earth:
            self._write_earth_truth(rows, block, scene_ns)
        self._write_companions(rows, block, scene_ns, imu_ns)
        self._bag.write_rows(rows)
        if self._gnss is not None:
            self._write_fixes(block, scene_ns, imu_ns)

    def _write_truth(self, r, block: SampleBlock, ns) -> None:
        from imu_emulator.geo.rotations import euler_to_matrix, matrix_to_quat
        tr, axes = block.truth, self.axes
        R = euler_to_matrix(tr["euler"])
        _stamp(r, ns)
        r["position"] = axes.world_vectors(tr["position"])
        r["orientation"] = axes.quaternions(matrix_to_quat(R))
        r["linear"] = axes.body_vectors(np.einsum("nji,nj->ni", R, tr["velocity"]))     # R^T v: in the body
        r["angular"] = axes.body_vectors(tr["omega_body"])

    def _write_earth_truth(self, rows, block: SampleBlock, ns) -> None:
        from imu_emulator.geo import frames
        from imu_emulator.geo.rotations import matrix_to_quat
        tr = block.truth
        llh, r_e, v_e = tr["geodetic"], tr["position_ecef"], tr["velocity_ecef"]
        c_eb = np.einsum("nji,njk->nik", frames.ned_from_ecef_matrix(llh[:, 0], llh[:, 1]),
                         frames.dcm_from_euler_zyx(tr["euler_ned"]))          # C_b^e = C_n^e C_b^n, body FRD
        v_b = np.einsum("nji,nj->ni", c_eb, v_e)
        w = tr["omega_body"] @ (frames.FRD_FROM_FLU if self.contents.frame == "ENU" else np.eye(3)).T   # to FRD
        w_eb = w + np.einsum("nji,nj->ni", frames.dcm_from_euler_zyx(tr["euler_ned"]), self._to_earth_rate(tr))
        fix = rows[f"c{self._fix_truth.id}"]
        _stamp(fix, ns)
        fix["position"] = llh
        odom = rows[f"c{self._odometry_ecef.id}"]
        _stamp(odom, ns)
        odom["position"] = r_e
        odom["orientation"] = self.earth_axes.quaternions(matrix_to_quat(np.ascontiguousarray(c_eb)))
        odom["linear"] = self.earth_axes.body_vectors(v_b)
        odom["angular"] = self.earth_axes.body_vectors(w_eb)

    def _to_earth_rate(self, tr) -> np.ndarray:
        """What to add (in local NED) to the kernel's body rate w to get omega_eb. w is the rate w.r.t. the
        attitude's reference X less u, the part of X's rate that the named Earth effects add back
        (motion.earth.reference_lines): X = local level turns at rho = omega_en over the Earth, ECEF not at
        all, ECI at -omega_ie; u holds rho with coriolis and, for ECI, omega_ie with earth_rate."""
        rho, w_ie = tr["transport_rate_ned"], tr["earth_rate_ned"]
        effects = self.contents.effects
        if self.contents.attitude_reference == "local_level":
            return rho
        added = rho if "coriolis" in effects else np.zeros_like(rho)
        if self.contents.attitude_reference == "ECI":
            added = added + (w_ie if "earth_rate" in effects else 0.0) - w_ie
        return added

    def _write_companions(self, rows, block: SampleBlock, scene_ns, imu_ns) -> None:
        """MagneticField and FluidPressure: in the dense rows (every sample), or sparse rows of their own at
        each new reading."""
        from imu_emulator.output.columns import named_columns
        if not self._companions:
            return
        columns = named_columns(block, self.layout)
        for kind, names, new, channels in self._companions:
            for m, channel, take, at, stamps in self._readings(columns, names[0], new, channels, scene_ns, imu_ns):
                if new is None:
                    r = rows[f"c{channel.id}"]
                else:
                    sparse = self._bag.rows([channel], len(at), keep=False)
                    r = sparse[f"c{channel.id}"]
                _stamp(r, stamps)
                values = [take(n)[at] for n in names]
                if kind == "mag":       # gauss in the sensor frame -> tesla in the bag's IMU axes
                    r["magnetic_field"] = self.axes.body_vectors(np.stack(values, axis=-1) * GAUSS_TO_TESLA)
                else:
                    r["fluid_pressure"] = values[0]
                if new is not None:
                    self._bag.write_rows(sparse)

    @staticmethod
    def _readings(columns, first: str, new: str | None, channels, scene_ns, imu_ns):
        """Per channel with something to write: (m, channel, take(column) -> its values, the samples to write,
        their stamps). A companion column is per IMU (one channel each) or shared (one channel); `new` names the
        column flagging new readings (None: every sample)."""
        per_imu = columns[first][0]
        for m, channel in enumerate(channels):
            def take(name, m=m):
                return columns[name][1][m] if per_imu else columns[name][1]
            at = slice(None) if new is None else np.flatnonzero(take(new) != 0)
            if new is not None and not len(at):
                continue
            yield m, channel, take, at, (imu_ns[m] if per_imu else scene_ns)[at]

    def _write_fixes(self, block: SampleBlock, scene_ns, imu_ns) -> None:
        """A NavSatFix per new receiver solution (gnss_new), sparse: rows of their own."""
        from imu_emulator.output.columns import named_columns
        from imu_emulator.output.ros2.messages import STATUS_FIX, STATUS_NO_FIX
        columns = named_columns(block, self.layout)
        accuracy, channels = self._gnss
        for m, channel, take, new, stamps in self._readings(columns, GNSS[0], GNSS_NEW, channels, scene_ns, imu_ns):
            rows = self._bag.rows([channel], len(new), keep=False)
            r = rows[f"c{channel.id}"]
            _stamp(r, stamps)
            r["status"] = np.where(take(GNSS_FIX)[new] >= 2, STATUS_FIX, STATUS_NO_FIX)
            r["position"] = np.stack([take(n)[new] for n in GNSS], axis=-1)
            if accuracy:
                h, v = (take(n)[new] ** 2 for n in GNSS_ACCURACY)
                covariance = np.zeros((len(new), 9))
                covariance[:, 0] = covariance[:, 4] = h
                covariance[:, 8] = v
                r["position_covariance"] = covariance
            self._bag.write_rows(rows)

    def close(self) -> None:
        try:
            if self._dense is None:
                self._declare(_empty_block(len(self.imu_names)))
            self._bag.finish()
        except OSError as exc:
            self._out.discard()
            raise output_error(self.path, exc) from None
        except BaseException:
            self._out.discard()
            raise
        self._out.close()

    def discard(self) -> None:
        self._out.discard()


def _empty_block(n_imu: int) -> SampleBlock:
    return SampleBlock(k0=0, t_s=np.zeros(0), accel=np.zeros((n_imu, 0, 3)), gyro=np.zeros((n_imu, 0, 3)), quat=None)


def open_bag(path: Path, contents: Contents) -> McapWriter:
    """The bag of a run: no temperature, no increments (sensor_msgs/Imu has no field for them)."""
    return McapWriter(path, contents)


def placements(scene) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each IMU's lever arm (m) and mounting rotation (sensor -> body) in the scene's body axes, as the samples
    carry them: zero and identity where the lever_arm or mounting effect is off."""
    from imu_emulator.geo.rotations import euler_to_matrix
    found = []
    for imu in scene.imus:
        lever = np.asarray(imu.lever_arm_m, float) if "lever_arm" in scene.effects else np.zeros(3)
        mounting = (euler_to_matrix(np.radians(np.asarray(imu.mounting_rpy_deg, float)))
                    if "mounting" in scene.effects else np.eye(3))
        found.append((lever, mounting))
    return found


# sizes: a message record's header and its message index entry (time 8 + offset 8)
_MCAP_RECORD = 31 + 16


def estimated_bytes(scene, truth: bool, increments: bool = False) -> int:
    """The messages of a run: one Imu per IMU per sample, with truth an Odometry, on the Earth a NavSatFix and
    an ECEF Odometry per sample (increments are not written)."""
    from imu_emulator.output.columns import scene_layout
    from imu_emulator.output.ros2 import messages as msg
    n = scene.n_samples
    earth = truth and scene_layout(scene, truth).earth
    zeros = [0.0] * 9
    imu = sum(_MCAP_RECORD + msg.imu(ros_name(name) + "_frd", zeros, zeros, zeros).size for name in scene.imu_names)
    odometry = _MCAP_RECORD + msg.odometry("world_ned", "base_link_frd").size
    return n * imu + (n * odometry if truth else 0) + (
        n * (2 * _MCAP_RECORD + msg.odometry("earth", "base_link_frd").size + msg.navsatfix_truth("earth").size)
        if earth else 0)


def carried(layout) -> tuple[str, ...]:
    """The schema's columns a bag holds as they are: each IMU's signals, the truth's position (the rest of the
    truth is there in other frames or forms: a quaternion, the twist in the body frame)."""
    from imu_emulator.output.columns import SAMPLES, TRUTH
    return SAMPLES.names + (TRUTH.names[:3] if layout.truth else ())


def read_metadata(path: str | Path) -> dict[str, str]:
    """The bag's "imu_emulator" metadata record ({} when it has none)."""
    from mcap.reader import make_reader
    with open(path, "rb") as f:
        for record in make_reader(f).iter_metadata():
            if record.name == METADATA_NAME:
                return dict(record.metadata)
    return {}


def read_columns(path: Path, names: tuple[str, ...]) -> dict | None:
    """`carried` columns in the scene's frames (the bag's axes turned back, exactly: they are permutations and
    sign changes), "t" (the IMU messages' stamps less the start: s on the scene's time base) and "imu" (the
    topics' names), rows IMU-fastest."""
    try:
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory
    except ImportError:
        raise ImuEmulatorError("reading .mcap needs mcap-ros2-support: pip install 'imu-emulator[logs]'") from None
    from imu_emulator.output.ros2.conventions import axes_for, turn
    meta = read_metadata(path)
    axes = axes_for(meta.get("scene_frame"), meta.get("axes", "rep103"))
    start_ns = int(meta.get("start_ns", 0))
    topics: dict[str, list] = {}
    with open(path, "rb") as f:
        for _, channel, _, ros_msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            topics.setdefault(channel.topic, []).append(ros_msg)
    imus = [topic for topic in topics if re.fullmatch(r"/imu/[^/]+", topic)]   # written first-to-last
    n = min((len(topics[topic]) for topic in imus), default=0)

    def rows(per_imu, dtype=np.float64):     # (n_imu, n[, 3]) -> (n * n_imu[, 3]), IMU fastest
        a = np.asarray(per_imu, dtype=dtype)
        return np.swapaxes(a, 0, 1).reshape((-1,) + a.shape[2:])

    stamps = rows([[m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in topics[t][:n]] for t in imus],
                  np.int64)      # Unix ns need 61 bits: subtract the start before they become doubles
    columns = {"t": (stamps - start_ns) / np.float64(1e9),
               "imu": np.tile(np.array([t[len("/imu/"):] for t in imus], dtype=object), n)}
    for prefix, field in (("a", "linear_acceleration"), ("g", "angular_velocity")):
        values = rows([[[getattr(getattr(m, field), axis) for axis in "xyz"] for m in topics[t][:n]] for t in imus])
        values = turn(axes.body.T, values.reshape(-1, 3))     # orthogonal: body^T turns the bag's back
        for i, axis in enumerate("xyz"):
            columns[prefix + axis] = values[:, i]
    if "/truth/odometry" in topics:
        position = np.array([[m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z]
                             for m in topics["/truth/odometry"][:n]])
        position = turn(axes.world.T, position)
        for i, axis in enumerate("xyz"):
            columns["p" + axis] = np.repeat(position[:, i], len(imus)).astype(np.float64)
    return {name: columns[name] for name in names} if set(names) <= set(columns) else None


FORMAT = Format("MCAP", (".mcap",), open_bag, estimated_bytes, order=30, margin=(0.1, 1.0),
                description="a ROS 2 bag's sensor_msgs/Imu", increments=False, attitude=True, columns=carried,
                read_columns=read_columns, run_metadata=run_metadata)
