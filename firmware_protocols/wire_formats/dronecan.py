"""DroneCAN (UAVCAN v0) messages of the `uavcan.equipment.ahrs` namespace on classic CAN and CAN FD.

Messages (DSDL as shipped with pydronecan 1.0.27, dronecan/dsdl_specs/uavcan/equipment/ahrs/):

- 1003 RawIMU, signature 0x8280632C40E574B5:
  uint56 timestamp µs | float32 integration_interval | float16[3] rate_gyro_latest (rad/s) |
  float32[3] rate_gyro_integral (rad) | float16[3] accelerometer_latest (m/s²) |
  float32[3] accelerometer_integral (m/s) | float16[<=36] covariance (sent empty)
  = 47 bytes on classic CAN (7 frames), 48 on FD (one 64-byte frame).
- 1000 Solution, signature 0x72A63A3C6F41FA9B:
  uint56 timestamp | float16[4] orientation_xyzw | void4 | float16[<=9] orientation_covariance |
  float16[3] angular_velocity | void4 | float16[<=9] angular_velocity_covariance |
  float16[3] linear_acceleration | float16[<=9] linear_acceleration_covariance
  (no void4 before the last array in this revision). Covariances sent empty: 29 bytes classic (5 frames),
  30 bytes FD (one 32-byte frame).
- 1002 MagneticFieldStrength2, signature 0xB6AC0C442430297E:
  uint8 sensor_id | float16[3] magnetic_field_ga | float16[<=9] magnetic_field_covariance (empty)
  = 7 bytes classic (single frame), 8 bytes FD (one 12-byte frame).

Axes are passed through unchanged: the DSDL defines the body frame as forward-right-down, so the caller
hands a sensor frame in those axes (the NED scene setting); the spec's common sample (z = -9.80665 at rest)
is already in it.

Wire-level choices, each matching pydronecan (the oracle):
- Empty covariance arrays. On classic CAN the last array uses the tail array optimisation (no length
  prefix, hence 47 bytes); on CAN FD pydronecan packs with tao=False, so every dynamic array carries its
  length prefix (one zero byte here), and the FD frame is padded with zeros before the tail byte up to
  the next valid FD data length (pydronecan Transfer.to_frames / datalength_roundup).
- float16 conversion is libuavcan's (transcribed by pydronecan as f16_from_f32): round the value to
  float32, then to half with ties away from zero. It differs from IEEE round-half-even only on exact
  ties, and it is what real DroneCAN nodes put on the bus. Magnitudes beyond 65504 saturate to ±65504 and
  are counted (libuavcan would send inf).
- The timestamp (uavcan.Timestamp, the node's own clock: no time sync is emulated) counts since the run's
  start, floor((time_ns - start_ns) / 1000) µs; negative times saturate to 0 (counted). int64 nanoseconds
  never reach 2^56 µs, so the DSDL's `truncated` (wrapping) cast never applies.

Integrals (RawIMU): integration_interval is Samples.delta_time_s when given (the emulator's streams give
the nominal sample period with the increments), else `sample_period_s`, else the time since the previous
sample of this stream (remembered across encode calls). The first sample of a stream without a known period
gets interval 0, which the DSDL defines as "integrals not available". rate_gyro_integral /
accelerometer_integral are Samples.delta_theta / delta_velocity when the block has them (the emulator's
streams always do: imu_emulator.codegen.increments), otherwise latest × interval (the rate held constant over the
period: what a caller without increments gets).
"""
from __future__ import annotations

import math

from imu_emulator.native.lazy import jit
import numpy as np

from firmware_protocols.base import (CLASSIC_FRAME_DTYPE, FD_FRAME_DTYPE, FD_LENGTH_TABLE, CanStreamDecoder,
                                     DecoderStats, EncodeError, Packet, SaturationStats, Samples, empty_frames,
                                     integration_intervals)
from firmware_protocols.crc import crc16_ccitt, crc16_ccitt_bytes
from firmware_protocols.frame_rows import DATA_AT, frame_bytes, put_header
from firmware_protocols.registry import FormatInfo, register

FLOAT16_MAX = 65504.0
FLOAT32_MAX = float(np.finfo(np.float32).max)

