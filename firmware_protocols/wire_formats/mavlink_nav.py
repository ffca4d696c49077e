"""MAVLink 2 messages of the sensor head beside the IMU: GNSS (HIL_GPS, GPS_RAW_INT), barometer (SCALED_PRESSURE)
and attitude (ATTITUDE, ATTITUDE_QUATERNION).

Layouts and CRC_EXTRA are common.xml's as pymavlink generates them (fields in wire order, extensions last).
Values come from Samples (SI, FRD body axes, quat FRD -> NED, scalar first: MAVLink's own conventions, so
nothing is rotated here):

==================  ======================================================================================
HIL_GPS (113)       time_usec u64: the solution's time of validity in UTC Unix us (firmware_protocols.gnss_time;
                    PX4 takes it as time_utc_usec), (time_ns - gnss_age_s) // 1000;
                    lat, lon i32 degE7; alt i32 mm (see "height" below); eph, epv u16 cm: the horizontal
                    and vertical 1-sigma accuracy, as PX4 reads them (simulator_mavlink handle_message_hil_gps:
                    eph * 1e-2 "cm -> m"; common.xml calls the field HDOP x 100, PX4 is the consumer);
                    vel u16 cm/s ground speed; vn, ve, vd i16 cm/s; cog u16 cdeg atan2(ve, vn) in
                    [0, 36000); fix_type u8; satellites_visible u8; id u8 (option); yaw u16 0 (not given)
GPS_RAW_INT (24)    time_usec, lat, lon, alt, vel, cog, fix_type, satellites_visible as HIL_GPS; eph, epv u16:
                    HDOP, VDOP x 100 (common.xml); alt_ellipsoid i32 mm; h_acc, v_acc u32 mm; vel_acc u32
                    mm/s; hdg_acc u32 0 and yaw u16 0 (no heading from a single antenna)
SCALED_PRESSURE     time_boot_ms u32: since the run's start, ((time_ns - start_ns) // 1e6) mod 2^32;
(29)                press_abs f32 hPa; press_diff f32 hPa (0 when absent); temperature i16 cdegC;
                    temperature_press_diff i16 cdegC, the sensor head's temperature when a differential
                    pressure is given, else 0 ("not available"; a reading of 0 goes out as 1)
ATTITUDE (30)       time_boot_ms; roll, pitch, yaw f32 rad (Samples.euler, else z-y-x angles of quat);
                    rollspeed, pitchspeed, yawspeed f32 rad/s: the body rates (Samples.gyro)
ATTITUDE_QUATERNION time_boot_ms; q1..q4 f32 = w, x, y, z of quat; the three body rates;
(31)                repr_offset_q f32[4] zeros (no offset: cut by truncation)
==================  ======================================================================================

GNSS: the receiver's solution (Samples.gnss_*); without gnss_llh, the position/velocity of the sample
(position_llh, velocity_ned) with gnss_time.GNSS_DEFAULTS' quality; without either, fix_type 1 (no fix) and zeros.
Each quality field that is None takes its GNSS_DEFAULTS value (DOPs: HDOP = hypot(dop_n, dop_e), VDOP = dop_v).
fix_type: Samples' 0 (no fix) is GPS_FIX_TYPE_NO_FIX (1): the receiver is there; 2 and 3 pass through.
The GNSS messages go out only at samples where gnss_new is 1 (a new solution, at the receiver's rate); every
sample when gnss_new is None. Height: there is no geoid model here, so alt (MSL) carries the ellipsoid height,
as gnss_time's records do; GPS_RAW_INT's alt_ellipsoid carries it too.
SCALED_PRESSURE goes out on the barometer's new readings (Samples.baro_new, from the scene's [imu.barometer]
rate_hz; every sample when baro_new is None; the retired option `baro_rate_hz` is refused); absent pressure and
temperature take Samples' documented defaults 101325 Pa and 25 degC.

Integers round to nearest and saturate (counted per wire field in `saturated`); a non-finite input is an
EncodeError naming field and sample. Signing and sequence numbers as mavlink.MavlinkEncoder (one frame is
packed at a time here: these messages are sent at GNSS/baro rates or by devices on request).
"""
from __future__ import annotations

