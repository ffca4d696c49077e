"""MAVLink 2 IMU messages: HIGHRES_IMU, HIL_SENSOR, SCALED_IMU/2/3 and RAW_IMU, plus a stream decoder.

Frame: ``FD len incompat compat seq sysid compid msgid(3 LE) payload crc(2 LE) [signature 13]``.
Payload fields are little-endian in wire order (largest type first, extensions appended); trailing
zero bytes are cut (one byte always stays). CRC-16/MCRF4XX over ``len .. payload`` then CRC_EXTRA.

Wire units and ranges (SI in, SI out of the decoder; conversions happen only here):

==============  =========================  ==================================================
message         field                      wire unit / range
==============  =========================  ==================================================
HIGHRES_IMU,    time_usec u64              (time_ns - start_ns) // 1000: time since the run's
                                           start (common.xml: "UNIX Epoch time or time since
                                           system boot"; PX4 SITL sets its clock from
                                           HIL_SENSOR's, as from Gazebo's sim time); negative
                                           time saturates to 0
HIL_SENSOR      x/y/z acc, gyro, mag f32   m/s^2, rad/s, gauss; |v| > FLT_MAX saturates
                abs_pressure f32           hPa (pressure_pa / 100)
                diff_pressure f32          hPa: Samples.differential_pressure_pa, or the
                                           `diff_pressure_pa` option (which wins when set)
                pressure_alt f32           m: the `pressure_alt_m` option, else the ISA
                                           (geopotential) altitude of the static pressure,
                                           44330.77 m * (1 - (p / 101325 Pa)^0.190263)
                temperature f32            degC
                fields_updated u16 / u32   bit k set iff float field k (wire order) was provided
                                           and, for mag (bits 6-8) and baro (9-12), that sensor
                                           has a new reading at this sample (Samples.mag_new,
                                           baro_new: the scene's companion rates; None = every
                                           sample); HIL_SENSOR's bit 31 (reset) is never set
                id u8 (extension)          the `id` option (sensor instance)
SCALED_IMU,     time_boot_ms u32           ((time_ns - start_ns) // 1_000_000) mod 2^32: since
                                           the run's start (the unit's boot); wraps after 49.7
SCALED_IMU2,                               days exactly as the autopilot's counter does
SCALED_IMU3     x/y/z acc i16              mG  (1 g = 9.80665 m/s^2), +-32767 mG ~ +-321 m/s^2
                x/y/z gyro i16             mrad/s, +-32.767 rad/s
                x/y/z mag i16              mgauss, +-32.767 gauss
                temperature i16 (ext.)     cdegC; 0 means "not sent", so 0 degC is sent as 1
RAW_IMU         time_usec u64              as HIGHRES_IMU
                9 x i16                    raw values = the SCALED_IMU values (mG, mrad/s,
                                           mgauss): a consumer that applies no scale factor
                                           then still reads physical units
                id u8, temperature i16     as above (temperature 0 = not sent)
==============  =========================  ==================================================

HIL_SENSOR for PX4 HITL (PX4-Autopilot simulator_mavlink, SimulatorMavlink.hpp/.cpp at commits ad41976 /
f66bdc0): PX4 takes a sensor only when ALL its bits are set: ACCEL 0b111, GYRO 0b111000, MAG 0b111000000,
BARO 0b1101000000000 (abs_pressure, pressure_alt AND temperature: a barometer needs Samples.temperature_c),
DIFF_PRESS 0b10000000000; pressures hPa x 100 -> Pa. Hence mag and baro bits go on and off together, and the
samples' new-reading flags (Samples.mag_new, baro_new, from the scene's [imu.magnetometer] / [imu.barometer]
rate_hz; differential pressure follows the barometer) decide at which samples they are set, so PX4 sees each
reading once at its sensor's rate. The retired options `mag_rate_hz` / `baro_rate_hz` are refused in one line.

Integer fields round to nearest (ties to even) and saturate; each clipped value is counted per wire
field in ``encoder.saturated``. Missing optional inputs go on the wire as 0, which is MAVLink's own
"not provided" value (with the fields_updated bit clear for HIGHRES_IMU / HIL_SENSOR, and the
temperature "not sent" convention for the integer messages); fields a message does not carry are
not checked for finiteness.

Signing timestamps (units of 10 us since 2015-01-01 UTC) come either from the sample time
(``sign_time="sample"``: time_ns, UTC Unix nanoseconds as firmware_protocols.gnss_time has it, deterministic)
or from the wall clock at the moment ``encode`` is called (``sign_time="wall"``, the default: a live link's
peer checks the stamps against its own clock). Either way each packet's timestamp is max(candidate, previous + 1)
for its `SigningLink`, so it is strictly increasing per link even when samples come faster than
100 kHz, within one batch or when several encoders share a link.
"""
from __future__ import annotations

import functools
import hashlib
import io
import math
import re
import struct
import time
from dataclasses import dataclass

from imu_emulator.native.lazy import jit
import numpy as np

from firmware_protocols.base import DecoderStats, EncodeError, Packet, SaturationStats, Samples, SerialBatch
from firmware_protocols.crc import crc16_mcrf4xx, crc16_mcrf4xx_bytes
from firmware_protocols.registry import FormatInfo, register
from firmware_protocols.update_rate import new_readings, refuse_retired, retired_help