# Serialisation program: rows of (opcode, source, column, saturation counter). All fields of these
# messages are byte-aligned once the empty arrays' void4 + length nibbles are folded into zero bytes.
OP_TIMESTAMP = 0            # uint56 µs from time_ns
OP_F16 = 1                  # float16 from sources[source][:, column]
OP_F32 = 2                  # float32 from sources[source][:, column]
OP_U8 = 3                   # the constant byte `column` (sensor_id, void4 + array length nibbles)
OP_F32_TIMES_INTERVAL = 4   # float32 of sources[source][:, column] * integration interval (sources[0])
_OP_WIDTH = {OP_TIMESTAMP: 7, OP_F16: 2, OP_F32: 4, OP_U8: 1, OP_F32_TIMES_INTERVAL: 4}


# --- numba kernels -----------------------------------------------------------------------------

@jit(cache=True, nogil=True, inline="always")
def _f16_from_f32_bits(u):
    """libuavcan's float -> half (pydronecan f16_from_f32) on float32 bits: ties away from zero.

    Inputs are finite and already clipped to +-65504, so the infinity branch of the original is absent.
    """
    sign = (u >> 16) & 0x8000
    u &= 0x7FFFFFFF
    if u >= (113 << 23):                    # >= 2^-14: a normal half; rebias the exponent, add the round bit
        return sign | (((u - (112 << 23)) + 0x1000) >> 13)
    e32 = u >> 23
    if e32 == 0:                            # float32 denormals are far below the smallest half
        return sign
    # Half subnormal: libuavcan drops the low 12 significand bits, lets the float32 multiply by 2^-112
    # round to nearest even on the float32 denormal grid, then adds the half rounding bias.
    st = ((u & 0x7FFFFF) | 0x800000) & ~0xFFF
    shift = 113 - e32
    if shift >= 40:
        return sign
    q = st >> shift
    rem = st & ((1 << shift) - 1)
    half = 1 << (shift - 1)
    if rem > half or (rem == half and (q & 1)):
        q += 1
    return sign | ((q + 0x1000) >> 13)


@jit(cache=True, nogil=True)
def _encode_transfers(time_ns, sources, ops, params, counts, frame_rows):
    """Serialise every sample per the op program and cut it into DroneCAN frames, written straight into
    the frames' bytes (frame_rows.rows: plain arrays, so that a warm run calls this as machine code).

    sources: tuple of (n, w) float64 arrays (RawIMU: sources[0][:, 0] is the integration interval).
    ops rows: (opcode, source, column, saturation counter).
    params: payload_len, signature_crc, can_id, fd, first transfer id, frames per transfer.
    counts (per wire field) are zeroed here and hold this call's saturations on return.
    Returns (frames written, failing sample, failing op, saturations); failing sample is -1 on success.
    """
    counts[:] = 0
    n = time_ns.shape[0]
    length = params[0]
    sig_crc = params[1]
    can_id = params[2]
    fd = params[3] != 0
    tid = params[4]
    per_transfer = params[5]
    mtu = 63 if fd else 7
    multi = length > mtu
    # stream = transfer CRC (2 bytes, little-endian, multi-frame only) + payload
    stream = np.zeros(length + 2, dtype=np.uint8)
    start = 2 if multi else 0
    scratch = np.zeros(1, dtype=np.float32)
    scratch_bits = scratch.view(np.uint32)
    fi = 0
    for k in range(n):
        pos = start
        for o in range(ops.shape[0]):
            code = ops[o, 0]
            if code == OP_TIMESTAMP:
                us = time_ns[k] // 1000     # int64 ns stays below 2^56 µs: only the low end can clip
                if us < 0:
                    us = 0
                    counts[ops[o, 3]] += 1
                for b in range(7):
                    stream[pos + b] = (us >> (8 * b)) & 0xFF
                pos += 7
                continue
            if code == OP_U8:
                stream[pos] = ops[o, 2]
                pos += 1
                continue
            v = sources[ops[o, 1]][k, ops[o, 2]]
            if code == OP_F32_TIMES_INTERVAL:
                v *= sources[0][k, 0]
            if not math.isfinite(v):
                return fi, k, o, 0
            limit = FLOAT16_MAX if code == OP_F16 else FLOAT32_MAX
            if v > limit:
                v = limit
                counts[ops[o, 3]] += 1
            elif v < -limit:
                v = -limit
                counts[ops[o, 3]] += 1
            scratch[0] = v
            bits = np.int64(scratch_bits[0])
            if code == OP_F16:
                bits = _f16_from_f32_bits(bits)
                stream[pos] = bits & 0xFF
                stream[pos + 1] = bits >> 8
                pos += 2
            else:
                stream[pos] = bits & 0xFF
                stream[pos + 1] = (bits >> 8) & 0xFF
                stream[pos + 2] = (bits >> 16) & 0xFF
                stream[pos + 3] = bits >> 24
                pos += 4
        tail_id = (tid + k) & 0x1F
        if not multi:
            # Single-frame transfer: no transfer CRC; FD pads with zeros up to a valid data length.
            total = FD_LENGTH_TABLE[length + 1] if fd else length + 1
            for b in range(length):
                frame_rows[fi, DATA_AT + b] = stream[b]
            for b in range(length, total - 1):
                frame_rows[fi, DATA_AT + b] = 0
            frame_rows[fi, DATA_AT + total - 1] = 0xC0 | tail_id
            put_header(frame_rows, fi, k, can_id, 1, fd, total)
            fi += 1
            continue
        crc = crc16_ccitt(stream, 2, length + 2, sig_crc)
        stream[0] = crc & 0xFF
        stream[1] = crc >> 8
        stream_len = length + 2
        toggle = 0
        j = 0
        for f in range(per_transfer):
            chunk = min(stream_len - j, mtu)
            for b in range(chunk):
                frame_rows[fi, DATA_AT + b] = stream[j + b]
            tail = tail_id | toggle
            if f == 0:
                tail |= 0x80
            if f == per_transfer - 1:
                tail |= 0x40
            frame_rows[fi, DATA_AT + chunk] = tail
            put_header(frame_rows, fi, k, can_id, 1, fd, chunk + 1)
            toggle ^= 0x20
            j += chunk
            fi += 1
    return fi, -1, -1, counts.sum()