import functools
import time

import numpy as np

from firmware_protocols import attitude
from firmware_protocols.base import SaturationStats, Samples, SerialBatch, to_float32_field, to_int_field
from firmware_protocols.gnss_time import receiver_solution
from firmware_protocols.registry import FormatInfo, register
from firmware_protocols.update_rate import new_readings, refuse_retired, retired_help
from firmware_protocols.wire_formats.mavlink import (_BY_MSGID, EPOCH_2015_NS, HEADER_LEN, SIGNATURE_LEN,
                                                     SigningLink, MavlinkDecoder, pack_frame)

_I16, _U16, _I32, _U32 = (-32768, 32767), (0, 65535), (-2 ** 31, 2 ** 31 - 1), (0, 2 ** 32 - 1)
_GPS_FIX_NO_FIX = 1


class NavMessage:
    """One message: its wire layout as a packed little-endian numpy dtype and how Samples fill it."""

    def __init__(self, name, msg_name, msgid, crc_extra, fields, fill, description, source="every"):
        self.name, self.msg_name, self.msgid, self.crc_extra = name, msg_name, msgid, crc_extra
        self.dtype = np.dtype(list(fields))
        self.payload_len = self.dtype.itemsize
        self.fill = fill               # fill(encoder, samples) -> {field: array}
        self.description = description
        self.source = source           # "gnss": only on new solutions; "baro": at the baro rate; "every"

    def decode(self, payload: bytes) -> dict:
        """Wire fields by name (raw wire units; pymavlink is the reference decoder for these)."""
        row = np.frombuffer(payload, dtype=self.dtype, count=1)[0]
        return {"msgid": self.msgid, **{name: row[name].tolist() for name in self.dtype.names}}


def _time_usec(samples: Samples, stats: SaturationStats) -> np.ndarray:
    age_ns = np.rint(samples.field_or("gnss_age_s", 0.0) * 1e9).astype(np.int64)
    usec = (samples.time_ns - age_ns) // 1000
    stats.add("time_usec", int(np.count_nonzero(usec < 0)))
    return np.maximum(usec, 0)