STX_V2 = 0xFD
STX_V1 = 0xFE
HEADER_LEN = 10          # STX .. msgid
SIGNATURE_LEN = 13       # link_id, timestamp(6), signature(6)
INCOMPAT_SIGNED = 0x01
STANDARD_GRAVITY = 9.80665
EPOCH_2015_NS = 1_420_070_400 * 1_000_000_000

# Wire field types. Float fields and i16 take the "scaled" path (value / lsb); the rest are integers
# that come from time or from options.
T_F32, T_I16, T_U8, T_U16, T_U32, T_U64 = range(6)
_TYPE_SIZE = {T_F32: 4, T_I16: 2, T_U8: 1, T_U16: 2, T_U32: 4, T_U64: 8}
_TYPE_STRUCT = {T_F32: "f", T_I16: "h", T_U8: "B", T_U16: "H", T_U32: "I", T_U64: "Q"}

# Sources of wire values. The measured ones are numbered like HIGHRES_IMU's fields_updated bits, so
# the kernel builds that bitmask from the sources a layout actually filled.
(S_ACC_X, S_ACC_Y, S_ACC_Z, S_GYRO_X, S_GYRO_Y, S_GYRO_Z, S_MAG_X, S_MAG_Y, S_MAG_Z,
 S_PRESSURE, S_DIFF_PRESSURE, S_PRESSURE_ALT, S_TEMPERATURE) = range(13)
S_TIME_USEC, S_TIME_BOOT_MS, S_FIELDS_UPDATED, S_ID = range(13, 17)

# Layout columns (int64 array, one row per wire field).
L_SOURCE, L_TYPE, L_OFFSET, L_ZERO_ABSENT = range(4)

# Encoder parameter slots (int64 array).
(P_SEQ, P_SYSID, P_COMPID, P_MSGID, P_CRC_EXTRA, P_TRUNCATE, P_SIGN_MODE, P_LINK_ID, P_WALL_TS,
 P_ID, P_PAYLOAD_LEN, P_START, P_COUNT) = range(13)       # P_START: Samples.start_ns, per encode
SIGN_NONE, SIGN_SAMPLE, SIGN_WALL = range(3)

# Constant-source slots (float64 array); NaN = not provided.
C_DIFF_PRESSURE, C_PRESSURE_ALT, C_COUNT = range(3)

_FLT_MAX = float(np.finfo(np.float32).max)
_ISA_P0 = 101325.0
_ISA_EXPONENT = 0.190263      # R * L / (g * M) of the ISA troposphere
_ISA_SCALE_M = 44330.77       # T0 / L


@dataclass(frozen=True)
class WireField:
    name: str
    type: int
    source: int
    lsb: float = 1.0             # SI value of one wire unit
    zero_absent: bool = False    # wire 0 means "not provided"


@dataclass(frozen=True)
class MessageSpec:
    name: str             # registry name
    msg_name: str         # MAVLink name
    msgid: int
    crc_extra: int
    fields: tuple         # WireField, in wire order (extensions last)
    description: str

    @functools.cached_property
    def offsets(self) -> tuple:
        out, pos = [], 0
        for f in self.fields:
            out.append(pos)
            pos += _TYPE_SIZE[f.type]
        return tuple(out)

    @property
    def payload_len(self) -> int:
        return self.offsets[-1] + _TYPE_SIZE[self.fields[-1].type]

    @functools.cached_property
    def layout(self) -> np.ndarray:
        return np.array([[f.source, f.type, off, f.zero_absent] for f, off in zip(self.fields, self.offsets)],
                        dtype=np.int64)

    @functools.cached_property
    def lsb(self) -> np.ndarray:
        return np.array([f.lsb for f in self.fields], dtype=np.float64)

    @functools.cached_property
    def unpacker(self):
        return struct.Struct("<" + "".join(_TYPE_STRUCT[f.type] for f in self.fields))

    def has_source(self, source: int) -> bool:
        return any(f.source == source for f in self.fields)

    def decode(self, payload: bytes) -> dict:
        """The full-length payload -> SI fields (see _si_fields)."""
        return _si_fields(self, payload)


def _float_fields() -> list:
    """HIGHRES_IMU's and HIL_SENSOR's 13 float32 fields (hPa for the two pressures)."""
    return [WireField(n, T_F32, s, lsb) for n, s, lsb in (
        ("xacc", S_ACC_X, 1.0), ("yacc", S_ACC_Y, 1.0), ("zacc", S_ACC_Z, 1.0),
        ("xgyro", S_GYRO_X, 1.0), ("ygyro", S_GYRO_Y, 1.0), ("zgyro", S_GYRO_Z, 1.0),
        ("xmag", S_MAG_X, 1.0), ("ymag", S_MAG_Y, 1.0), ("zmag", S_MAG_Z, 1.0),
        ("abs_pressure", S_PRESSURE, 100.0), ("diff_pressure", S_DIFF_PRESSURE, 100.0),
        ("pressure_alt", S_PRESSURE_ALT, 1.0), ("temperature", S_TEMPERATURE, 1.0))]