# --- message descriptions -----------------------------------------------------------------------

class _Message:
    """A DSDL message as a serialisation program over named sources (Samples fields)."""

    def __init__(self, name, dtid, signature, ops, sources, counters, tail_array=True):
        self.name = name
        self.dtid = dtid
        self.signature = signature
        self.sources = sources              # source index -> Samples field name (for error messages)
        self.counters = counters            # counter index -> wire field name
        self.signature_crc = crc16_ccitt_bytes(signature.to_bytes(8, "little"), 0xFFFF)
        self.ops = np.array(ops, dtype=np.int64).reshape(-1, 4)
        # pydronecan packs FD payloads without the tail array optimisation: a final (empty) array gets
        # its length prefix, one zero byte for every message here that ends in one (`tail_array`).
        self.fd_ops = (np.vstack([self.ops, np.array([[OP_U8, 0, 0, 0]], dtype=np.int64)]) if tail_array
                       else self.ops)
        self.payload_len = {fd: int(sum(_OP_WIDTH[int(c)] for c in self.program(fd)[:, 0])) for fd in (False, True)}

    def program(self, fd: bool) -> np.ndarray:
        return self.fd_ops if fd else self.ops

    def frame_lengths(self, fd: bool) -> tuple:
        """Data lengths of the frames of one transfer."""
        length = self.payload_len[fd]
        if fd:
            if length > 63:
                raise ValueError(f"{self.name}: {length}-byte payload needs a multi-frame FD transfer (unsupported)")
            return (int(FD_LENGTH_TABLE[length + 1]),)
        if length <= 7:
            return (length + 1,)
        full, rest = divmod(length + 2, 7)
        return (8,) * full + ((rest + 1,) if rest else ())


def _vector(opcode, source, counter, columns=(0, 1, 2)):
    return [(opcode, source, c, counter) for c in columns]


def _raw_imu_ops(integrals_given: bool) -> list:
    # sources: 0 interval (n, 1), 1 gyro, 2 accel, 3 delta_theta, 4 delta_velocity
    gyro_int = _vector(OP_F32, 3, 3) if integrals_given else _vector(OP_F32_TIMES_INTERVAL, 1, 3)
    accel_int = _vector(OP_F32, 4, 5) if integrals_given else _vector(OP_F32_TIMES_INTERVAL, 2, 5)
    return ([(OP_TIMESTAMP, 0, 0, 0), (OP_F32, 0, 0, 1)] + _vector(OP_F16, 1, 2) + gyro_int
            + _vector(OP_F16, 2, 4) + accel_int)


