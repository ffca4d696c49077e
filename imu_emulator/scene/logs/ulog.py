"""PX4 ULog, read with pyulog.

Motion: `vehicle_local_position` (x, y, z and vx, vy, vz: NED, metres, relative to the reference point
ref_lat/ref_lon/ref_alt when the estimator has one) and `vehicle_attitude` (q[0..3]: scalar first, FRD body
-> NED). Recorded IMU: `sensor_combined` (gyro_rad[0..2] at `timestamp`, accelerometer_m_s2[0..2] at
`timestamp + accelerometer_timestamp_relative`, FRD body). Stamps are microseconds since boot; where a topic
has `timestamp_sample` (the time the data refers to, newer PX4) that is used instead of `timestamp` (the
time it was published).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imu_emulator.errors import DataError
from imu_emulator.scene.logs import LogMotion, RecordedImu, require, series, split_source

POSITION = "vehicle_local_position"
ATTITUDE = "vehicle_attitude"
IMU = "sensor_combined"


def _open(path: Path, topics):
    pyulog = require("pyulog", "PX4 ULog files")
    try:
        return pyulog.ULog(str(path), message_name_filter_list=sorted(set(topics)))
    except Exception as exc:        # pyulog raises bare Exceptions and struct errors on damaged files
        raise DataError(f"{path.name}: not a readable ULog file ({exc})") from None


def _dataset(ulog, path: Path, source: str | None, default: str):
    name, instance = split_source(source, default)
    found = [d for d in ulog.data_list if d.name == name]
    if not found:
        topics = sorted({d.name for d in ulog.data_list})
        raise DataError(f"{path.name}: no topic {name!r} in this log (it has {', '.join(topics) or 'none'})")
    chosen = [d for d in found if d.multi_id == (instance or 0)]
    if not chosen:
        raise DataError(f"{path.name}: topic {name!r} has instances {sorted(d.multi_id for d in found)}, "
                        f"not {instance}")
    label = name if instance is None else f"{name}:{instance}"
    return label, chosen[0].data


def _fields(data, label: str, path: Path, names):
    missing = [n for n in names if n not in data]
    if missing:
        raise DataError(f"{path.name}: {label} has no field {missing[0]!r}")
    return np.column_stack([np.asarray(data[n], dtype=float) for n in names])


def _stamps(data) -> np.ndarray:
    return data["timestamp_sample"] if "timestamp_sample" in data else data["timestamp"]


def read_motion(path: Path, position_source=None, attitude_source=None) -> LogMotion:
    pos_name = split_source(position_source, POSITION)[0]
    att_name = split_source(attitude_source, ATTITUDE)[0]
    ulog = _open(path, [pos_name, att_name])
    notes = []
    label, lp = _dataset(ulog, path, position_source, POSITION)
    position, note = series(label, path.name, _stamps(lp), _fields(lp, label, path, ("x", "y", "z")), 1e-6)
    notes.append(note)
    velocity = None
    if all(k in lp for k in ("vx", "vy", "vz")):
        velocity, _ = series(label, path.name, _stamps(lp), _fields(lp, label, path, ("vx", "vy", "vz")), 1e-6)
    origin = None
    if all(k in lp for k in ("ref_lat", "ref_lon", "ref_alt")):
        # the last reference: the estimator may set it after start; (0, 0, 0) means it never did
        ref = (float(lp["ref_lat"][-1]), float(lp["ref_lon"][-1]), float(lp["ref_alt"][-1]))
        if any(ref[:2]):
            origin = ref
            if len({tuple(r) for r in zip(lp["ref_lat"], lp["ref_lon"], lp["ref_alt"])}) > 1:
                notes.append(f"{label}: the reference point changed during the log; the last one is reported")
    label, va = _dataset(ulog, path, attitude_source, ATTITUDE)
    attitude, note = series(label, path.name, _stamps(va), _fields(va, label, path, [f"q[{i}]" for i in range(4)]),
                            1e-6)
    notes.append(note)
    return LogMotion(source=path, frame="NED", position=position, attitude=attitude, velocity=velocity,
                     origin_lla=origin, notes=tuple(n for n in notes if n))


def read_imu(path: Path, source=None) -> RecordedImu | None:
    name = split_source(source, IMU)[0]
    ulog = _open(path, [name])
    if not any(d.name == name for d in ulog.data_list):
        if source is None:
            return None
    label, sc = _dataset(ulog, path, source, IMU)
    t = np.asarray(sc["timestamp"], dtype=np.float64) * 1e-6
    gyro = _fields(sc, label, path, [f"gyro_rad[{i}]" for i in range(3)])
    accel = _fields(sc, label, path, [f"accelerometer_m_s2[{i}]" for i in range(3)])
    if "accelerometer_timestamp_relative" in sc:
        # the accelerometer sample's own time; PX4 marks "no accel in this message" with INT32_MIN
        rel = np.asarray(sc["accelerometer_timestamp_relative"], dtype=np.float64)
        t_acc = t + np.where(rel > -2**31, rel, 0.0) * 1e-6
        accel = np.column_stack([np.interp(t, t_acc, accel[:, i]) for i in range(3)])
    keep = np.concatenate([[True], np.diff(t) > 0])
    return RecordedImu(label, t[keep], gyro[keep], accel[keep])
