"""ArduPilot SITL's JSON physics backend: the line a simulator sends back for each servo packet.

Transcribed from ArduPilot/ardupilot libraries/SITL/SIM_JSON.cpp (commit 2ebd1127ac11b2a2b02dfabeb9f9e9318170af46)
and SIM_JSON.h (commit 0394cbc9084433e45d6bc2a8c234d6c265931d39). The parser there is not a JSON parser: for
each key of its `keytable` it finds the section with strstr, then the key inside it, skips `key":` (strlen + 2)
and reads the value with atof or with sscanf("[%f, %f, %f]") - so a value must follow the colon with NO space
(json.dumps' default ": " would fail every vector), and vectors are float32 (a value beyond FLT_MAX saturates
here and is counted, rather than arriving as inf). A line is framed by '\\n' on both sides: recv_fdm turns
'\\n' into NUL and parses what lies between the last two NULs, so a first line without a '\\n' before it would
never be read.

Fields (keys and units as SIM_JSON reads them; Samples' conventions are the same, nothing is rotated):

==========================  =================================================================================
timestamp                   s, double: (time_ns - start_ns) / 1e9, the physics time since the run's start
                            (a Unix-epoch double would keep only 0.24 us). SITL's clock advances by its
                            differences (a step back is "physics reset")
imu.gyro                    rad/s, body forward-right-down, float32
imu.accel_body              specific force, m/s^2, body FRD, float32
position                    m north, east, down of the origin (double): SITL adds origin-to-home itself and
                            takes the origin as where it starts, so the origin here is the `origin` option
                            "LAT,LON,HEIGHT" (deg, deg, m above the ellipsoid) or, without it, the first
                            sample's position; NED of the origin's tangent plane (exact, via ECEF)
quaternion                  w, x, y, z rotating body FRD -> NED (Quaternion q1..q4, rotation_matrix), float32
velocity                    m/s north, east, down, float32
==========================  =================================================================================

Without position_llh / velocity_ned (a scene without navigation truth) position and velocity are zeros; without
quat the identity. A non-finite input is an EncodeError naming field and sample.
"""
from __future__ import annotations

import json
import math

import numpy as np

from firmware_protocols.base import DecoderStats, Packet, SaturationStats, Samples, SerialBatch
from firmware_protocols.registry import FormatInfo, register

_FLT_MAX = float(np.finfo(np.float32).max)
_WGS84_A = 6378137.0
_WGS84_E2 = 6.69437999014e-3
# SIM_JSON's receive buffer (sensor_buffer[65000]): a longer line could never be parsed there
MAX_LINE = 65000


def _ecef(llh: np.ndarray) -> np.ndarray:
    lat, lon, h = np.radians(llh[:, 0]), np.radians(llh[:, 1]), llh[:, 2]
    n = _WGS84_A / np.sqrt(1.0 - _WGS84_E2 * np.sin(lat) ** 2)
    return np.stack(((n + h) * np.cos(lat) * np.cos(lon), (n + h) * np.cos(lat) * np.sin(lon),
                     (n * (1.0 - _WGS84_E2) + h) * np.sin(lat)), axis=1)


def ned_of(llh: np.ndarray, origin) -> np.ndarray:
    """(n, 3) north, east, down of geodetic points in the tangent plane at `origin` (lat, lon deg, height m)."""
    origin = np.asarray(origin, dtype=np.float64).reshape(1, 3)
    d = _ecef(np.asarray(llh, dtype=np.float64).reshape(-1, 3)) - _ecef(origin)
    lat, lon = math.radians(origin[0, 0]), math.radians(origin[0, 1])
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    rot = np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])
    return d @ rot.T


def _parse_origin(origin):
    if origin is None:
        return None
    parts = origin.split(",") if isinstance(origin, str) else list(origin)
    try:
        values = [float(p) for p in parts]
    except (TypeError, ValueError):
        values = []
    if len(values) != 3 or not all(map(math.isfinite, values)) or not -90 <= values[0] <= 90:
        raise ValueError(f"origin: expected 'LAT,LON,HEIGHT' (degrees, degrees, metres), got {origin!r}")
    return values