_RAW_IMU_ARGS = dict(
    name="uavcan.equipment.ahrs.RawIMU", dtid=1003, signature=0x8280632C40E574B5,
    sources=["integration_interval", "gyro", "accel", "delta_theta", "delta_velocity"],
    counters=["timestamp", "integration_interval", "rate_gyro_latest", "rate_gyro_integral",
              "accelerometer_latest", "accelerometer_integral"],
)
RAW_IMU = _Message(ops=_raw_imu_ops(True), **_RAW_IMU_ARGS)
RAW_IMU_FROM_RATES = _Message(ops=_raw_imu_ops(False), **_RAW_IMU_ARGS)

SOLUTION = _Message(
    "uavcan.equipment.ahrs.Solution", 1000, 0x72A63A3C6F41FA9B,
    # sources: 0 quat (scalar first; the wire wants x, y, z, w), 1 gyro, 2 accel
    [(OP_TIMESTAMP, 0, 0, 0)] + _vector(OP_F16, 0, 1, (1, 2, 3, 0)) + [(OP_U8, 0, 0, 0)]
    + _vector(OP_F16, 1, 2) + [(OP_U8, 0, 0, 0)] + _vector(OP_F16, 2, 3),
    sources=["quat", "gyro", "accel"],
    counters=["timestamp", "orientation_xyzw", "angular_velocity", "linear_acceleration"],
)


def _mag2_message(sensor_id: int) -> _Message:
    return _Message(
        "uavcan.equipment.ahrs.MagneticFieldStrength2", 1002, 0xB6AC0C442430297E,
        [(OP_U8, 0, sensor_id, 0)] + _vector(OP_F16, 0, 0),
        sources=["mag"],
        counters=["magnetic_field_ga"],
    )


MESSAGES_BY_ID = {m.dtid: m for m in (RAW_IMU, SOLUTION, _mag2_message(0))}


def can_id_for(dtid: int, node_id: int, priority: int) -> int:
    """29-bit message frame id: priority(5) | data type id(16) | service_not_message(0) | source node(7)."""
    return (priority & 0x1F) << 24 | (dtid & 0xFFFF) << 8 | (node_id & 0x7F)


def transfer_frames(payload: bytes, signature: int, transfer_id: int, fd: bool = False) -> list:
    """A transfer's frame payloads: single frame up to 7 bytes, else CRC-prefixed (CRC-16/CCITT-FALSE
    seeded with the data type signature) and split in 7-byte chunks, each followed by the tail byte (start 0x80,
    end 0x40, toggle 0x20 alternating from 0, transfer id). CAN FD: one frame up to 63 bytes, zero-padded before
    the tail byte to the next FD data length (longer FD transfers are not built here). For transfers built one at
    a time in Python (node status, service replies, GNSS fixes); the IMU messages go through _encode_transfers."""
    tid = transfer_id & 0x1F
    if fd:
        if len(payload) > 63:
            raise ValueError(f"a {len(payload)}-byte payload needs a multi-frame FD transfer (unsupported)")
        return [payload.ljust(int(FD_LENGTH_TABLE[len(payload) + 1]) - 1, b"\0") + bytes([0xC0 | tid])]
    if len(payload) <= 7:
        return [payload + bytes([0xC0 | tid])]
    crc = crc16_ccitt_bytes(signature.to_bytes(8, "little") + payload, 0xFFFF)
    data = crc.to_bytes(2, "little") + payload
    chunks = [data[k:k + 7] for k in range(0, len(data), 7)]
    frames = []
    for index, chunk in enumerate(chunks):
        tail = (0x80 if index == 0 else 0) | (0x40 if index == len(chunks) - 1 else 0) | (0x20 if index % 2 else 0)
        frames.append(chunk + bytes([tail | tid]))
    return frames


# --- encoders -----------------------------------------------------------------------------------