def _int16_fields() -> list:
    mg, milli = STANDARD_GRAVITY / 1000.0, 1e-3
    return [WireField(n, T_I16, s, lsb) for n, s, lsb in (
        ("xacc", S_ACC_X, mg), ("yacc", S_ACC_Y, mg), ("zacc", S_ACC_Z, mg),
        ("xgyro", S_GYRO_X, milli), ("ygyro", S_GYRO_Y, milli), ("zgyro", S_GYRO_Z, milli),
        ("xmag", S_MAG_X, milli), ("ymag", S_MAG_Y, milli), ("zmag", S_MAG_Z, milli))]


_TEMPERATURE_CDEG = WireField("temperature", T_I16, S_TEMPERATURE, 0.01, zero_absent=True)
_TIME_USEC = WireField("time_usec", T_U64, S_TIME_USEC)
_ID = WireField("id", T_U8, S_ID)


def _scaled_imu(name: str, msg_name: str, msgid: int, crc_extra: int) -> MessageSpec:
    return MessageSpec(name, msg_name, msgid, crc_extra,
                       (WireField("time_boot_ms", T_U32, S_TIME_BOOT_MS), *_int16_fields(), _TEMPERATURE_CDEG),
                       f"MAVLink 2 {msg_name} ({msgid}): int16 mG / mrad/s / mgauss, time_boot_ms")


MESSAGES = {spec.name: spec for spec in (
    MessageSpec("mavlink-highres", "HIGHRES_IMU", 105, 93,
                (_TIME_USEC, *_float_fields(), WireField("fields_updated", T_U16, S_FIELDS_UPDATED), _ID),
                "MAVLink 2 HIGHRES_IMU (105): float32 SI values, pressure, temperature"),
    MessageSpec("mavlink-hil-sensor", "HIL_SENSOR", 107, 108,
                (_TIME_USEC, *_float_fields(), WireField("fields_updated", T_U32, S_FIELDS_UPDATED), _ID),
                "MAVLink 2 HIL_SENSOR (107): what PX4 HITL consumes"),
    _scaled_imu("mavlink-scaled-imu", "SCALED_IMU", 26, 170),
    _scaled_imu("mavlink-scaled-imu2", "SCALED_IMU2", 116, 76),
    _scaled_imu("mavlink-scaled-imu3", "SCALED_IMU3", 129, 46),
    MessageSpec("mavlink-raw-imu", "RAW_IMU", 27, 144,
                (_TIME_USEC, *_int16_fields(), _ID, _TEMPERATURE_CDEG),
                "MAVLink 2 RAW_IMU (27): int16 raw values (= SCALED_IMU units), time_usec"),
)}
_BY_MSGID = {spec.msgid: spec for spec in MESSAGES.values()}


# --- the packing kernel -------------------------------------------------------------------------

@jit(cache=True, nogil=True)
def _put_le(out, pos, value, nbytes):
    for k in range(nbytes):
        out[pos + k] = (value >> (8 * k)) & 0xFF


@jit(cache=True, nogil=True)
def _first_nonfinite_row(values, n, lo, hi):
    """First row in [lo, hi) holding a non-finite value, or hi (an empty array means "absent")."""
    if values.shape[0] != n:
        return hi
    flat = values.reshape(-1)
    width = flat.shape[0] // n
    for j in range(lo * width, hi * width):
        if not np.isfinite(flat[j]):
            return j // width
    return hi


