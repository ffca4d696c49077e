"""What every wire format shares: the sample block it encodes, saturation counting, frame containers.

firmware_protocols knows nothing of scenes or kernels. An encoder takes a `Samples` block (SI units,
sensor frame, time as integer nanoseconds on whatever time base the caller declares) and returns
bytes (serial formats) or an array of CAN frames (CAN formats). Wire units live only in the format
modules.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable

import numpy as np


class EncodeError(ValueError):
    """Input an encoder refuses (non-finite value, missing field); the message names field and sample."""


@dataclass
class Samples:
    """A block of n IMU samples in SI units, sensor frame.

    time_ns:        (n,) int64, UTC nanoseconds since the Unix epoch: the run's start (`--start-time`) + scene time.
                    GNSS/UTC fields derive from it through firmware_protocols.gnss_time (GPS = UTC + leap s).
    start_ns:       int, the run's start on time_ns's base (default 0). Formats whose wire time counts since the
                    unit's start (MAVLink IMU time_usec / time_boot_ms) send time_ns - start_ns; each says which.
    accel:          (n, 3) specific force, m/s^2
    gyro:           (n, 3) angular rate, rad/s
    mag:            (n, 3) magnetic field, gauss                    (optional)
    quat:           (n, 4) attitude sensor->NED, scalar FIRST (w, x, y, z)   (optional; the wire formats'
                    convention; a format declaring another reference frame converts at its edge)
    euler:          (n, 3) roll, pitch, yaw in rad (z-y-x) of the same attitude   (optional)
    temperature_c:  (n,) degrees Celsius                            (optional)
    pressure_pa:    (n,) static pressure, pascal                    (optional)
    delta_theta:    (n, 3) integrated rate over the sample period, rad      (optional)
    delta_velocity: (n, 3) integrated specific force over the period, m/s   (optional)
    delta_time_s:   (n,) the period the two above span, s (the sensor's own clock)  (optional)
    attitude_change: (n, 4) the sensor's exact attitude change over the period, q(t_k-1)^-1 (x) q(t_k), coning
                    included (attitude.attitude_change); formats carrying a delta quaternion use it, else the
                    rotation by delta_theta  (optional)
    position_llh:   (n, 3) geodetic latitude, longitude (deg), height above the WGS-84 ellipsoid (m)  (optional)
    velocity_ned:   (n, 3) velocity north, east, down, m/s                  (optional)
    linear_accel_ned: (n, 3) acceleration without gravity, north, east, down, m/s^2  (optional)
    position_llh, velocity_ned, quat, euler are the unit's own estimate when the scene names one (truth plus its
    errors), else the truth. Its uncertainties and status:
    attitude_sigma_rad: (n, 3) roll, pitch, yaw 1-sigma, rad                   (optional)
    position_sigma_m:   (n, 3) north, east, down 1-sigma, m                    (optional)
    velocity_sigma_mps: (n, 3) north, east, down 1-sigma, m/s                  (optional)
    ins_mode:       (n,) 0 not tracking, 1 aligning, 2 tracking (healthy)      (optional)
    differential_pressure_pa: (n,) pitot minus static pressure, pascal          (optional)
    The GNSS receiver's measurement, as the receiver last reported it (held between fixes):
    gnss_llh:       (n, 3) antenna latitude, longitude (deg), height above the ellipsoid (m)   (optional)
    gnss_velocity_ned: (n, 3) antenna velocity north, east, down, m/s           (optional)
    gnss_fix:       (n,) 0 no fix, 2 2D, 3 3D                                   (optional)
    gnss_satellites: (n,) satellites used                                       (optional)
    gnss_hdop, gnss_vdop: (n,) dilutions of precision                           (optional)
    gnss_horizontal_accuracy_m, gnss_vertical_accuracy_m, gnss_speed_accuracy_mps: (n,) 1-sigma   (optional)
    gnss_new:       (n,) 1 where a new solution became available at this sample, else 0   (optional)
    gnss_age_s:     (n,) time since the solution's time of validity (latency + hold), s   (optional)
    mag_new, baro_new: (n,) 1 where the magnetometer's / barometer's reading is new at this sample (its own rate;
                    mag, pressure_pa, differential_pressure_pa and the barometer's temperature hold between them),
                    else 0; None: every sample is new (firmware_protocols.update_rate)   (optional)
    Vectors (accel, gyro, mag, delta_theta, delta_velocity) are in the part's own body axes forward-right-down
    (FRD) as it sits upright facing forward; quat/euler rotate FRD -> NED. A format whose manual declares
    other axes converts at its edge.
    Formats that need an optional field which is None use a documented default (usually zeros,
    identity quaternion, 25 degC, 101325 Pa) rather than failing.
    """

    time_ns: np.ndarray
    accel: np.ndarray
    gyro: np.ndarray
    mag: np.ndarray | None = None
    quat: np.ndarray | None = None
    euler: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    pressure_pa: np.ndarray | None = None
    delta_theta: np.ndarray | None = None
    delta_velocity: np.ndarray | None = None
    delta_time_s: np.ndarray | None = None
    attitude_change: np.ndarray | None = None
    position_llh: np.ndarray | None = None
    velocity_ned: np.ndarray | None = None
    linear_accel_ned: np.ndarray | None = None
    attitude_sigma_rad: np.ndarray | None = None
    position_sigma_m: np.ndarray | None = None
    velocity_sigma_mps: np.ndarray | None = None
    ins_mode: np.ndarray | None = None
    differential_pressure_pa: np.ndarray | None = None
    gnss_llh: np.ndarray | None = None
    gnss_velocity_ned: np.ndarray | None = None
    gnss_fix: np.ndarray | None = None
    gnss_satellites: np.ndarray | None = None
    gnss_hdop: np.ndarray | None = None
    gnss_vdop: np.ndarray | None = None
    gnss_horizontal_accuracy_m: np.ndarray | None = None
    gnss_vertical_accuracy_m: np.ndarray | None = None
    gnss_speed_accuracy_mps: np.ndarray | None = None
    gnss_new: np.ndarray | None = None
    gnss_age_s: np.ndarray | None = None
    mag_new: np.ndarray | None = None
    baro_new: np.ndarray | None = None
    start_ns: int = 0

    def __post_init__(self):
        self.time_ns = np.ascontiguousarray(self.time_ns, dtype=np.int64).reshape(-1)
        n = self.time_ns.shape[0]
        for name, width in _FIELD_WIDTHS.items():
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.ascontiguousarray(value, dtype=np.float64)
            arr = arr.reshape(n) if width == 0 else arr.reshape(n, width)
            setattr(self, name, arr)

    def __len__(self) -> int:
        return int(self.time_ns.shape[0])

    @classmethod
    def single(cls, time_ns: int, accel, gyro, **optional) -> "Samples":
        """One sample, for the live path: scalars/3-vectors in, a block of one out."""
        wrapped = {k: (None if v is None else np.asarray(v, dtype=np.float64)[None, ...]) for k, v in optional.items()}
        return cls(np.array([time_ns], dtype=np.int64), np.asarray(accel, float)[None, :],
                   np.asarray(gyro, float)[None, :], **wrapped)

    def slice(self, start: int, stop: int) -> "Samples":
        kw = {name: (None if getattr(self, name) is None else getattr(self, name)[start:stop])
              for name in _FIELD_WIDTHS}
        return Samples(self.time_ns[start:stop], **kw, start_ns=self.start_ns)

    def rows(self, index: np.ndarray) -> "Samples":
        """The samples at `index` (an integer array), as a block of their own: what an encoder that sends only
        at some samples (a GNSS message on each new solution) packs."""
        kw = {name: (None if getattr(self, name) is None else getattr(self, name)[index]) for name in _FIELD_WIDTHS}
        return Samples(self.time_ns[index], **kw, start_ns=self.start_ns)

    def field_or(self, name: str, default) -> np.ndarray:
        """The named field, or `default` broadcast to the block's shape."""
        value = getattr(self, name)
        if value is not None:
            return value
        width = _FIELD_WIDTHS[name]
        shape = (len(self),) if width == 0 else (len(self), width)
        return np.broadcast_to(np.asarray(default, dtype=np.float64), shape).copy()

    def require_finite(self, names: Iterable[str], rows: np.ndarray | None = None) -> None:
        """Raise EncodeError naming the first non-finite value among the fields an encoder uses (only in `rows`,
        the samples it sends, when given; the error still names the block's sample number)."""
        for name in names:
            value = getattr(self, name)
            if value is None:
                continue
            bad = ~np.isfinite(value if rows is None else value[rows])
            if bad.any():
                index = np.argwhere(bad)[0]
                sample = index[0] if rows is None else rows[index[0]]
                where = f"sample {sample}" + (f", component {index[1]}" if value.ndim == 2 else "")
                raise EncodeError(f"non-finite value in field '{name}' at {where}")


#: the integrated outputs (an encoder whose fields read them says so with `uses_increments = True`)
INCREMENT_FIELDS = ("delta_theta", "delta_velocity")

_FIELD_WIDTHS = {
    "accel": 3, "gyro": 3, "mag": 3, "quat": 4, "euler": 3,
    "temperature_c": 0, "pressure_pa": 0, "delta_theta": 3, "delta_velocity": 3, "delta_time_s": 0,
    "attitude_change": 4,
    "position_llh": 3, "velocity_ned": 3, "linear_accel_ned": 3,
    "attitude_sigma_rad": 3, "position_sigma_m": 3, "velocity_sigma_mps": 3, "ins_mode": 0,
    "differential_pressure_pa": 0,
    "gnss_llh": 3, "gnss_velocity_ned": 3, "gnss_fix": 0, "gnss_satellites": 0, "gnss_hdop": 0, "gnss_vdop": 0,
    "gnss_horizontal_accuracy_m": 0, "gnss_vertical_accuracy_m": 0, "gnss_speed_accuracy_mps": 0, "gnss_new": 0,
    "gnss_age_s": 0, "mag_new": 0, "baro_new": 0,
}


def integration_intervals(samples: Samples, period_s: float | None, last_time_ns: int | None) -> np.ndarray:
    """(n, 1) the period each sample's increments span, s: Samples.delta_time_s when given, else a fixed
    period, else the time since the previous sample (`last_time_ns`, the previous block's last; 0 for the
    very first sample, which formats define as "no integral")."""
    n = len(samples)
    if samples.delta_time_s is not None:
        return samples.delta_time_s.reshape(n, 1)
    if period_s is not None:
        return np.full((n, 1), period_s)
    interval = np.empty((n, 1))
    if n:
        first = samples.time_ns[0] if last_time_ns is None else last_time_ns
        interval[0, 0] = (samples.time_ns[0] - first) * 1e-9
        if n > 1:       # not for a sample alone (as devices encode): numpy's calls on empty arrays cost 3 µs
            np.multiply(np.diff(samples.time_ns), 1e-9, out=interval[1:, 0])
    return interval


@dataclass
class SaturationStats:
    """How many values per wire field were clipped to the field's range (never wrapped)."""

    counts: dict = field(default_factory=dict)

    def add(self, field_name: str, count: int) -> None:
        if count:
            self.counts[field_name] = self.counts.get(field_name, 0) + int(count)

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def __str__(self) -> str:
        if not self.counts:
            return "none"
        return ", ".join(f"{k}: {v}" for k, v in sorted(self.counts.items()))


def saturate(values: np.ndarray, lo: float, hi: float, field_name: str, stats: SaturationStats) -> np.ndarray:
    """Clip to [lo, hi] (the field's representable range) and count what was clipped."""
    clipped = np.clip(values, lo, hi)
    stats.add(field_name, int(np.count_nonzero((values < lo) | (values > hi))))
    return clipped


def to_int_field(values: np.ndarray, scale: float, offset: float, lo: int, hi: int,
                 field_name: str, stats: SaturationStats, dtype) -> np.ndarray:
    """SI value -> integer wire value: (value - offset) / scale, ROUNDED to nearest, saturated and counted."""
    raw = np.rint((np.asarray(values, dtype=np.float64) - offset) / scale)
    return saturate(raw, lo, hi, field_name, stats).astype(dtype)


def to_float16_field(values: np.ndarray, field_name: str, stats: SaturationStats) -> np.ndarray:
    """SI value -> IEEE half, round to nearest; beyond +-65504 saturates (counted) instead of becoming inf."""
    limit = 65504.0
    return saturate(np.asarray(values, dtype=np.float64), -limit, limit, field_name, stats).astype(np.float16)


def to_float32_field(values: np.ndarray, field_name: str, stats: SaturationStats) -> np.ndarray:
    limit = float(np.finfo(np.float32).max)
    return saturate(np.asarray(values, dtype=np.float64), -limit, limit, field_name, stats).astype(np.float32)


# --- containers for what encoders return ------------------------------------------------------

@dataclass
class SerialBatch:
    """Packets of n samples in one contiguous buffer; packet i is data[offsets[i]:offsets[i+1]].

    A sample may produce more than one packet (e.g. several messages); offsets are per SAMPLE, so the
    live path can write everything belonging to sample i at sample i's deadline.
    """

    data: bytes
    offsets: np.ndarray  # (n + 1,) int64

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def packet(self, i: int) -> bytes:
        return self.data[self.offsets[i]:self.offsets[i + 1]]


def _frame_dtype(data_bytes: int) -> np.dtype:
    return np.dtype([
        ("sample", "<i8"),
        ("can_id", "<u4"),
        ("extended", "?"),
        ("fd", "?"),
        ("length", "u1"),
        ("data", "u1", (data_bytes,)),
    ])


#: One CAN frame per row. `sample` is the index (within the encoded block) of the sample the frame belongs
#: to; `data[:length]` is the payload. Classic-CAN encoders return the 8-byte-data rows (23 bytes a frame,
#: which matters for an hour of 7-frame transfers), CAN FD encoders the 64-byte ones. Consumers index
#: `data[:length]` and so accept either.
CLASSIC_FRAME_DTYPE = _frame_dtype(8)
FD_FRAME_DTYPE = _frame_dtype(64)
CAN_FRAME_DTYPE = FD_FRAME_DTYPE     # wide enough for any frame
FRAME_DTYPES = (CLASSIC_FRAME_DTYPE, FD_FRAME_DTYPE)
#: CAN FD data lengths (ISO 11898-1); a frame's payload is padded up to the next one: FD_LENGTH_TABLE[n].
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
FD_LENGTH_TABLE = np.array([next(L for L in FD_LENGTHS if L >= n) for n in range(65)], dtype=np.int64)


def empty_frames(count: int, fd: bool = False) -> np.ndarray:
    return np.zeros(count, dtype=FD_FRAME_DTYPE if fd else CLASSIC_FRAME_DTYPE)


def frame_bytes(frame) -> bytes:
    """The payload of one row of a CAN_FRAME_DTYPE array."""
    return bytes(frame["data"][: frame["length"]])


# --- decoders --------------------------------------------------------------------------------

@dataclass
class DecoderStats:
    packets: int = 0          # valid packets yielded
    skipped_bytes: int = 0    # bytes discarded while hunting for a sync pattern (serial)
    bad_checksum: int = 0     # candidate packets dropped for a CRC/checksum mismatch
    ignored_frames: int = 0   # CAN frames not belonging to this format, or incomplete transfers


@dataclass
class Packet:
    """A decoded packet: `kind` names the message, `fields` holds values converted back to SI units."""

    kind: str
    fields: dict
    raw: bytes = b""


class CanStreamDecoder:
    """What every CAN decoder shares: rows of a frame array or single frames in, packets out, and never
    an exception (a malformed frame counts in stats.ignored_frames). Subclasses set `self.stats` and
    implement `_feed(can_id, data, extended, fd) -> list[Packet]`."""

    stats: DecoderStats

    def feed_frames(self, frames: np.ndarray) -> list[Packet]:
        out: list[Packet] = []
        for row in frames:
            out.extend(self.feed_frame(int(row["can_id"]), bytes(row["data"][: row["length"]]),
                                       bool(row["extended"]), bool(row["fd"])))
        return out

    def feed_frame(self, can_id: int, data: bytes, extended: bool, fd: bool = False) -> list[Packet]:
        try:
            return self._feed(int(can_id), bytes(data), bool(extended), bool(fd))
        except Exception:                   # a malformed frame must never stop the stream
            self.stats.ignored_frames += 1
            return []


def can_bits_worst_case(length: int, extended: bool, fd: bool = False) -> int:
    """Bits on the bus for one frame with worst-case bit stuffing (classic CAN; CAN FD approximated at
    nominal rate for the whole frame, an upper bound)."""
    if not fd:
        # 11-bit: 44 + 8n bits before stuffing (+ 3 IFS); 29-bit: 64 + 8n. Stuffing adds 1 per 4 of the
        # 34 + 8n (11-bit) or 54 + 8n (29-bit) stuffable bits.
        header = 64 if extended else 44
        stuffable = (54 if extended else 34) + 8 * length
        return header + 8 * length + (stuffable - 1) // 4 + 3
    crc_bits = 17 if length <= 16 else 21
    header = 67 if extended else 47
    stuffable = (header - 20) + 8 * length
    return header + 8 * length + crc_bits + (stuffable - 1) // 4 + 3