class _DroneCanEncoder:
    """Shared by the three messages: options, transfer id state, framing and saturation bookkeeping."""
    # Axes: uavcan.equipment.ahrs.RawIMU (dronecan's dsdl_specs, 1003.RawIMU.uavcan): "linear acceleration along X
    # (forward positive) ... Y (right positive) ... Z (down positive)", rates about the same axes; Solution is
    # "Inertial data and orientation in body frame", its orientation w.r.t. NED as the autopilots read it.
    body_axes, reference = "FRD", "NED"
    axes_source = "DSDL 1003.RawIMU: X forward, Y right, Z down positive; Solution: body frame, NED"


    message: _Message

    def __init__(self, node_id: int = 42, priority: int = 31, fd: bool = False, transfer_id: int = 0):
        if not 1 <= int(node_id) <= 127:
            raise ValueError(f"node_id must be 1..127 (0 is anonymous), got {node_id}")
        if not 0 <= int(priority) <= 31:
            raise ValueError(f"priority must be 0..31, got {priority}")
        self.node_id = int(node_id)
        self.priority = int(priority)
        self.fd = bool(fd)
        self.transfer_id = int(transfer_id) & 0x1F
        self.saturated = SaturationStats()
        self.can_id = can_id_for(self.message.dtid, self.node_id, self.priority)
        self._lengths = self.message.frame_lengths(self.fd)
        self._params = np.array([self.message.payload_len[self.fd], self.message.signature_crc, self.can_id,
                                 int(self.fd), 0, len(self._lengths)], dtype=np.int64)
        self._counts = np.zeros(len(self.message.counters), dtype=np.int64)

    @property
    def frames_per_sample(self) -> tuple:
        return tuple((length, True, self.fd) for length in self._lengths)

    def _program(self, samples: Samples) -> tuple[_Message, tuple]:
        """The message variant and its source arrays (all (n, w) float64, C-contiguous) for this block."""
        raise NotImplementedError

    #: the Samples flag of the sensor reading the message carries (a compass or baro message goes out only on the
    #: sensor's new readings, as a node publishes it; every sample when the samples carry no flag)
    new_flag: str | None = None

    def encode(self, samples: Samples) -> np.ndarray:
        flags = None if self.new_flag is None else getattr(samples, self.new_flag)
        if flags is not None:
            samples.require_finite((self.new_flag,))
            due = np.flatnonzero(flags)
            if len(due) < len(samples):
                frames = empty_frames(len(due) * len(self._lengths), fd=self.fd)
                if len(due):
                    self._encode(samples.rows(due), frames)
                    frames["sample"] = due[frames["sample"]]
                return frames
        frames = empty_frames(len(samples) * len(self._lengths), fd=self.fd)
        self._encode(samples, frames)      # frames as encode_into requires them: no checks per sample
        return frames

    def encode_into(self, samples: Samples, frames: np.ndarray) -> int:
        """Encode into a caller's frame array (empty_frames(..., fd=...), reused across blocks, so a long run
        does not fault in fresh memory for every block); returns the number of frames written from row 0. Every
        sample is encoded here, new reading or not (`new_flag` is for `encode`)."""
        n = len(samples)
        needed = n * len(self._lengths)
        wanted = FD_FRAME_DTYPE if self.fd else CLASSIC_FRAME_DTYPE
        if (frames.dtype not in (wanted, FD_FRAME_DTYPE) or frames.ndim != 1 or frames.shape[0] < needed
                or not frames.flags.c_contiguous):
            raise ValueError(f"frames must be an empty_frames(count, fd={self.fd}) array of at least {needed} rows")
        return self._encode(samples, frames)

    def _encode(self, samples: Samples, frames: np.ndarray) -> int:
        n = len(samples)
        message, sources = self._program(samples)
        params = self._params
        params[4] = self.transfer_id
        counts = self._counts
        ops = message.program(self.fd)
        since_start = samples.time_ns - np.int64(samples.start_ns) if samples.start_ns else samples.time_ns
        written, bad_sample, bad_op, saturated = _encode_transfers(since_start, sources, ops, params, counts,
                                                                   frame_bytes(frames))
        if bad_sample >= 0:
            field = message.sources[ops[bad_op, 1]]
            component = "" if field == "integration_interval" else f", component {ops[bad_op, 2]}"
            where = f"sample {bad_sample}{component}"
            raise EncodeError(f"non-finite value in field '{field}' at {where} ({message.name})")
        if saturated:
            for index, name in enumerate(message.counters):
                self.saturated.add(name, int(counts[index]))
        self.transfer_id = (self.transfer_id + n) & 0x1F
        self._after_block(samples)
        return int(written)

    def _after_block(self, samples: Samples) -> None:
        """Hook for state that follows the last sample (RawIMU's previous timestamp)."""


