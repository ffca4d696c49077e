"""ArduPilot DataFlash logs (`.bin`), read with pymavlink's DFReader.

Attitude (FRD body -> NED), first present by default: the EKF's quaternion (`XKQ` core 0, `XKQ1`, `NKQ1`:
Q1..Q4 = w, x, y, z), `AHR2` (Q1..Q4), `ATT` (Roll, Pitch, Yaw in degrees, z-y-x: turned into quaternions
here, exactly: no Euler angle is differentiated). Position, NED metres: the EKF's `XKF1`/`NKF1` (PN, PE, PD
relative to the EKF origin `ORGN`, with VN, VE, VD), else `POS` (Lat, Lng, Alt) converted to NED about the
origin (`ORGN`, else the first POS) with pymap3d. Recorded IMU: `IMU` (GyrX..Z rad/s, AccX..Z m/s^2, FRD).
Stamps: TimeUS (microseconds since boot). Messages that carry an instance field (`C` for EKF cores, `I` for
IMUs in newer firmware) are filtered on it: "XKF1:1" is core 1; "IMU:1" the second IMU.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imu_emulator.errors import DataError
from imu_emulator.scene.logs import LogMotion, RecordedImu, require, series, split_source

ATTITUDE_DEFAULTS = ("XKQ", "XKQ1", "NKQ1", "AHR2", "ATT")
POSITION_DEFAULTS = ("XKF1", "NKF1", "POS")
QUATERNION_FIELDS = ("Q1", "Q2", "Q3", "Q4")
INSTANCE_FIELDS = ("C", "I")


def _read(path: Path, types) -> tuple[dict[str, list], dict[str, list[str]]]:
    """Every message of the given types as dicts, and the columns of every type the log declares."""
    DFReader = require("pymavlink.DFReader", "ArduPilot DataFlash logs")
    try:
        reader = DFReader.DFReader_binary(str(path))
        columns = {f.name: list(f.columns) for f in reader.formats.values()}
        messages: dict[str, list] = {t: [] for t in types}
        while True:
            m = reader.recv_match(type=list(types))
            if m is None:
                break
            messages[m.get_type()].append(m.to_dict())
    except DataError:
        raise
    except Exception as exc:         # DFReader raises assorted errors on damaged files
        raise DataError(f"{path.name}: not a readable DataFlash log ({exc})") from None
    return messages, columns


def _pick(source, defaults, messages, columns, path: Path, what: str) -> tuple[str, int | None]:
    """The source asked for, or the first default the log has messages of."""
    if source is not None:
        name, instance = split_source(source, "")
        if name not in columns:
            raise DataError(f"{path.name}: no message type {name!r} in this log")
        return name, instance
    for name in defaults:
        if messages.get(name):
            return name, None
    raise DataError(f"{path.name}: no {what} in this log (looked for {', '.join(defaults)})")


def _rows(messages, name, instance, columns, path: Path) -> list[dict]:
    rows = messages[name]
    field = next((f for f in INSTANCE_FIELDS if f in columns[name]), None)
    if field is not None:
        rows = [r for r in rows if r[field] == (instance or 0)]
    elif instance:
        raise DataError(f"{path.name}: {name} has no instance field; drop ':{instance}'")
    if not rows:
        raise DataError(f"{path.name}: no {name} messages" + (f" for instance {instance}" if instance else ""))
    return rows


def _column(rows, *names) -> np.ndarray:
    return np.array([[r[n] for n in names] for r in rows], dtype=float)


def _label(name, instance):
    return name if instance is None else f"{name}:{instance}"


def read_motion(path: Path, position_source=None, attitude_source=None) -> LogMotion:
    wanted = {"ORGN", *ATTITUDE_DEFAULTS, *POSITION_DEFAULTS}
    for source in (attitude_source, position_source):
        if source is not None:
            wanted.add(split_source(source, "")[0])
    messages, columns = _read(path, wanted)       # one pass over the log
    att_name, att_inst = _pick(attitude_source, ATTITUDE_DEFAULTS, messages, columns, path, "attitude")
    pos_name, pos_inst = _pick(position_source, POSITION_DEFAULTS, messages, columns, path, "position")
    notes = []

    rows = _rows(messages, att_name, att_inst, columns, path)
    t = _column(rows, "TimeUS")[:, 0]
    if all(f in columns[att_name] for f in QUATERNION_FIELDS):
        quat = _column(rows, *QUATERNION_FIELDS)
    elif all(f in columns[att_name] for f in ("Roll", "Pitch", "Yaw")):
        from imu_emulator.geo.rotations import euler_to_quat
        quat = euler_to_quat(np.radians(_column(rows, "Roll", "Pitch", "Yaw")))
    else:
        raise DataError(f"{path.name}: {att_name} holds neither Q1..Q4 nor Roll, Pitch, Yaw")
    attitude, note = series(_label(att_name, att_inst), path.name, t, quat, 1e-6)
    notes.append(note)

    rows = _rows(messages, pos_name, pos_inst, columns, path)
    t = _column(rows, "TimeUS")[:, 0]
    origin = None
    velocity = None
    origins = [r for r in messages.get("ORGN", []) if r.get("Type", 0) == 0] or messages.get("ORGN", [])
    if origins:
        o = origins[-1]
        origin = (float(o["Lat"]), float(o["Lng"]), float(o["Alt"]))
    if all(f in columns[pos_name] for f in ("PN", "PE", "PD")):
        ned = _column(rows, "PN", "PE", "PD")
        if all(f in columns[pos_name] for f in ("VN", "VE", "VD")):
            velocity, _ = series(_label(pos_name, pos_inst), path.name, t, _column(rows, "VN", "VE", "VD"), 1e-6)
    elif all(f in columns[pos_name] for f in ("Lat", "Lng", "Alt")):
        pymap3d = require("pymap3d", "positions given as latitude and longitude")
        lla = _column(rows, "Lat", "Lng", "Alt")
        if origin is None:
            origin = tuple(float(v) for v in lla[0])
            notes.append(f"{pos_name}: no ORGN message; NED about the first {pos_name} fix")
        ned = np.column_stack(pymap3d.geodetic2ned(lla[:, 0], lla[:, 1], lla[:, 2], *origin))
    else:
        raise DataError(f"{path.name}: {pos_name} holds neither PN, PE, PD nor Lat, Lng, Alt")
    position, note = series(_label(pos_name, pos_inst), path.name, t, ned, 1e-6)
    notes.append(note)
    return LogMotion(source=path, frame="NED", position=position, attitude=attitude, velocity=velocity,
                     origin_lla=origin, notes=tuple(n for n in notes if n))


def read_imu(path: Path, source=None) -> RecordedImu | None:
    name, instance = split_source(source, "IMU")
    messages, columns = _read(path, {name})
    if name not in columns:
        if source is None:
            return None
        raise DataError(f"{path.name}: no message type {name!r} in this log")
    rows = _rows(messages, name, instance, columns, path)
    t = _column(rows, "TimeUS")[:, 0] * 1e-6
    keep = np.concatenate([[True], np.diff(t) > 0])
    return RecordedImu(_label(name, instance), t[keep], _column(rows, "GyrX", "GyrY", "GyrZ")[keep],
                       _column(rows, "AccX", "AccY", "AccZ")[keep])