def _time_boot_ms(samples: Samples) -> np.ndarray:
    return ((samples.time_ns - samples.start_ns) // 1_000_000) & 0xFFFFFFFF     # since the run's start


def _gnss_solution(samples: Samples) -> dict:
    """The receiver's solution (gnss_time.receiver_solution), fix as GPS_FIX_TYPE: Samples' 0 is NO_FIX (1)."""
    g = receiver_solution(samples)
    g["fix"] = np.where(g["fix"] >= 2, g["fix"], _GPS_FIX_NO_FIX)
    return g


def _gnss_common(encoder, samples: Samples) -> tuple:
    g = _gnss_solution(samples)
    stats = encoder.saturated
    llh, vel = g["llh"], g["vel"]
    ground = np.hypot(vel[:, 0], vel[:, 1])
    cog = np.rint(np.degrees(np.arctan2(vel[:, 1], vel[:, 0])) % 360.0 * 100.0) % 36000
    out = {"time_usec": _time_usec(samples, stats),
           "lat": to_int_field(llh[:, 0], 1e-7, 0, *_I32, "lat", stats, np.int64),
           "lon": to_int_field(llh[:, 1], 1e-7, 0, *_I32, "lon", stats, np.int64),
           "alt": to_int_field(llh[:, 2], 1e-3, 0, *_I32, "alt", stats, np.int64),
           "vel": to_int_field(ground, 0.01, 0, *_U16, "vel", stats, np.int64),
           "cog": cog, "fix_type": g["fix"],
           "satellites_visible": to_int_field(g["sats"], 1, 0, 0, 255, "satellites_visible", stats, np.int64)}
    return out, g


def _fill_hil_gps(encoder, samples: Samples) -> dict:
    out, g = _gnss_common(encoder, samples)
    stats, vel = encoder.saturated, g["vel"]
    out.update(eph=to_int_field(g["h_acc"], 0.01, 0, *_U16, "eph", stats, np.int64),
               epv=to_int_field(g["v_acc"], 0.01, 0, *_U16, "epv", stats, np.int64),
               vn=to_int_field(vel[:, 0], 0.01, 0, *_I16, "vn", stats, np.int64),
               ve=to_int_field(vel[:, 1], 0.01, 0, *_I16, "ve", stats, np.int64),
               vd=to_int_field(vel[:, 2], 0.01, 0, *_I16, "vd", stats, np.int64),
               id=encoder.id)
    return out


def _fill_gps_raw_int(encoder, samples: Samples) -> dict:
    out, g = _gnss_common(encoder, samples)
    stats = encoder.saturated
    out.update(eph=to_int_field(g["hdop"], 0.01, 0, *_U16, "eph", stats, np.int64),
               epv=to_int_field(g["vdop"], 0.01, 0, *_U16, "epv", stats, np.int64),
               alt_ellipsoid=out["alt"],
               h_acc=to_int_field(g["h_acc"], 1e-3, 0, *_U32, "h_acc", stats, np.int64),
               v_acc=to_int_field(g["v_acc"], 1e-3, 0, *_U32, "v_acc", stats, np.int64),
               vel_acc=to_int_field(g["s_acc"], 1e-3, 0, *_U32, "vel_acc", stats, np.int64))
    return out


def _cdeg(values, name, stats, zero_absent=False):
    raw = to_int_field(values, 0.01, 0, *_I16, name, stats, np.int64)
    return np.where(raw == 0, 1, raw) if zero_absent else raw


def _fill_scaled_pressure(encoder, samples: Samples) -> dict:
    stats = encoder.saturated
    temperature = samples.field_or("temperature_c", 25.0)
    diff = samples.differential_pressure_pa
    return {"time_boot_ms": _time_boot_ms(samples), "press_abs": samples.field_or("pressure_pa", 101325.0) / 100.0,
            "press_diff": 0.0 if diff is None else diff / 100.0,
            "temperature": _cdeg(temperature, "temperature", stats),
            "temperature_press_diff": 0 if diff is None else _cdeg(temperature, "temperature_press_diff", stats,
                                                                   zero_absent=True)}


def _quat(samples: Samples) -> np.ndarray:
    return samples.field_or("quat", (1.0, 0.0, 0.0, 0.0))


def _rates(samples: Samples) -> dict:
    return {"rollspeed": samples.gyro[:, 0], "pitchspeed": samples.gyro[:, 1], "yawspeed": samples.gyro[:, 2]}


def _fill_attitude(encoder, samples: Samples) -> dict:
    euler = samples.euler if samples.euler is not None else attitude.to_euler(_quat(samples))
    return {"time_boot_ms": _time_boot_ms(samples), "roll": euler[:, 0], "pitch": euler[:, 1], "yaw": euler[:, 2],
            **_rates(samples)}


def _fill_attitude_quaternion(encoder, samples: Samples) -> dict:
    q = _quat(samples)
    return {"time_boot_ms": _time_boot_ms(samples), "q1": q[:, 0], "q2": q[:, 1], "q3": q[:, 2], "q4": q[:, 3],
            **_rates(samples)}


_GNSS_INPUTS = ("gnss_llh", "gnss_velocity_ned", "gnss_fix", "gnss_satellites", "gnss_hdop", "gnss_vdop",
                "gnss_horizontal_accuracy_m", "gnss_vertical_accuracy_m", "gnss_speed_accuracy_mps", "gnss_age_s",
                "position_llh", "velocity_ned")
_INPUTS = {"gnss": _GNSS_INPUTS, "baro": ("pressure_pa", "differential_pressure_pa", "temperature_c"),
           "every": ("gyro", "quat", "euler")}

NAV_MESSAGES = {m.name: m for m in (
    NavMessage("mavlink-hil-gps", "HIL_GPS", 113, 124,
               [("time_usec", "<u8"), ("lat", "<i4"), ("lon", "<i4"), ("alt", "<i4"), ("eph", "<u2"),
                ("epv", "<u2"), ("vel", "<u2"), ("vn", "<i2"), ("ve", "<i2"), ("vd", "<i2"), ("cog", "<u2"),
                ("fix_type", "u1"), ("satellites_visible", "u1"), ("id", "u1"), ("yaw", "<u2")],
               _fill_hil_gps, "MAVLink 2 HIL_GPS (113): the GNSS receiver's fix, as PX4 HITL consumes it", "gnss"),
    NavMessage("mavlink-gps-raw-int", "GPS_RAW_INT", 24, 24,
               [("time_usec", "<u8"), ("lat", "<i4"), ("lon", "<i4"), ("alt", "<i4"), ("eph", "<u2"),
                ("epv", "<u2"), ("vel", "<u2"), ("cog", "<u2"), ("fix_type", "u1"), ("satellites_visible", "u1"),
                ("alt_ellipsoid", "<i4"), ("h_acc", "<u4"), ("v_acc", "<u4"), ("vel_acc", "<u4"),
                ("hdg_acc", "<u4"), ("yaw", "<u2")],
               _fill_gps_raw_int, "MAVLink 2 GPS_RAW_INT (24): the GNSS receiver's fix with accuracies", "gnss"),
    NavMessage("mavlink-scaled-pressure", "SCALED_PRESSURE", 29, 115,
               [("time_boot_ms", "<u4"), ("press_abs", "<f4"), ("press_diff", "<f4"), ("temperature", "<i2"),
                ("temperature_press_diff", "<i2")],
               _fill_scaled_pressure, "MAVLink 2 SCALED_PRESSURE (29): static/differential pressure, hPa", "baro"),
    NavMessage("mavlink-attitude", "ATTITUDE", 30, 39,
               [("time_boot_ms", "<u4")] + [(f, "<f4") for f in ("roll", "pitch", "yaw", "rollspeed", "pitchspeed",
                                                                 "yawspeed")],
               _fill_attitude, "MAVLink 2 ATTITUDE (30): roll, pitch, yaw and body rates"),
    NavMessage("mavlink-attitude-quaternion", "ATTITUDE_QUATERNION", 31, 246,
               [("time_boot_ms", "<u4")] + [(f, "<f4") for f in ("q1", "q2", "q3", "q4", "rollspeed", "pitchspeed",
                                                                 "yawspeed")] + [("repr_offset_q", "<f4", (4,))],
               _fill_attitude_quaternion, "MAVLink 2 ATTITUDE_QUATERNION (31): attitude quaternion, body rates"),
)}
NAV_BY_MSGID = {m.msgid: m for m in NAV_MESSAGES.values()}


class MavlinkNavEncoder:
    """Samples -> MAVLink 2 frames of one of NAV_MESSAGES; sequence and signing state continue across calls.

    `encode` returns a SerialBatch with an (empty or one-frame) packet per sample: GNSS messages only where a
    new solution arrived, SCALED_PRESSURE only on the barometer's readings."""
    # Axes: ATTITUDE* are "in the aeronautical frame (right-handed, Z-down, Y-right, X-front)" w.r.t. NED; the GNSS
    # messages' velocities are north, east, down (common.xml). No body vector is carried besides the attitude.
    body_axes, reference = "FRD", "NED"
    axes_source = "MAVLink common.xml: ATTITUDE aeronautical frame (X-front, Y-right, Z-down); HIL_GPS vn/ve/vd"

    uses_navigation = True      # position/velocity/attitude: a device sending it (also=) needs the navigation

    def __init__(self, message: str, sysid: int = 1, compid: int = 1, seq: int = 0, id: int | None = None,
                 signing_key=None, link_id: int = 0, signing_link: SigningLink | None = None, sign_time: str = "wall",
                 truncate: bool = True, baro_rate_hz: float | None = None):
        if message not in NAV_MESSAGES:
            raise ValueError(f"message: unknown {message!r}; known: {', '.join(NAV_MESSAGES)}")
        self.spec = spec = NAV_MESSAGES[message]
        if id is not None and "id" not in spec.dtype.names:
            raise ValueError(f"id: {spec.msg_name} has no id field")
        refuse_retired(baro_rate_hz=baro_rate_hz)
        if sign_time not in ("wall", "sample"):
            raise ValueError(f"sign_time: 'wall' or 'sample', got {sign_time!r}")
        for name, value in (("sysid", sysid), ("compid", compid), ("seq", seq), ("id", id or 0)):
            if not 0 <= int(value) <= 255:
                raise ValueError(f"{name}: must be 0..255, got {value}")
        self.sysid, self.compid, self.seq, self.id = int(sysid), int(compid), int(seq), int(id or 0)
        if signing_link is None and signing_key is not None:
            signing_link = SigningLink(signing_key, link_id)
        self.signing_link = signing_link
        self.sign_time, self.truncate = sign_time, bool(truncate)
        self.saturated = SaturationStats()
        self.bytes_per_sample = HEADER_LEN + spec.payload_len + 2 + (SIGNATURE_LEN if signing_link else 0)

    def _due(self, samples: Samples) -> np.ndarray:
        if self.spec.source == "gnss":
            return new_readings(samples.gnss_new, len(samples))
        if self.spec.source == "baro":
            return new_readings(samples.baro_new, len(samples))
        return np.ones(len(samples), bool)

    def encode(self, samples: Samples) -> SerialBatch:
        n = len(samples)
        samples.require_finite(("gnss_new", "baro_new"))
        due = np.flatnonzero(self._due(samples))
        if not len(due):        # between readings (most samples of a device): nothing to pack or check
            return SerialBatch(b"", np.zeros(n + 1, dtype=np.int64))
        # only what is sent is checked (a GNSS message between fixes or a pressure between readings is not)
        samples.require_finite(_INPUTS[self.spec.source] + ("gyro",), None if len(due) == n else due)
        picked = samples if len(due) == n else samples.rows(due)
        payloads = np.zeros(len(due), dtype=self.spec.dtype)
        for name, values in self.spec.fill(self, picked).items():
            if payloads.dtype[name].kind == "f":
                values = to_float32_field(values, name, self.saturated)     # beyond FLT_MAX: clipped, counted
            payloads[name] = values
        wall = (time.time_ns() - EPOCH_2015_NS) // 10_000
        frames, sizes = [], np.zeros(n, dtype=np.int64)
        raw = payloads.tobytes()
        size = self.spec.payload_len
        for k, i in enumerate(due.tolist()):
            stamp = wall if self.sign_time == "wall" else (int(samples.time_ns[i]) - EPOCH_2015_NS) // 10_000
            frame = pack_frame(self.spec.msgid, self.spec.crc_extra, raw[k * size:(k + 1) * size], self.seq,
                               self.sysid, self.compid, self.signing_link, stamp, self.truncate)
            self.seq = (self.seq + 1) & 0xFF
            frames.append(frame)
            sizes[i] = len(frame)
        offsets = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(sizes, out=offsets[1:])
        return SerialBatch(b"".join(frames), offsets)


_COMMON_OPTIONS = {
    "sysid": "MAVLink system id 0..255", "compid": "MAVLink component id 0..255",
    "seq": "sequence number of the first packet, 0..255; continues across encode calls",
    "signing_key": "32-byte secret key (bytes or 64 hex digits): sign every packet",
    "link_id": "signing link id 0..255", "signing_link": "a SigningLink shared with other encoders on the same link",
    "sign_time": "signing timestamp from 'wall' clock or 'sample' time (time_ns as Unix ns)",
    "truncate": "cut trailing zero payload bytes as MAVLink 2 does",
}
_EXTRA_OPTIONS = {"gnss": {}, "every": {},
                  "baro": {"baro_rate_hz": retired_help("baro_rate_hz")}}

for _spec in NAV_MESSAGES.values():
    register(FormatInfo(
        name=_spec.name, kind="serial", description=_spec.description,
        encoder=functools.partial(MavlinkNavEncoder, _spec.name),
        decoder=functools.partial(MavlinkDecoder, messages={**_BY_MSGID, **NAV_BY_MSGID}),
        bytes_per_sample=HEADER_LEN + _spec.payload_len + 2,
        options={**_COMMON_OPTIONS, **_EXTRA_OPTIONS[_spec.source],
                 **({"id": "GNSS instance id 0..255 (PX4 publishes one sensor_gps per id)"}
                    if "id" in _spec.dtype.names else {})}))