class RawImuEncoder(_DroneCanEncoder):
    message = RAW_IMU
    uses_increments = True     # rate_gyro_integral, accelerometer_integral

    def __init__(self, sample_period_s: float | None = None, **options):
        super().__init__(**options)
        if sample_period_s is not None and not (math.isfinite(sample_period_s) and sample_period_s > 0):
            raise ValueError(f"sample_period_s must be a positive number, got {sample_period_s}")
        self.sample_period_s = sample_period_s
        self._last_time_ns: int | None = None

    def _program(self, samples: Samples):
        given = samples.delta_theta is not None and samples.delta_velocity is not None
        message = RAW_IMU if given else RAW_IMU_FROM_RATES
        interval = integration_intervals(samples, self.sample_period_s, self._last_time_ns)
        sources = (interval, samples.gyro, samples.accel,
                   samples.delta_theta if given else samples.gyro,
                   samples.delta_velocity if given else samples.accel)
        return message, sources

    def _after_block(self, samples: Samples) -> None:
        if len(samples):
            self._last_time_ns = int(samples.time_ns[-1])


class SolutionEncoder(_DroneCanEncoder):
    """Attitude from Samples.quat (identity when absent), rate and specific force as given."""

    message = SOLUTION

    def _program(self, samples: Samples):
        return SOLUTION, (samples.field_or("quat", (1.0, 0.0, 0.0, 0.0)), samples.gyro, samples.accel)


class MagneticFieldStrength2Encoder(_DroneCanEncoder):
    """Magnetic field in gauss from Samples.mag (zeros when absent), on the magnetometer's new readings."""
    new_flag = "mag_new"
    frames_vary = True     # a transfer only at samples with a new reading (Samples.mag_new)

    def __init__(self, sensor_id: int = 0, **options):
        if not 0 <= int(sensor_id) <= 255:
            raise ValueError(f"sensor_id must be 0..255, got {sensor_id}")
        self.message = _mag2_message(int(sensor_id))
        self.sensor_id = int(sensor_id)
        super().__init__(**options)

    def _program(self, samples: Samples):
        return self.message, (samples.field_or("mag", (0.0, 0.0, 0.0)),)


# --- decoder ------------------------------------------------------------------------------------

def _half(data: bytes, offset: int, count: int) -> np.ndarray:
    return np.frombuffer(data, dtype="<f2", count=count, offset=offset).astype(np.float64)


def _single(data: bytes, offset: int, count: int) -> np.ndarray:
    return np.frombuffer(data, dtype="<f4", count=count, offset=offset).astype(np.float64)


def _timestamp_ns(payload: bytes) -> int:
    return int.from_bytes(payload[0:7], "little") * 1000


def _parse_raw_imu(p: bytes) -> dict:
    return {"time_ns": _timestamp_ns(p), "integration_interval": float(_single(p, 7, 1)[0]),
            "gyro": _half(p, 11, 3), "delta_theta": _single(p, 17, 3),
            "accel": _half(p, 29, 3), "delta_velocity": _single(p, 35, 3)}


def _parse_solution(p: bytes) -> dict:
    xyzw = _half(p, 7, 4)
    return {"time_ns": _timestamp_ns(p), "quat": np.array([xyzw[3], xyzw[0], xyzw[1], xyzw[2]]),
            "gyro": _half(p, 16, 3), "accel": _half(p, 23, 3)}


def _parse_mag2(p: bytes) -> dict:
    return {"sensor_id": p[0], "mag": _half(p, 1, 3)}


_PARSERS = {1003: _parse_raw_imu, 1000: _parse_solution, 1002: _parse_mag2}


class _Transfer:
    __slots__ = ("transfer_id", "toggle", "data", "fd")

    def __init__(self, transfer_id, data, fd):
        self.transfer_id = transfer_id
        self.toggle = 0
        self.data = bytearray(data)
        self.fd = fd