@jit(cache=True, nogil=True)
def _encode_block(time_ns, accel, gyro, mag, pressure, diff_pressure, temperature, updated, layout, lsb, consts,
                  params, link_state, lo, hi, base, sat, out, offsets):
    """Pack samples [lo, hi) into `out` from its start; offsets[lo..hi] get `base` + position in out.

    `updated` (n,) int64: the fields_updated bits sample i may carry (the sensors with a new reading then);
    empty: all. Returns (first non-finite row or -1, bytes written, values saturated). Saturations are added
    to `sat`; params / link_state are only advanced when the whole range is finite.
    """
    n = time_ns.shape[0]
    bad = hi
    for values in (accel, gyro, mag):
        bad = min(bad, _first_nonfinite_row(values, n, lo, bad))
    for values in (pressure, diff_pressure, temperature):
        bad = min(bad, _first_nonfinite_row(values, n, lo, bad))
    if bad < hi:
        return bad, 0, 0

    has_mag = mag.shape[0] == n
    has_pressure = pressure.shape[0] == n
    has_diff = diff_pressure.shape[0] == n
    has_updated = updated.shape[0] == n
    has_temperature = temperature.shape[0] == n
    nfields = layout.shape[0]

    # Which measured sources this block provides; doubles as HIGHRES/HIL fields_updated.
    present = 0
    for f in range(nfields):
        s = layout[f, L_SOURCE]
        if s > S_TEMPERATURE:
            continue
        provided = (s <= S_GYRO_Z or (s <= S_MAG_Z and has_mag) or (s == S_PRESSURE and has_pressure)
                    or (s == S_DIFF_PRESSURE and (has_diff or not np.isnan(consts[C_DIFF_PRESSURE])))
                    or (s == S_PRESSURE_ALT and (has_pressure or not np.isnan(consts[C_PRESSURE_ALT])))
                    or (s == S_TEMPERATURE and has_temperature))
        if provided:
            present |= 1 << s

    f32 = np.zeros(1, dtype=np.float32)
    f32_bytes = f32.view(np.uint8)
    seq = params[P_SEQ]
    sign_mode = params[P_SIGN_MODE]
    last_ts = link_state[0]
    sat_before = 0
    for f in range(nfields):
        sat_before += sat[f]
    pos = 0
    for i in range(lo, hi):
        offsets[i] = base + pos
        p0 = pos + HEADER_LEN
        t = time_ns[i]
        for f in range(nfields):
            s = layout[f, L_SOURCE]
            typ = layout[f, L_TYPE]
            at = p0 + layout[f, L_OFFSET]
            if s <= S_TEMPERATURE:
                value = 0.0
                if present & (1 << s):
                    if s <= S_ACC_Z:
                        value = accel[i, s - S_ACC_X]
                    elif s <= S_GYRO_Z:
                        value = gyro[i, s - S_GYRO_X]
                    elif s <= S_MAG_Z:
                        value = mag[i, s - S_MAG_X]
                    elif s == S_PRESSURE:
                        value = pressure[i]
                    elif s == S_DIFF_PRESSURE:
                        value = diff_pressure[i] if np.isnan(consts[C_DIFF_PRESSURE]) else consts[C_DIFF_PRESSURE]
                    elif s == S_PRESSURE_ALT:
                        if np.isnan(consts[C_PRESSURE_ALT]):
                            # ISA is undefined below zero pressure; such input is nonsense anyway.
                            value = _ISA_SCALE_M * (1.0 - (max(pressure[i], 0.0) / _ISA_P0) ** _ISA_EXPONENT)
                        else:
                            value = consts[C_PRESSURE_ALT]
                    else:
                        value = temperature[i]
                    value = value / lsb[f]
                if typ == T_F32:
                    if value > _FLT_MAX:
                        value = _FLT_MAX
                        sat[f] += 1
                    elif value < -_FLT_MAX:
                        value = -_FLT_MAX
                        sat[f] += 1
                    f32[0] = value
                    for k in range(4):
                        out[at + k] = f32_bytes[k]
                else:
                    r = np.rint(value)
                    if r > 32767.0:
                        r = 32767.0
                        sat[f] += 1
                    elif r < -32768.0:
                        r = -32768.0
                        sat[f] += 1
                    iv = np.int64(r)
                    if iv == 0 and layout[f, L_ZERO_ABSENT] and (present & (1 << s)):
                        iv = 1   # the smallest reading that is not "not sent"
                    _put_le(out, at, iv, 2)
            elif s == S_TIME_USEC:
                usec = (t - params[P_START]) // 1000
                if usec < 0:
                    usec = 0
                    sat[f] += 1
                _put_le(out, at, usec, 8)
            elif s == S_TIME_BOOT_MS:
                _put_le(out, at, ((t - params[P_START]) // 1_000_000) & 0xFFFFFFFF, 4)
            elif s == S_FIELDS_UPDATED:
                bits = present & updated[i] if has_updated else present
                _put_le(out, at, bits, 4 if typ == T_U32 else 2)
            else:
                _put_le(out, at, params[P_ID], 1)

        plen = params[P_PAYLOAD_LEN]
        if params[P_TRUNCATE]:
            while plen > 1 and out[p0 + plen - 1] == 0:
                plen -= 1
        out[pos] = STX_V2
        out[pos + 1] = plen
        out[pos + 2] = INCOMPAT_SIGNED if sign_mode != SIGN_NONE else 0
        out[pos + 3] = 0
        out[pos + 4] = seq
        out[pos + 5] = params[P_SYSID]
        out[pos + 6] = params[P_COMPID]
        _put_le(out, pos + 7, params[P_MSGID], 3)
        # CRC_EXTRA is fed as if it were one more byte; it sits where the CRC goes, then is overwritten.
        end = p0 + plen
        out[end] = params[P_CRC_EXTRA]
        crc = crc16_mcrf4xx(out, pos + 1, end + 1, 0xFFFF)
        _put_le(out, end, crc, 2)
        end += 2
        if sign_mode != SIGN_NONE:
            ts = params[P_WALL_TS] if sign_mode == SIGN_WALL else (t - EPOCH_2015_NS) // 10_000
            if ts <= last_ts:
                ts = last_ts + 1
            last_ts = ts
            out[end] = params[P_LINK_ID]
            _put_le(out, end + 1, ts, 6)
            end += SIGNATURE_LEN   # the 6 signature bytes are filled by SHA-256 in Python
        pos = end
        seq = (seq + 1) & 0xFF
    offsets[hi] = base + pos
    params[P_SEQ] = seq
    link_state[0] = last_ts
    nsat = -sat_before
    for f in range(nfields):
        nsat += sat[f]
    return -1, pos, nsat


# --- one frame at a time (messages sent now and then: GNSS fixes, replies) ---------------------------

def pack_frame(msgid: int, crc_extra: int, payload: bytes, seq: int, sysid: int, compid: int, link=None,
               timestamp: int | None = None, truncate: bool = True) -> bytes:
    """One MAVLink 2 frame: trailing zero payload bytes cut (one stays) unless `truncate` is False; signed on
    `link` (a SigningLink) with `timestamp` (10 us since 2015-01-01; None: the wall clock), raised to the
    link's previous timestamp + 1 so that it strictly increases on the link."""
    if truncate:
        payload = payload.rstrip(b"\0") or b"\0"
    header = bytes([STX_V2, len(payload), INCOMPAT_SIGNED if link is not None else 0, 0, seq & 0xFF, sysid,
                    compid]) + msgid.to_bytes(3, "little")
    crc = crc16_mcrf4xx_bytes(header[1:] + payload + bytes([crc_extra]))
    frame = header + payload + crc.to_bytes(2, "little")
    if link is None:
        return frame
    if timestamp is None:
        timestamp = (time.time_ns() - EPOCH_2015_NS) // 10_000
    stamp = max(int(timestamp), int(link.state[0]) + 1)
    link.state[0] = stamp
    head = frame + bytes([link.link_id]) + stamp.to_bytes(6, "little")
    return head + hashlib.sha256(link.secret_key + head).digest()[:6]


# --- encoder ------------------------------------------------------------------------------------

class SigningLink:
    """Secret key, link id and the last timestamp sent on the link; share one between encoders that
    sign on the same link so their timestamps stay strictly increasing together."""

    def __init__(self, secret_key, link_id: int = 0):
        key = bytes.fromhex(secret_key) if isinstance(secret_key, str) else bytes(secret_key)
        if len(key) != 32:
            raise ValueError(f"signing_key: MAVLink secret keys are 32 bytes, got {len(key)}")
        if not 0 <= int(link_id) <= 255:
            raise ValueError(f"link_id: must be 0..255, got {link_id}")
        self.secret_key = key
        self.link_id = int(link_id)
        self._hash = hashlib.sha256(key)
        self.state = np.zeros(1, dtype=np.int64)   # last timestamp, written by the kernel

    @property
    def last_timestamp(self) -> int:
        return int(self.state[0])

    def sign(self, out: np.ndarray, offsets: np.ndarray, base: int = 0) -> None:
        """Fill the signature of the packets at out[offsets[i] - base : offsets[i + 1] - base]."""
        view = memoryview(out)
        keyed = self._hash
        for start, end in zip((offsets[:-1] - base).tolist(), (offsets[1:] - base).tolist()):
            h = keyed.copy()
            h.update(view[start:end - 6])
            view[end - 6:end] = h.digest()[:6]


_NO_ROWS = np.empty(0, dtype=np.float64)
_NO_ROWS3 = np.empty((0, 3), dtype=np.float64)
_NO_LINK = np.zeros(1, dtype=np.int64)
_NO_BITS = np.empty(0, dtype=np.int64)
_MAG_BITS = (1 << S_MAG_X) | (1 << S_MAG_Y) | (1 << S_MAG_Z)
_BARO_BITS = (1 << S_PRESSURE) | (1 << S_DIFF_PRESSURE) | (1 << S_PRESSURE_ALT) | (1 << S_TEMPERATURE)
_CHUNK = 8192   # samples per packing pass: the scratch buffer (<= 0.75 MB) stays in cache


def _byte_option(name: str, value: int) -> int:
    value = int(value)
    if not 0 <= value <= 255:
        raise ValueError(f"{name}: must be 0..255, got {value}")
    return value


class MavlinkEncoder:
    """Samples -> MAVLink 2 frames of one message type. Stateful: the sequence number (and the
    signing timestamp) continue across `encode` calls."""
    # Axes (common.xml as pymavlink bundles it): HIGHRES_IMU and HIL_SENSOR are "The IMU readings in SI units in NED
    # body frame"; SCALED_IMU* and RAW_IMU name no axes and are filled by the autopilots from the same body frame;
    # ATTITUDE* are "in the aeronautical frame (right-handed, Z-down, Y-right, X-front)". Samples are already so.
    body_axes, reference = "FRD", "NED"
    axes_source = "MAVLink common.xml: 'IMU readings in SI units in NED body frame'; attitude: aeronautical frame"


    def __init__(self, message: str = "mavlink-highres", sysid: int = 1, compid: int = 1, seq: int = 0,
                 id: int | None = None, signing_key=None, link_id: int = 0, signing_link: SigningLink | None = None,
                 sign_time: str = "wall", truncate: bool = True, diff_pressure_pa: float | None = None,
                 pressure_alt_m: float | None = None, mag_rate_hz: float | None = None,
                 baro_rate_hz: float | None = None):
        if message not in MESSAGES:
            raise ValueError(f"message: unknown {message!r}; known: {', '.join(MESSAGES)}")
        spec = self.spec = MESSAGES[message]
        if id is not None and not spec.has_source(S_ID):
            raise ValueError(f"id: {spec.msg_name} has no id field (its message number names the instance)")
        for name, value, source in (("diff_pressure_pa", diff_pressure_pa, S_DIFF_PRESSURE),
                                    ("pressure_alt_m", pressure_alt_m, S_PRESSURE_ALT)):
            if value is not None and not spec.has_source(source):
                raise ValueError(f"{name}: {spec.msg_name} carries no such field")
            if value is not None and not np.isfinite(value):
                raise ValueError(f"{name}: must be finite, got {value}")
        refuse_retired(mag_rate_hz=mag_rate_hz, baro_rate_hz=baro_rate_hz)
        self._flags_updates = spec.has_source(S_FIELDS_UPDATED)
        self._one_bits = np.empty(1, dtype=np.int64)       # the bits of a block of one, reused
        if sign_time not in ("wall", "sample"):
            raise ValueError(f"sign_time: 'wall' or 'sample', got {sign_time!r}")
        if signing_link is None and signing_key is not None:
            signing_link = SigningLink(signing_key, link_id)
        self.signing_link = signing_link
        self.saturated = SaturationStats()

        params = np.zeros(P_COUNT, dtype=np.int64)
        params[P_SEQ] = _byte_option("seq", seq)
        params[P_SYSID] = _byte_option("sysid", sysid)
        params[P_COMPID] = _byte_option("compid", compid)
        params[P_MSGID] = spec.msgid
        params[P_CRC_EXTRA] = spec.crc_extra
        params[P_TRUNCATE] = bool(truncate)
        params[P_ID] = _byte_option("id", id or 0)
        params[P_PAYLOAD_LEN] = spec.payload_len
        if signing_link is not None:
            params[P_SIGN_MODE] = SIGN_WALL if sign_time == "wall" else SIGN_SAMPLE
            params[P_LINK_ID] = signing_link.link_id
        self._params = params
        self._consts = np.array([np.nan if diff_pressure_pa is None else diff_pressure_pa,
                                 np.nan if pressure_alt_m is None else pressure_alt_m], dtype=np.float64)
        self._layout, self._lsb = spec.layout, spec.lsb
        self._sat = np.zeros(len(spec.fields), dtype=np.int64)   # per wire field, within one encode call
        self._uses_pressure = spec.has_source(S_PRESSURE)
        self._checked = ("accel", "gyro", "mag", "temperature_c") + (
            ("pressure_pa", "differential_pressure_pa") if self._uses_pressure else ())
        self.bytes_per_sample = HEADER_LEN + spec.payload_len + 2 + (SIGNATURE_LEN if signing_link else 0)
        self._scratch = np.empty(_CHUNK * self.bytes_per_sample, dtype=np.uint8)

    def _updated_bits(self, samples: Samples) -> np.ndarray:
        """Per sample, the fields_updated bits allowed: the magnetometer's and the barometer's (static and
        differential pressure, pressure altitude, temperature: PX4's SensorSource BARO and DIFF_PRESS) only
        where that sensor has a new reading (Samples.mag_new, baro_new); no limit (_NO_BITS) when the samples
        carry neither flag or the message has no fields_updated."""
        mag_new, baro_new = samples.mag_new, samples.baro_new
        if not self._flags_updates or (mag_new is None and baro_new is None):
            return _NO_BITS
        n = len(samples)
        if n == 1:      # a device's one sample: Python scalars, no numpy temporaries (half the per-sample cost)
            bits = 0xFFFFFFFF
            for name, flags, mask in (("mag_new", mag_new, _MAG_BITS), ("baro_new", baro_new, _BARO_BITS)):
                if flags is not None:
                    value = float(flags[0])
                    if not math.isfinite(value):
                        samples.require_finite((name,))        # raises, naming the field and sample
                    if value == 0:
                        bits &= ~mask
            self._one_bits[0] = bits
            return self._one_bits
        samples.require_finite(("mag_new", "baro_new"))
        allowed = np.full(n, 0xFFFFFFFF, dtype=np.int64)
        allowed[~new_readings(samples.mag_new, n)] &= ~_MAG_BITS
        allowed[~new_readings(samples.baro_new, n)] &= ~_BARO_BITS
        return allowed

    @property
    def seq(self) -> int:
        """Sequence number of the next packet."""
        return int(self._params[P_SEQ])

    def encode(self, samples: Samples, lo: int = 0, hi: int | None = None) -> SerialBatch:
        """Samples lo to hi - 1 of the block (all by default): a device encoding a few samples of a block at once
        passes the whole block and the range, which spares it a view of every field (about 9 us a call)."""
        n = len(samples.time_ns) if hi is None else hi
        mag, pressure, temperature = samples.mag, samples.pressure_pa, samples.temperature_c
        params, link = self._params, self.signing_link
        link_state = _NO_LINK if link is None else link.state
        if link is not None and params[P_SIGN_MODE] == SIGN_WALL:
            params[P_WALL_TS] = (time.time_ns() - EPOCH_2015_NS) // 10_000
        params[P_START] = samples.start_ns      # the wire times count since the run's start
        diff = samples.differential_pressure_pa
        arrays = (samples.time_ns, samples.accel, samples.gyro, _NO_ROWS3 if mag is None else mag,
                  pressure if pressure is not None and self._uses_pressure else _NO_ROWS,
                  diff if diff is not None and self._uses_pressure else _NO_ROWS,
                  _NO_ROWS if temperature is None else temperature,
                  self._updated_bits(samples),
                  self._layout, self._lsb, self._consts, params, link_state)
        offsets = np.empty(n + 1, dtype=np.int64)      # those of samples lo to n are set
        scratch, sat = self._scratch, self._sat
        # Big blocks are packed chunk by chunk into a cache-sized scratch buffer and streamed into a
        # BytesIO, whose getvalue() hands over its buffer without a copy: one large allocation
        # instead of two, which matters because first-touch page faults cost as much as the packing.
        sink = io.BytesIO() if n - lo > _CHUNK else None
        seq0, ts0 = params[P_SEQ], link_state[0]
        saturated, base, first = 0, 0, lo
        for lo in range(first, max(n, first + 1), _CHUNK):
            hi = min(lo + _CHUNK, n)
            bad, nbytes, nsat = _encode_block(*arrays, lo, hi, base, sat, scratch, offsets)
            if bad >= 0:
                params[P_SEQ], link_state[0] = seq0, ts0
                sat[:] = 0
                samples.require_finite(self._checked, np.arange(first, n))
                raise EncodeError(f"non-finite value at sample {bad}")   # unreachable unless arrays changed
            if link is not None:
                link.sign(scratch, offsets[lo:hi + 1], base)
            if sink is None:
                data = scratch[:nbytes].tobytes()
            else:
                sink.write(scratch[:nbytes])
            saturated += nsat
            base += nbytes
        if saturated:
            for field, count in zip(self.spec.fields, sat.tolist()):
                self.saturated.add(field.name, count)
            sat[:] = 0
        return SerialBatch(data if sink is None else sink.getvalue(), offsets[first:])


# --- decoder ------------------------------------------------------------------------------------

_SOURCE_NAMES = {S_PRESSURE: "pressure_pa", S_DIFF_PRESSURE: "diff_pressure_pa",
                 S_PRESSURE_ALT: "pressure_alt_m", S_TEMPERATURE: "temperature_c"}
_VECTORS = (("accel", S_ACC_X), ("gyro", S_GYRO_X), ("mag", S_MAG_X))
_STX = re.compile(b"[\xfd\xfe]")
_MAX_V2_FRAME = HEADER_LEN + 255 + 2 + SIGNATURE_LEN


def _si_fields(spec: MessageSpec, payload: bytes) -> dict:
    """Wire payload (zero-padded to full length) -> SI values; fields the sender marked as not
    provided come back as None."""
    wire = dict(zip((f.name for f in spec.fields), spec.unpacker.unpack(payload)))
    out = {"msgid": spec.msgid}
    updated = wire.get("fields_updated")
    si = {}
    for f in spec.fields:
        value = wire[f.name]
        if f.source <= S_TEMPERATURE:
            provided = (updated >> f.source) & 1 if updated is not None else not (f.zero_absent and value == 0)
            si[f.source] = value * f.lsb if provided else None
        elif f.source == S_TIME_USEC:
            out["time_usec"] = value
            out["time_ns"] = value * 1000
        elif f.source == S_TIME_BOOT_MS:
            out["time_boot_ms"] = value
            out["time_ns"] = value * 1_000_000
        else:
            out[f.name] = value
    for name, first in _VECTORS:
        parts = [si.get(first + k) for k in range(3)]
        out[name] = None if any(p is None for p in parts) else tuple(parts)
    for source, name in _SOURCE_NAMES.items():
        if source in si:
            out[name] = si[source]
    return out


class MavlinkDecoder:
    """Byte stream -> valid MAVLink 2 IMU packets. Never raises on any byte content.

    Frames of other message ids cannot be checked (their CRC_EXTRA is unknown here), so their bytes
    count as skipped. A MAVLink 1 frame of a known id with a valid CRC is skipped whole and counted in
    `stats.ignored_frames`. With `signing_key`, a frame is accepted only if its signature verifies and
    its timestamp is newer than the last one accepted from the same (link_id, sysid, compid); rejected
    frames (and unsigned ones, unless `allow_unsigned`) count in `stats.ignored_frames` and in
    `bad_signature`. Without a key, signed frames are accepted on their CRC alone.
    """

    def __init__(self, signing_key=None, allow_unsigned: bool = False, messages: dict | None = None):
        # messages: msgid -> spec (name, crc_extra, payload_len, decode(payload) -> dict); default the IMU messages
        self._messages = _BY_MSGID if messages is None else dict(messages)
        self.stats = DecoderStats()
        self.bad_signature = 0
        self._key = None
        if signing_key is not None:
            self._key = bytes.fromhex(signing_key) if isinstance(signing_key, str) else bytes(signing_key)
        self._allow_unsigned = allow_unsigned
        self._stream_ts: dict = {}
        self._buf = bytearray()

    def feed(self, chunk) -> list:
        buf = self._buf
        buf += chunk
        packets = []
        pos, size = 0, len(buf)
        stats = self.stats
        while pos < size:
            match = _STX.search(buf, pos)
            if match is None:
                stats.skipped_bytes += size - pos
                pos = size
                break
            stats.skipped_bytes += match.start() - pos
            pos = match.start()
            step = self._frame_v2(buf, pos, size, packets) if buf[pos] == STX_V2 else self._frame_v1(buf, pos, size)
            if step is None:      # a frame may still be arriving
                break
            if step == 0:         # not a frame start after all
                stats.skipped_bytes += 1
                step = 1
            pos += step
        del buf[:pos]
        return packets

    def _frame_v2(self, buf, pos, size, packets):
        """Bytes consumed by a frame at pos (0: not a frame, None: wait for more bytes)."""
        if size - pos < HEADER_LEN:
            return None
        plen, incompat = buf[pos + 1], buf[pos + 2]
        spec = self._messages.get(buf[pos + 7] | buf[pos + 8] << 8 | buf[pos + 9] << 16)
        if spec is None or incompat & ~INCOMPAT_SIGNED or not 1 <= plen <= spec.payload_len:
            return 0
        signed = bool(incompat & INCOMPAT_SIGNED)
        total = HEADER_LEN + plen + 2 + (SIGNATURE_LEN if signed else 0)
        if size - pos < total:
            return None
        end = pos + HEADER_LEN + plen
        crc = crc16_mcrf4xx_bytes(bytes(buf[pos + 1:end]) + bytes((spec.crc_extra,)))
        if crc != buf[end] | buf[end + 1] << 8:
            self.stats.bad_checksum += 1
            return 0
        frame = bytes(buf[pos:pos + total])
        sysid, compid = frame[5], frame[6]
        if self._key is not None and not self._authentic(frame, signed, sysid, compid):
            self.bad_signature += 1
            self.stats.ignored_frames += 1
            return total
        fields = spec.decode(frame[HEADER_LEN:HEADER_LEN + plen].ljust(spec.payload_len, b"\0"))
        fields.update(seq=frame[4], sysid=sysid, compid=compid, signed=signed)
        if signed:
            fields["link_id"] = frame[-13]
            fields["signing_timestamp"] = int.from_bytes(frame[-12:-6], "little")
        packets.append(Packet(spec.name, fields, frame))
        self.stats.packets += 1
        return total

    def _authentic(self, frame: bytes, signed: bool, sysid: int, compid: int) -> bool:
        if not signed:
            return self._allow_unsigned
        if hashlib.sha256(self._key + frame[:-6]).digest()[:6] != frame[-6:]:
            return False
        stream = (frame[-13], sysid, compid)
        timestamp = int.from_bytes(frame[-12:-6], "little")
        if timestamp <= self._stream_ts.get(stream, -1):
            return False   # replayed or reordered
        self._stream_ts[stream] = timestamp
        return True

    def _frame_v1(self, buf, pos, size):
        """A MAVLink 1 frame of a known message with a valid CRC is skipped whole; anything else
        starting with 0xFE is treated as noise."""
        if size - pos < 6:
            return None
        plen = buf[pos + 1]
        spec = self._messages.get(buf[pos + 5])
        if spec is None:
            return 0
        total = 6 + plen + 2
        if size - pos < total:
            return None
        end = pos + 6 + plen
        crc = crc16_mcrf4xx_bytes(bytes(buf[pos + 1:end]) + bytes((spec.crc_extra,)))
        if crc != buf[end] | buf[end + 1] << 8:
            return 0
        self.stats.ignored_frames += 1
        return total


# --- registry -----------------------------------------------------------------------------------

_COMMON_OPTIONS = {
    "sysid": "MAVLink system id 0..255",
    "compid": "MAVLink component id 0..255",
    "seq": "sequence number of the first packet, 0..255; continues across encode calls",
    "signing_key": "32-byte secret key (bytes or 64 hex digits): sign every packet",
    "link_id": "signing link id 0..255",
    "signing_link": "a SigningLink shared with other encoders on the same link",
    "sign_time": "signing timestamp from 'wall' clock or 'sample' time (time_ns as Unix ns)",
    "truncate": "cut trailing zero payload bytes as MAVLink 2 does",
}
_ID_OPTION = {"id": "sensor instance id 0..255 sent in the message's id field (None: 0)"}
_PRESSURE_OPTIONS = {
    "diff_pressure_pa": "constant differential pressure to report, Pa, instead of Samples.differential_pressure_pa "
                        "(None: that field, not reported when absent)",
    "mag_rate_hz": retired_help("mag_rate_hz"),
    "baro_rate_hz": retired_help("baro_rate_hz"),
    "pressure_alt_m": "constant pressure altitude to report, m (None: ISA altitude of the static pressure)",
}

for _spec in MESSAGES.values():
    register(FormatInfo(
        name=_spec.name, kind="serial", description=_spec.description,
        encoder=functools.partial(MavlinkEncoder, _spec.name), decoder=MavlinkDecoder,
        bytes_per_sample=HEADER_LEN + _spec.payload_len + 2,
        options={**_COMMON_OPTIONS,
                 **(_ID_OPTION if _spec.has_source(S_ID) else {}),
                 **(_PRESSURE_OPTIONS if _spec.has_source(S_PRESSURE) else {})}))