class ArduPilotJsonEncoder:
    """Samples -> one JSON line per sample as SIM_JSON reads it. Stateful: the origin, once taken."""

    uses_navigation = True     # the streamer computes position and velocity for it
    true_physics = True        # SITL's physics backend: the truth, never a unit's own estimate (companion INS)
    body_axes, reference = "FRD", "NED"
    axes_source = "ArduPilot SIM_JSON.cpp/h (2ebd1127): imu.gyro, accel_body body frame; quaternion, velocity NED"

    def __init__(self, origin=None):
        self.origin = _parse_origin(origin)
        self.saturated = SaturationStats()
        self.bytes_per_sample = 512

    def _float32(self, values: np.ndarray, name: str) -> np.ndarray:
        clipped = np.clip(values, -_FLT_MAX, _FLT_MAX)
        self.saturated.add(name, int(np.count_nonzero(clipped != values)))
        return clipped

    def encode(self, samples: Samples) -> SerialBatch:
        n = len(samples)
        samples.require_finite(("accel", "gyro", "quat", "position_llh", "velocity_ned"))
        if samples.position_llh is not None and self.origin is None and n:
            self.origin = samples.position_llh[0].tolist()
        position = (np.zeros((n, 3)) if samples.position_llh is None or self.origin is None
                    else ned_of(samples.position_llh, self.origin))
        gyro = self._float32(samples.gyro, "imu.gyro")
        accel = self._float32(samples.accel, "imu.accel_body")
        quat = samples.field_or("quat", (1.0, 0.0, 0.0, 0.0))
        velocity = self._float32(samples.field_or("velocity_ned", (0.0, 0.0, 0.0)), "velocity")
        times = (samples.time_ns - samples.start_ns) / 1e9     # since the run's start: SITL's physics time
        lines = [line(float(times[i]), gyro[i], accel[i], position[i], quat[i], velocity[i]) for i in range(n)]
        offsets = np.zeros(n + 1, dtype=np.int64)
        offsets[1:] = np.cumsum([len(b) for b in lines])
        return SerialBatch(b"".join(lines), offsets)


def line(timestamp: float, gyro, accel, position, quat, velocity) -> bytes:
    """One reply: '\\n' + compact JSON + '\\n' (keys in SIM_JSON's keytable order; reprs round-trip)."""
    body = {"timestamp": timestamp, "imu": {"gyro": [float(v) for v in gyro], "accel_body": [float(v) for v in accel]},
            "position": [float(v) for v in position], "quaternion": [float(v) for v in quat],
            "velocity": [float(v) for v in velocity]}
    return b"\n" + json.dumps(body, separators=(",", ":")).encode() + b"\n"


class ArduPilotJsonDecoder:
    """Byte stream -> one Packet per complete line that parses as JSON with SIM_JSON's required keys (SI values
    back in Samples' names); anything else is skipped and counted. Linear in its input, never raises."""

    def __init__(self):
        self.stats = DecoderStats()
        self._buf = b""

    def feed(self, chunk) -> list:
        data = self._buf + bytes(chunk)
        *complete, rest = data.split(b"\n")
        if len(rest) > MAX_LINE:           # a line SITL's buffer could not hold either
            self.stats.skipped_bytes += len(rest)
            rest = b""
        self._buf = rest
        packets = []
        for raw in complete:
            if not raw:
                continue
            try:
                obj = json.loads(raw)
                fields = {"time_s": float(obj["timestamp"]), "gyro": obj["imu"]["gyro"],
                          "accel": obj["imu"]["accel_body"], "position_ned": obj["position"],
                          "quat": obj["quaternion"], "velocity_ned": obj["velocity"]}
            except (ValueError, KeyError, TypeError, RecursionError):
                self.stats.skipped_bytes += len(raw) + 1
                continue
            self.stats.packets += 1
            packets.append(Packet("ardupilot-json", fields, raw))
        return packets


register(FormatInfo(
    name="ardupilot-json", kind="serial",
    description="ArduPilot SITL JSON backend reply (SIM_JSON): timestamp, imu.gyro/accel_body, position, "
                "quaternion, velocity; for the ardupilot-json target",
    encoder=ArduPilotJsonEncoder, decoder=ArduPilotJsonDecoder, bytes_per_sample=512,
    options={"origin": "'LAT,LON,HEIGHT' the position's NED origin = SITL's home (None: the first sample's)"}))