class DroneCanDecoder(CanStreamDecoder):
    """Reassembles ahrs.RawIMU / Solution / MagneticFieldStrength2 transfers from any source node.

    One transfer in progress per CAN id (a node sends one transfer of a subject at a time). A frame that
    breaks the toggle / transfer id / start-of-transfer sequence drops the transfer in progress
    (counted in ignored_frames); a bad transfer CRC counts in bad_checksum. Nothing raises.
    """

    def __init__(self, data_type_ids=(1000, 1002, 1003), messages: dict | None = None):
        # messages: dtid -> (message with name, signature_crc, payload_len[False], parser(payload) -> dict) for
        # data types beyond this module's (dronecan_sensors' air data and GNSS)
        self._messages = {dtid: (m, _PARSERS[dtid]) for dtid, m in MESSAGES_BY_ID.items()}
        self._messages.update(messages or {})
        self.data_type_ids = frozenset(int(d) for d in data_type_ids)
        self.stats = DecoderStats()
        self._pending: dict[int, _Transfer] = {}

    def _feed(self, can_id, data, extended, fd):
        dtid = (can_id >> 8) & 0xFFFF
        if (not extended or not data or can_id > 0x1FFFFFFF or can_id & 0x80 or (can_id & 0x7F) == 0
                or dtid not in self.data_type_ids or len(data) > (64 if fd else 8)):
            self.stats.ignored_frames += 1
            return []
        tail = data[-1]
        body = data[:-1]
        start, end, toggle, tid = bool(tail & 0x80), bool(tail & 0x40), tail & 0x20, tail & 0x1F
        pending = self._pending.get(can_id)
        if start:
            if pending is not None:         # the previous transfer never finished
                self.stats.ignored_frames += 1
            self._pending.pop(can_id, None)
            if toggle:
                self.stats.ignored_frames += 1
                return []
            if end:
                return self._complete(can_id, dtid, body, fd, tid)
            self._pending[can_id] = _Transfer(tid, body, fd)
            return []
        if pending is None or tid != pending.transfer_id or toggle == pending.toggle or fd != pending.fd:
            self.stats.ignored_frames += 1
            if pending is not None:
                del self._pending[can_id]
            return []
        pending.toggle = toggle
        pending.data += body
        if not end:
            return []
        del self._pending[can_id]
        stream = bytes(pending.data)
        if len(stream) < 2:
            self.stats.ignored_frames += 1
            return []
        message = self._messages[dtid][0]
        received = stream[0] | stream[1] << 8
        payload = stream[2:]
        if crc16_ccitt_bytes(payload, message.signature_crc) != received:
            self.stats.bad_checksum += 1
            return []
        return self._complete(can_id, dtid, payload, fd, tid)

    def _complete(self, can_id, dtid, payload, fd, tid):
        message, parser = self._messages[dtid]
        if len(payload) < message.payload_len[False]:
            self.stats.ignored_frames += 1
            return []
        fields = parser(payload)
        fields.update(source_node_id=can_id & 0x7F, priority=(can_id >> 24) & 0x1F, transfer_id=tid)
        self.stats.packets += 1
        return [Packet(kind=message.name, fields=fields, raw=payload)]


# --- registry -----------------------------------------------------------------------------------

_COMMON_OPTIONS = {
    "node_id": "source node id 1..127",
    "priority": "transfer priority 0..31 (31 is lowest)",
    "fd": "CAN FD framing: one frame per transfer (False: classic 8-byte frames)",
    "transfer_id": "first transfer id 0..31",
}

register(FormatInfo(
    name="dronecan-rawimu", kind="can",
    description="DroneCAN uavcan.equipment.ahrs.RawIMU (id 1003): rate, specific force, integrals",
    encoder=RawImuEncoder, decoder=lambda **_: DroneCanDecoder((1003,)),
    frames_per_sample=tuple((n, True, False) for n in RAW_IMU.frame_lengths(False)),
    options={**_COMMON_OPTIONS,
             "sample_period_s": "integration interval in s, > 0 (None: time since the previous sample)"},
))
register(FormatInfo(
    name="dronecan-solution", kind="can",
    description="DroneCAN uavcan.equipment.ahrs.Solution (id 1000): attitude, rate, acceleration",
    encoder=SolutionEncoder, decoder=lambda **_: DroneCanDecoder((1000,)),
    frames_per_sample=tuple((n, True, False) for n in SOLUTION.frame_lengths(False)),
    options=dict(_COMMON_OPTIONS),
))
register(FormatInfo(
    name="dronecan-mag2", kind="can",
    description="DroneCAN uavcan.equipment.ahrs.MagneticFieldStrength2 (id 1002): field in gauss",
    encoder=MagneticFieldStrength2Encoder, decoder=lambda **_: DroneCanDecoder((1002,)),
    frames_per_sample=tuple((n, True, False) for n in _mag2_message(0).frame_lengths(False)),
    options={**_COMMON_OPTIONS, "sensor_id": "sensor id 0..255"},
))
