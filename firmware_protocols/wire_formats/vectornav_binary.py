"""VectorNav (VN-100/200/300) binary output: user-configured packets and their stream decoder (the ASCII
sentences: vectornav_ascii; the replies a driver waits for: firmware_protocols.devices.vectornav).

Binary frame (wire-formats.md, "VectorNav binary output"):

    FA  groups(u8)  mask(u16 LE) per set group bit, ascending  payload(LE)  crc(u16 BIG-endian)

CRC-16/XMODEM over groups .. payload, so a receiver's CRC over groups .. crc is 0. Fields appear in
group-bit, then field-bit order. Field sizes are VectorNav's own `BinaryPacketGroupLengths` table
(vnproglib 1.1, dawonn/vectornav libvnc/src/vnupack.c; the newer libvnc adds Time bits 8-9,
SyncOutCnt 4 and TimeStatus 1). The GPS groups (3 and 6) follow vnproglib 1.2's upack.c (bit 12 TimeInfo 2,
bit 13 DOP 28), the layout ArduPilot's VN-300 GNSS packet assumes; older libraries had SvStat at bit 12.

What the encoder can fill, wire units, and the Samples field each comes from:

    TimeStartup     u64 ns          time_ns - start_ns: since the run's start (the unit's power-up; negative
                                    times saturate to 0, counted)
    YawPitchRoll    3 x f32 deg     euler, reordered yaw, pitch, roll         default 0, 0, 0
    Quaternion      4 x f32         quat, reordered x, y, z, w (scalar LAST)  default identity
    AngularRate,
    UncompGyro      3 x f32 rad/s   gyro
    Accel,
    UncompAccel     3 x f32 m/s^2   accel
    Mag, UncompMag  3 x f32 gauss   mag                                       default 0, 0, 0
    Temp            f32 degC        temperature_c                             default 25
    Pres            f32 kPa         pressure_pa / 1000                        default 101.325
    Common.Imu      UncompAccel + UncompGyro;  Common.MagPres  Mag + Temp + Pres
    IMU.DeltaTheta  f32 s + 3 x f32 deg   delta_time_s (else `sample_period_s`, else the time since the
                                    previous sample), delta_theta (required: no rate x dt stand-in)
    IMU.DeltaVel    3 x f32 m/s     delta_velocity (required)
    Common.DeltaTheta  IMU.DeltaTheta + IMU.DeltaVel
    TimeGps         u64 ns          GPS time of time_ns (UTC Unix ns + 18 leap seconds - the GPS epoch,
                                    firmware_protocols.gnss_time); Time.GpsTow u64 ns and Time/GPS Week u16
                                    split it; before 1980-01-06 they clip to 0 (counted)
    TimeUtc, GPS Utc  i8 year-2000, u8 month, day, hour, minute, second, u16 ms: GPS time - 18 leap seconds
    TimeGpsPps,     u64 ns          ns since the last PPS edge, on whole GPS seconds; the SyncIn pin is taken as
    TimeSyncIn                      wired to the PPS, so TimeSyncIn is the same and
    SyncInCnt       u32             counts the edges since start-up (whole seconds of TimeStartup); SyncOutCnt 0
    TimeStatus, GPS TimeInfo  u8 7 (time of week, week, UTC valid; 0 without any fix) [+ i8 leap seconds 18]
    Common.Position = INS.PosLla  3 x f64 deg, deg, m    position_llh (the INS estimate)   default PX4's home
    Common.Velocity = INS.VelNed  3 x f32 m/s            velocity_ned                     default 0
    InsStatus       u16             bits 0-1 ins_mode (0 not tracking, 1 aligning, 2 tracking), bit 2 a 3D GNSS fix
                                    (gnss_fix >= 3)                                    default 0x0006
    INS.PosEcef     3 x f64 m       position_llh in WGS-84 ECEF (closed form)
    INS.VelEcef, VelBody  3 x f32   velocity_ned in ECEF / in body axes (quat)
    INS.AccelEcef, MagEcef  3 x f32 accel (specific force, "with gravity") / mag rotated body -> NED -> ECEF
    INS.LinearAccelEcef  3 x f32    linear_accel_ned in ECEF; Attitude.LinearAccelBody: in body axes
    Attitude.AccelNed, MagNed  3 x f32  accel / mag rotated into NED
    YprU            3 x f32 deg     attitude_sigma_rad reordered yaw, pitch, roll      default 1, 0.5, 0.5
    INS.PosU, VelU  f32 m, m/s      the root sum of squares of position_sigma_m / velocity_sigma_mps  default 1, 0.05
    GPS, GPS2       the receiver: NumSats u8 gnss_satellites, Fix u8 gnss_fix, PosLla 3 x f64 gnss_llh, PosEcef,
                    VelNed 3 x f32 gnss_velocity_ned, VelEcef, PosU 3 x f32 (N, E = gnss_horizontal_accuracy_m,
                    D = gnss_vertical_accuracy_m), VelU f32 gnss_speed_accuracy_mps, TimeU f32 s, Dop 7 x f32 (g, p,
                    t, v, h, n, e from gnss_hdop / gnss_vdop); without gnss_* the INS estimate and GNSS_CONSTANTS
                    (BinaryEncoder(constants=...), defaults in _DEFAULTS)
    ImuStatus, SensSat  u16 0       (reserved; no sensor saturated: saturation is counted at the wire instead)

Frames: vectors in Samples are the part's body axes forward-right-down and quat rotates them to NED, which is
VectorNav's own convention, so they go out unconverted; the derived quantities: firmware_protocols.
vectornav_quantities. A quantity the samples do not carry uses the documented default (or the caller's
constant), never a failure.

A real unit resets its integrals at each output, so with an output divider its increments span several IMU
samples; the encoder sends what it is given, one sample's increments per packet.

The emulator has one accel/gyro/mag measurement, so the "uncompensated" fields carry the same values
as the compensated ones. Every f32 saturates at +-float32 max, every integer at its range (counted per wire
field in `encoder.saturated`, e.g. "imu.accel"); non-finite input raises EncodeError naming field and sample.
Fields the table knows but the emulator has no data for (Attitude Dcm, IMU Raw) can be decoded (as raw bytes)
but not selected for encoding.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

from imu_emulator.native.lazy import jit
import numpy as np

from firmware_protocols.base import (DecoderStats, EncodeError, Packet, SaturationStats, Samples,
                                     SerialBatch, integration_intervals)
from firmware_protocols.crc import crc16_ccitt, crc16_ccitt_bytes
from firmware_protocols.gnss_time import GNSS_DEFAULTS, GPS_WEEK_OFFSET_RETIRED, dops, gps_offset_ns
from firmware_protocols import vectornav_quantities
from firmware_protocols.registry import FormatInfo, register
from firmware_protocols.vectornav_common import DEG, SAMPLE_DEFAULTS

SYNC = 0xFA

# --- field table -----------------------------------------------------------------------------

# Samples sources the packing kernel can read; the index is what the kernel switches on.
_SOURCES = ("time_ns", "accel", "gyro", "mag", "quat", "euler", "temperature_c", "pressure_pa", "extra")
_SOURCE_ID = {name: i for i, name in enumerate(_SOURCES)}
# Navigation and status quantities: packed side by side into the kernel's one "extra" matrix (only when a
# layout asks for them). Name -> width. Samples fields where Samples has them, quantities computed from the samples
# (_DERIVED), else the documented defaults / the caller's constants.
_EXTRA_WIDTH = {"position_llh": 3, "velocity_ned": 3, "linear_accel_ned": 3, "ypr_u": 3, "ins_status": 1,
                "pos_u": 1, "vel_u": 1, "delta_time": 1, "delta_theta": 3, "delta_velocity": 3,
                "gnss_num_sats": 1, "gnss_fix": 1, "gnss_pos_u": 3, "gnss_vel_u": 1, "gnss_dop": 7,
                "gnss_llh": 3, "gnss_velocity_ned": 3, "gnss_pos_ecef": 3, "gnss_vel_ecef": 3, "gnss_time_u": 1,
                "gnss_time_info": 2, "pos_ecef": 3, "vel_ecef": 3, "vel_body": 3, "accel_ned": 3, "mag_ned": 3,
                "accel_ecef": 3, "mag_ecef": 3, "lin_accel_ecef": 3, "lin_accel_body": 3, "utc": 7,
                "time_status": 1, "since_pps": 1, "sync_in_count": 1, "sync_out_count": 1, "zero_word": 1}
#: extras without a default: the caller must give them (the integrated outputs; a rate times the period would
#: be an approximation the field's name does not announce)
_REQUIRED = {"delta_theta", "delta_velocity"}
#: the constants a caller may set (BinaryEncoder(constants=...)): what the samples may not carry
_SETTABLE = ("ypr_u", "ins_status", "pos_u", "vel_u", "gnss_num_sats", "gnss_fix", "gnss_pos_u", "gnss_vel_u",
             "gnss_dop")
# Kernel wire codes: value kinds f32, f64, u16, u8; and integer times made from time_ns (+ the GPS offset).
_WIRE_CODE = {"f": 0, "Q": 1, "d": 2, "H": 3, "B": 4}
# Integers made from a value (extras): u32, u64 (exact below 2^53), i8.
_VALUE_CODE = {"f": 0, "d": 2, "H": 3, "B": 4, "I": 8, "Q": 9, "b": 10}
_TIME_CODE = {"startup": 1, "gps": 7, "tow": 5, "week": 6}


# Documented defaults for the navigation and status quantities (one row, broadcast), after those of Samples.
_DEFAULTS = {
    **SAMPLE_DEFAULTS,
    # Until the scene has an origin the streaming side places it at PX4 SITL's default home (Zurich):
    # a device asked for position without any truth at all reports that point, at rest.
    "position_llh": (47.397742, 8.545594, 488.0),
    "velocity_ned": (0.0, 0.0, 0.0),
    "linear_accel_ned": (0.0, 0.0, 0.0),
    # Uncertainties a healthy VN-300 INS reports (1 sigma): yaw, pitch, roll deg; position m; velocity m/s.
    "ypr_u": (1.0, 0.5, 0.5),
    "pos_u": (1.0,),
    "vel_u": (0.05,),
    # INS status: mode 2 (INS tracking, bits 0-1) + GNSS fix (bit 2), no error bits: 0x0006.
    "ins_status": (6.0,),
    # A healthy receiver under open sky (firmware_protocols.gnss_time): 3D fix (vnproglib GPSFIX_3D = 3;
    # ArduPilot's pre-arm wants >= 3), satellites, 1 sigma position N, E, D m and speed m/s, consistent DOPs.
    "gnss_num_sats": (float(GNSS_DEFAULTS["num_sats"]),),
    "gnss_fix": (float(GNSS_DEFAULTS["fix_type"]),),
    "gnss_pos_u": (1.0, 1.0, 1.5),
    "gnss_vel_u": (0.05,),
    "gnss_dop": dops(GNSS_DEFAULTS["dop_n"], GNSS_DEFAULTS["dop_e"], GNSS_DEFAULTS["dop_v"], GNSS_DEFAULTS["dop_t"]),
    # GPS TimeU (s); SyncOutCnt: the SyncOut pin is not configured (register 32)
    "gnss_time_u": (GNSS_DEFAULTS["t_acc_ns"] * 1e-9,),
    "sync_out_count": (0.0,),
    # IMU ImuStatus (reserved) and SensSat (no sensor saturated: saturation is counted at the wire instead)
    "zero_word": (0.0,),
}
GNSS_CONSTANTS = ("gnss_num_sats", "gnss_fix", "gnss_pos_u", "gnss_vel_u", "gnss_dop")


def _derived():
    """name -> f(samples, encoder) giving the (n, width) quantity from the samples, or None (then the default or
    the caller's constant). See firmware_protocols.vectornav_quantities for the frames and time conventions."""
    vq = vectornav_quantities

    def default(enc):
        return lambda name: enc._defaults[name][0]

    def fix_default(enc):
        return float(enc._defaults["gnss_fix"][0, 0])

    return {
        "ypr_u": lambda s, e: vq.ypr_uncertainty(s),
        "pos_u": lambda s, e: vq.sigma_norm(s.position_sigma_m),
        "vel_u": lambda s, e: vq.sigma_norm(s.velocity_sigma_mps),
        # a caller's ins_status constant stands while the samples carry neither mode nor fix
        "ins_status": lambda s, e: None if ("ins_status" in e._constants and s.ins_mode is None
                                            and s.gnss_fix is None) else vq.ins_status(s, fix_default(e)),
        "gnss_num_sats": lambda s, e: s.gnss_satellites,
        "gnss_pos_u": lambda s, e: vq.gnss_position_uncertainty(s),
        "gnss_vel_u": lambda s, e: s.gnss_speed_accuracy_mps,
        "gnss_dop": lambda s, e: vq.gnss_dops(s),
        "gnss_llh": lambda s, e: vq.position(s, default(e), "gnss_llh"),
        "gnss_velocity_ned": lambda s, e: vq.velocity(s, default(e), "gnss_velocity_ned"),
        "gnss_pos_ecef": lambda s, e: vq.ecef_position(vq.position(s, default(e), "gnss_llh")),
        "gnss_vel_ecef": lambda s, e: vq.ecef_vector(s, vq.velocity(s, default(e), "gnss_velocity_ned"), default(e),
                                                     "gnss_llh"),
        "pos_ecef": lambda s, e: vq.ecef_position(vq.position(s, default(e))),
        "vel_ecef": lambda s, e: vq.ecef_vector(s, vq.velocity(s, default(e)), default(e)),
        "vel_body": lambda s, e: vq.rotated(s, "velocity_ned", default(e), "body"),
        "accel_ned": lambda s, e: vq.rotated(s, "accel", default(e), "ned"),
        "mag_ned": lambda s, e: vq.rotated(s, "mag", default(e), "ned"),
        "accel_ecef": lambda s, e: vq.rotated(s, "accel", default(e), "ecef"),
        "mag_ecef": lambda s, e: vq.rotated(s, "mag", default(e), "ecef"),
        "lin_accel_ecef": lambda s, e: vq.ecef_vector(
            s, s.linear_accel_ned if s.linear_accel_ned is not None
            else np.broadcast_to(e._defaults["linear_accel_ned"], (len(s), 3)), default(e)),
        "lin_accel_body": lambda s, e: vq.rotated(s, "linear_accel_ned", default(e), "body"),
        "utc": lambda s, e: vq.utc_fields(s.time_ns, e.gps_offset_ns),
        "time_status": lambda s, e: vq.time_valid(s, fix_default(e)).reshape(-1, 1),
        "gnss_time_info": lambda s, e: np.column_stack(
            (vq.time_valid(s, fix_default(e)), np.full(len(s), float(vectornav_quantities.LEAP_SECONDS)))),
        "since_pps": lambda s, e: vq.since_pps(s.time_ns, e.gps_offset_ns),
        "sync_in_count": lambda s, e: vq.sync_in_count(s.time_ns - s.start_ns),
    }


_DERIVED = _derived()


@dataclass(frozen=True)
class _Quantity:
    """One physical quantity inside a wire field: `order[k]` is the Samples component written k-th."""

    label: str          # key suffix in decoded packets ("" when the field holds one quantity)
    source: str         # Samples attribute
    order: tuple        # Samples component index for each wire slot
    scale: float        # wire value = SI value * scale
    wire: str           # struct code: "Q" (u64), "f" (f32), "d" (f64), "H" (u16), "B" (u8)
    time: str = ""      # integer time from time_ns: "startup", "gps" (ns), "tow" (ns into the week), "week"


@dataclass(frozen=True)
class _Field:
    group: str
    name: str
    bit: int
    size: int
    quantities: tuple = ()      # empty: decode-only, kept as raw bytes

    @property
    def key(self) -> str:
        return f"{self.group}.{self.name.lower()}"


def _q(source, n=3, order=None, scale=1.0, label="", wire="f", time=""):
    return _Quantity(label, source, tuple(order if order is not None else range(n)), scale, wire, time)


_TIME = (_q("time_ns", 1, wire="Q", time="startup"),)
# GPS time of time_ns (firmware_protocols.gnss_time), as u64 ns since the GPS epoch (ArduPilot divides it into week
# and time of week), the same split as u64 ns into the week and u16 week.
_GPS_TIME = (_q("time_ns", 1, wire="Q", time="gps"),)
_GPS_TOW = (_q("time_ns", 1, wire="Q", time="tow"),)
_GPS_WEEK = (_q("time_ns", 1, wire="H", time="week"),)
_NUM_SATS = (_q("gnss_num_sats", 1, wire="B"),)
_GNSS_FIX = (_q("gnss_fix", 1, wire="B"),)
_GNSS_POS_U = (_q("gnss_pos_u"),)
_GNSS_VEL_U = (_q("gnss_vel_u", 1),)
_DOP = (_q("gnss_dop", 7),)
_YPR = (_q("euler", order=(2, 1, 0), scale=DEG),)
_QUAT = (_q("quat", order=(1, 2, 3, 0)),)
_GYRO = (_q("gyro"),)
_ACCEL = (_q("accel"),)
_MAG = (_q("mag"),)
_TEMP = (_q("temperature_c", 1),)
_PRES = (_q("pressure_pa", 1, scale=1e-3),)
_LLA = (_q("position_llh", wire="d"),)
_VEL_NED = (_q("velocity_ned"),)
_LIN_ACC_NED = (_q("linear_accel_ned"),)
_YPR_U = (_q("ypr_u"),)
_INS_STATUS = (_q("ins_status", 1, wire="H"),)
_POS_U = (_q("pos_u", 1),)
_VEL_U = (_q("vel_u", 1),)
# DeltaTheta: dtime (s, the period integrated over) then the angles in DEGREES; DeltaVel m/s (vnproglib's
# VnUartPacket parsing of IMUGROUP_DELTATHETA / DELTAVEL; VectorNav's field description via INSTINCT).
_DTHETA = (_q("delta_time", 1, label="dtime"), _q("delta_theta", scale=DEG, label="dtheta"))
_DVEL = (_q("delta_velocity"),)
# Time and counters (vectornav_quantities): TimeSyncIn / TimeGpsPps u64 ns since the PPS edge, SyncInCnt /
# SyncOutCnt u32, TimeStatus u8, TimeUtc int8 year - 2000, u8 month, day, hour, minute, second, u16 ms
# (vnproglib's TimeUtc struct).
_SINCE_PPS = (_q("since_pps", 1, wire="Q"),)
_SYNC_IN_COUNT = (_q("sync_in_count", 1, wire="I"),)
_SYNC_OUT_COUNT = (_q("sync_out_count", 1, wire="I"),)
_TIME_STATUS = (_q("time_status", 1, wire="B"),)
_UTC = ((_q("utc", 1, order=(0,), wire="b", label="year"),)
        + tuple(_q("utc", 1, order=(k,), wire="B", label=name)
                for k, name in enumerate(("month", "day", "hour", "minute", "second"), start=1))
        + (_q("utc", 1, order=(6,), wire="H", label="ms"),))
_ZERO_WORD = (_q("zero_word", 1, wire="H"),)
# GNSS receiver: its own solution (Samples.gnss_*, else the INS estimate), ECEF from it; TimeU s; TimeInfo
# status u8 + leap seconds i8
_GNSS_LLA = (_q("gnss_llh", wire="d"),)
_GNSS_VEL_NED = (_q("gnss_velocity_ned"),)
_GNSS_POS_ECEF = (_q("gnss_pos_ecef", wire="d"),)
_GNSS_VEL_ECEF = (_q("gnss_vel_ecef"),)
_GNSS_TIME_U = (_q("gnss_time_u", 1),)
_GNSS_TIME_INFO = (_q("gnss_time_info", 1, order=(0,), wire="B", label="status"),
                   _q("gnss_time_info", 1, order=(1,), wire="b", label="leapseconds"))
# INS estimate in ECEF / body axes, attitude group's NED vectors (vectornav_quantities)
_POS_ECEF = (_q("pos_ecef", wire="d"),)
_VEL_ECEF = (_q("vel_ecef"),)
_VEL_BODY = (_q("vel_body"),)
_ACCEL_NED = (_q("accel_ned"),)
_MAG_NED = (_q("mag_ned"),)
_ACCEL_ECEF = (_q("accel_ecef"),)
_MAG_ECEF = (_q("mag_ecef"),)
_LIN_ACC_ECEF = (_q("lin_accel_ecef"),)
_LIN_ACC_BODY = (_q("lin_accel_body"),)


def _lbl(quantities, label):
    return tuple(_Quantity(label, q.source, q.order, q.scale, q.wire, q.time) for q in quantities)


# GPS group (VN-200/300 receiver 1; group 6 is receiver 2, same fields). Bits: vnproglib 1.2 GPSGROUP_*
# (UTC, Tow, Week, NumSats, Fix, PosLla, PosEcef, VelNed, VelEcef, PosU, VelU, TimeU, TimeInfo, DOP); sizes:
# its upack.c BinaryPacketGroupLengths row 4 {8, 8, 2, 1, 1, 24, 24, 12, 12, 12, 4, 4, 2, 28}. PosU is N, E, D
# (ArduPilot reads [0] as horizontal, [2] as vertical accuracy), DOP is g, p, t, v, h, n, e. Position and
# velocity are the truth the INS group reports too (a receiver without noise), from the same sources.
_GPS_FIELDS = [
    ("Utc", 8, _UTC), ("Tow", 8, _GPS_TOW), ("Week", 2, _GPS_WEEK), ("NumSats", 1, _NUM_SATS), ("Fix", 1, _GNSS_FIX),
    ("PosLla", 24, _GNSS_LLA), ("PosEcef", 24, _GNSS_POS_ECEF), ("VelNed", 12, _GNSS_VEL_NED),
    ("VelEcef", 12, _GNSS_VEL_ECEF), ("PosU", 12, _GNSS_POS_U), ("VelU", 4, _GNSS_VEL_U), ("TimeU", 4, _GNSS_TIME_U),
    ("TimeInfo", 2, _GNSS_TIME_INFO), ("Dop", 28, _DOP)]


# (group name, group bit, [(field name, size, quantities)] in field-bit order). Sizes: vnupack.c
# BinaryPacketGroupLengths (see module docstring); names: VectorNav's COMMONGROUP_*/TIMEGROUP_*/...
# enums in the same library and PX4/ArduPilot drivers.
_GROUP_TABLE = (
    ("common", 0, [
        ("TimeStartup", 8, _TIME), ("TimeGps", 8, _GPS_TIME), ("TimeSyncIn", 8, _SINCE_PPS),
        ("YawPitchRoll", 12, _YPR), ("Quaternion", 16, _QUAT), ("AngularRate", 12, _GYRO), ("Position", 24, _LLA),
        ("Velocity", 12, _VEL_NED),
        ("Accel", 12, _ACCEL), ("Imu", 24, _lbl(_ACCEL, "accel") + _lbl(_GYRO, "gyro")),
        ("MagPres", 20, _lbl(_MAG, "mag") + _lbl(_TEMP, "temperature_c") + _lbl(_PRES, "pressure_pa")),
        ("DeltaTheta", 28, _DTHETA + _lbl(_DVEL, "dvel")), ("InsStatus", 2, _INS_STATUS),
        ("SyncInCnt", 4, _SYNC_IN_COUNT), ("TimeGpsPps", 8, _SINCE_PPS)]),
    ("time", 1, [
        ("TimeStartup", 8, _TIME), ("TimeGps", 8, _GPS_TIME), ("GpsTow", 8, _GPS_TOW), ("GpsWeek", 2, _GPS_WEEK),
        ("TimeSyncIn", 8, _SINCE_PPS), ("TimeGpsPps", 8, _SINCE_PPS), ("TimeUtc", 8, _UTC),
        ("SyncInCnt", 4, _SYNC_IN_COUNT), ("SyncOutCnt", 4, _SYNC_OUT_COUNT), ("TimeStatus", 1, _TIME_STATUS)]),
    ("imu", 2, [
        ("ImuStatus", 2, _ZERO_WORD), ("UncompMag", 12, _MAG), ("UncompAccel", 12, _ACCEL),
        ("UncompGyro", 12, _GYRO),
        ("Temp", 4, _TEMP), ("Pres", 4, _PRES), ("DeltaTheta", 16, _DTHETA), ("DeltaVel", 12, _DVEL), ("Mag", 12, _MAG),
        ("Accel", 12, _ACCEL), ("AngularRate", 12, _GYRO), ("SensSat", 2, _ZERO_WORD), ("Raw", 40, ())]),
    ("gps", 3, _GPS_FIELDS),
    # Attitude bits 9-11 exist on some units but their names and sizes vary by library version.
    ("attitude", 4, [
        ("VpeStatus", 2, ()), ("YawPitchRoll", 12, _YPR), ("Quaternion", 16, _QUAT), ("Dcm", 36, ()),
        ("MagNed", 12, _MAG_NED), ("AccelNed", 12, _ACCEL_NED), ("LinearAccelBody", 12, _LIN_ACC_BODY),
        ("LinearAccelNed", 12, _LIN_ACC_NED),
        ("YprU", 12, _YPR_U)]),
    # INS group: vnproglib 1.1 vnenum.h INSGROUP_* bits and vnupack.c sizes; PosLla is 3 x f64 (deg, deg, m).
    ("ins", 5, [
        ("InsStatus", 2, _INS_STATUS), ("PosLla", 24, _LLA), ("PosEcef", 24, _POS_ECEF), ("VelBody", 12, _VEL_BODY),
        ("VelNed", 12, _VEL_NED), ("VelEcef", 12, _VEL_ECEF), ("MagEcef", 12, _MAG_ECEF),
        ("AccelEcef", 12, _ACCEL_ECEF), ("LinearAccelEcef", 12, _LIN_ACC_ECEF), ("PosU", 4, _POS_U),
        ("VelU", 4, _VEL_U)]),
    ("gps2", 6, _GPS_FIELDS),
)

_GROUP_BIT = {name: bit for name, bit, _ in _GROUP_TABLE}
_FIELDS = {bit: {fbit: _Field(gname, fname, fbit, size, qs) for fbit, (fname, size, qs) in enumerate(fields)}
           for gname, bit, fields in _GROUP_TABLE}
_BY_NAME = {gname: {f.name.lower(): f for f in _FIELDS[bit].values()} for gname, bit, _ in _GROUP_TABLE}

for _bit, _fields in _FIELDS.items():   # the table is transcribed by hand: keep it honest
    for _f in _fields.values():
        assert not _f.quantities or _f.size == sum(struct.calcsize(q.wire) * len(q.order) for q in _f.quantities), _f

DEFAULT_FIELDS = "time:timestartup;imu:accel,angularrate"
# PX4's binary output 1 (src/drivers/ins/vectornav/VectorNav.cpp). Most revisions of that driver ask for
# IMU Accel|AngularRate (the spec's vector); one asks for UncompAccel|UncompGyro instead: pass
# fields="time:timestartup;imu:uncompaccel,uncompgyro" to emulate that one.


# --- layout ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Layout:
    """One binary output configuration: which fields, in wire order, and the header announcing them."""

    groups: int
    masks: tuple            # one u16 per set group bit, ascending
    fields: tuple           # _Field in wire order

    @property
    def header(self) -> bytes:
        return bytes([self.groups]) + b"".join(struct.pack("<H", m) for m in self.masks)

    @property
    def payload_size(self) -> int:
        return sum(f.size for f in self.fields)

    @property
    def packet_size(self) -> int:
        return 1 + len(self.header) + self.payload_size + 2


def _layout_from_selection(selection: dict) -> Layout:
    """{group bit: field-bit mask} -> Layout; None when a bit is outside the known table."""
    groups, masks, fields = 0, [], []
    for gbit in sorted(selection):
        mask = selection[gbit]
        if gbit not in _FIELDS or mask == 0:
            return None
        groups |= 1 << gbit
        masks.append(mask)
        for fbit in range(16):
            if mask >> fbit & 1:
                if fbit not in _FIELDS[gbit]:
                    return None
                fields.append(_FIELDS[gbit][fbit])
    return Layout(groups, tuple(masks), tuple(fields))


def every_field_layout(increments: bool = True) -> Layout:
    """A layout with every field the emulator sends (those with quantities behind them), of every group; without
    the integrated outputs (DeltaTheta, DeltaVel) when the samples carry none."""
    return parse_fields({gname: [fname for fname, _, quantities in fields
                                 if quantities and (increments or not fname.startswith("Delta"))]
                         for gname, _, fields in _GROUP_TABLE})


def parse_fields(fields) -> Layout:
    """A field selection -> Layout. Accepts a spec string "common:timestartup,accel;imu:uncompgyro",
    a dict {group: [field names] or int mask}, or a Layout. Names are case-insensitive; order given
    does not matter (the wire order is fixed by the bits)."""
    if fields is None:
        fields = DEFAULT_FIELDS
    if isinstance(fields, Layout):
        return fields
    if isinstance(fields, str):
        parsed = {}
        for part in filter(None, (p.strip() for p in fields.split(";"))):
            group, sep, names = part.partition(":")
            if not sep:
                raise ValueError(f"VectorNav fields: expected 'group:field,field' but got {part!r}")
            parsed.setdefault(group.strip(), []).extend(n.strip() for n in names.split(",") if n.strip())
        fields = parsed
    if not isinstance(fields, dict) or not fields:
        raise ValueError(f"VectorNav fields: expected a spec string or a dict of groups, got {fields!r}")
    selection = {}
    for group, names in fields.items():
        gname = str(group).strip().lower()
        if gname not in _BY_NAME:
            raise ValueError(f"VectorNav fields: unknown group {group!r} (known: {', '.join(_BY_NAME)})")
        gbit = _GROUP_BIT[gname]
        if isinstance(names, (int, np.integer)):
            known = sum(1 << b for b in _FIELDS[gbit])
            if not 0 < int(names) <= 0xFFFF or int(names) & ~known:
                raise ValueError(f"VectorNav fields: mask {int(names):#06x} has bits outside group {gname!r}")
            chosen = [_FIELDS[gbit][b] for b in _FIELDS[gbit] if int(names) >> b & 1]
        else:
            if isinstance(names, str):
                names = [names]
            chosen = []
            for name in names:
                field = _BY_NAME[gname].get(str(name).strip().lower())
                if field is None:
                    raise ValueError(f"VectorNav fields: unknown field {name!r} in group {gname!r} "
                                     f"(known: {', '.join(_BY_NAME[gname])})")
                chosen.append(field)
        if not chosen:
            raise ValueError(f"VectorNav fields: group {gname!r} selects no field")
        selection[gbit] = selection.get(gbit, 0) | sum(1 << f.bit for f in chosen)
    return _layout_from_selection(selection)


# --- binary encoder --------------------------------------------------------------------------

@jit(cache=True, nogil=True)
def _pack(out, size, header, items, scales, time_ns, accel, gyro, mag, quat, euler, temp, pres, extra, steps, sat,
          gps_offset_ns, startup_ns):
    """Write len(time_ns) packets of `size` bytes into `out`. items[j] = (source id, column, wire type
    0 f32 / 1 u64 time / 2 f64 / 3 u16 / 4 u8 / 5 u64 GPS time of week / 6 u16 GPS week / 7 u64 GPS time /
    8 u32 / 9 u64 / 10 i8, the last three from a value) in wire order. Returns the first sample with a
    non-finite value, or -1."""
    scratch = np.empty(1, np.float32)
    bits = scratch.view(np.uint32)
    scratch64 = np.empty(1, np.float64)
    bits64 = scratch64.view(np.uint64)
    n_head = header.shape[0]
    for i in range(time_ns.shape[0]):
        base = i * size
        out[base] = 0xFA
        for h in range(n_head):
            out[base + 1 + h] = header[h]
        p = base + 1 + n_head
        for j in range(items.shape[0]):
            src = items[j, 0]
            kind = items[j, 2]
            if kind == 1 or 5 <= kind <= 7:
                # TimeStartup counts since the run's start; the GPS times are UTC Unix time + gps_offset_ns (< 0).
                # `zero` is the time_ns that goes out as 0; earlier ones clip to it (compared first: no overflow)
                t = time_ns[i]
                zero = startup_ns if kind == 1 else -gps_offset_ns
                if t < zero:
                    t = 0
                    sat[j] += 1
                else:
                    t -= zero
                if kind == 6:
                    week = t // 604800000000000
                    if week > 65535:
                        week = 65535
                        sat[j] += 1
                    out[p] = week & 0xFF
                    out[p + 1] = (week >> 8) & 0xFF
                    p += 2
                    continue
                if kind == 5:
                    t = t % 604800000000000
                for b in range(8):
                    out[p + b] = (t >> (8 * b)) & 0xFF
                p += 8
                continue
            col = items[j, 1]
            if src == 1:
                v = accel[i * steps[1], col]
            elif src == 2:
                v = gyro[i * steps[2], col]
            elif src == 3:
                v = mag[i * steps[3], col]
            elif src == 4:
                v = quat[i * steps[4], col]
            elif src == 5:
                v = euler[i * steps[5], col]
            elif src == 6:
                v = temp[i * steps[6], col]
            elif src == 7:
                v = pres[i * steps[7], col]
            else:
                v = extra[i * steps[8], col]
            if not np.isfinite(v):
                return i
            v *= scales[j]
            if kind == 2:
                scratch64[0] = v
                w = bits64[0]
                for b in range(8):
                    out[p + b] = (w >> np.uint64(8 * b)) & np.uint64(0xFF)
                p += 8
                continue
            if kind >= 8:       # integers from a value: u32, u64, i8 (rounded, saturated and counted)
                lo, top, width = 0.0, 4294967295.0, 4
                if kind == 9:
                    top, width = 9007199254740992.0, 8
                elif kind == 10:
                    lo, top, width = -128.0, 127.0, 1
                if v < lo or v > top:
                    sat[j] += 1
                    v = min(max(v, lo), top)
                word = int(np.rint(v))
                if word < 0:
                    word += 256
                for b in range(width):
                    out[p + b] = (word >> (8 * b)) & 0xFF
                p += width
                continue
            if kind == 3 or kind == 4:
                top = 65535.0 if kind == 3 else 255.0
                if v < 0.0 or v > top:
                    sat[j] += 1
                    v = min(max(v, 0.0), top)
                word = int(np.rint(v))
                out[p] = word & 0xFF
                p += 1
                if kind == 3:
                    out[p] = (word >> 8) & 0xFF
                    p += 1
                continue
            if v > 3.4028234663852886e38:
                v = 3.4028234663852886e38
                sat[j] += 1
            elif v < -3.4028234663852886e38:
                v = -3.4028234663852886e38
                sat[j] += 1
            scratch[0] = v
            u = bits[0]
            out[p] = u & 0xFF
            out[p + 1] = (u >> 8) & 0xFF
            out[p + 2] = (u >> 16) & 0xFF
            out[p + 3] = (u >> 24) & 0xFF
            p += 4
        crc = crc16_ccitt(out, base + 1, base + size - 2, 0)
        out[base + size - 2] = (crc >> 8) & 0xFF
        out[base + size - 1] = crc & 0xFF
    return -1


def _constant(name: str, value) -> np.ndarray:
    """A validated one-row value for a quantity no Samples field carries."""
    if name not in _SETTABLE:
        raise ValueError(f"VectorNav constants: {name!r} is not a settable quantity (settable: {', '.join(_SETTABLE)})")
    row = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if row.shape != (_EXTRA_WIDTH[name],) or not np.isfinite(row).all():
        raise ValueError(f"{name}: expected {_EXTRA_WIDTH[name]} finite number(s), got {value!r}")
    return row.reshape(1, -1)


class BinaryEncoder:
    """Samples -> VectorNav binary packets for one output configuration (`fields`, see parse_fields)."""
    # Axes: yaw/pitch/roll and the quaternion describe "the body frame with respect to the local North East Down
    # (NED) frame" (VN-100 User Manual UM001 §4.4.3-4.4.4), and accel/gyro are "expressed in the body frame" (§4.4.5):
    # a unit level and facing north reads yaw, pitch, roll 0 only if its body axes are x forward, y right, z down.
    # Samples are already so.
    body_axes, reference = "FRD", "NED"
    axes_source = "VN-100 User Manual UM001 4.4.3-4.4.5: body frame w.r.t. NED (so x fwd, y right, z down)"


    def __init__(self, fields=None, sample_period_s: float | None = None, gps_week_offset=None,
                 constants: dict | None = None):
        """`constants`: values for the quantities no Samples field carries (GNSS_CONSTANTS, the INS uncertainties
        and status), replacing the documented defaults. `gps_week_offset` is retired (a one-line error naming
        --start-time): GPS time follows time_ns, UTC since the Unix epoch (firmware_protocols.gnss_time)."""
        self.layout = parse_fields(fields)
        if sample_period_s is not None and not (np.isfinite(sample_period_s) and sample_period_s > 0):
            raise ValueError(f"sample_period_s must be a positive number, got {sample_period_s}")
        self.sample_period_s = sample_period_s
        self._last_time_ns = None
        if gps_week_offset is not None:
            raise ValueError(GPS_WEEK_OFFSET_RETIRED)
        self.gps_offset_ns = gps_offset_ns(vectornav_quantities.LEAP_SECONDS)    # GPS time - time_ns (negative)
        undecodable = [f.key for f in self.layout.fields if not f.quantities]
        if undecodable:
            raise ValueError(f"VectorNav fields: the emulator has no data for {', '.join(undecodable)}")
        self.bytes_per_sample = self.layout.packet_size
        self.saturated = SaturationStats()
        rows, scales, self._item_field = [], [], []
        self._extra_base = {}     # extra source -> first column in the extra matrix
        for field in self.layout.fields:
            for q in field.quantities:
                for col in q.order:
                    if q.source in _EXTRA_WIDTH:
                        if q.source not in self._extra_base:
                            self._extra_base[q.source] = sum(_EXTRA_WIDTH[e] for e in self._extra_base)
                        rows.append((_SOURCE_ID["extra"], self._extra_base[q.source] + col, _VALUE_CODE[q.wire]))
                    else:
                        code = _TIME_CODE[q.time] if q.time else _WIRE_CODE[q.wire]
                        rows.append((_SOURCE_ID[q.source], col, code))
                    scales.append(q.scale)
                    self._item_field.append(field.key)
        self._items = np.array(rows, dtype=np.int64).reshape(-1, 3)
        self._scales = np.array(scales, dtype=np.float64)
        self._header = np.frombuffer(self.layout.header, dtype=np.uint8).copy()
        self._sources = sorted({q.source for f in self.layout.fields for q in f.quantities}
                               - {"time_ns"} - set(_EXTRA_WIDTH))
        self.uses_increments = bool(_REQUIRED & set(self._extra_base))
        self._defaults = {name: np.array([value], dtype=np.float64) for name, value in _DEFAULTS.items()}
        for name, value in (constants or {}).items():
            self._defaults[name] = _constant(name, value)
        self._constants = frozenset(constants or ())
        self._unused = np.zeros((1, 4), dtype=np.float64)
        self._offsets = np.zeros(1, dtype=np.int64)   # reused while block sizes repeat (the live path)

    def _columns(self, samples: Samples):
        """Each kernel source as a 2-D array plus its row step (0: one default row for every sample).
        Sources the layout does not use get a dummy row the kernel never reads."""
        arrays = [self._unused] * (len(_SOURCES) - 1)
        steps = np.zeros(len(_SOURCES), dtype=np.int64)
        for name in self._sources:
            k = _SOURCE_ID[name]
            value = getattr(samples, name)
            if value is None:
                value = self._defaults[name]
            else:
                steps[k] = 1
                if value.ndim == 1:
                    value = value.reshape(-1, 1)
            arrays[k - 1] = value
        if self._extra_base:
            parts = []
            for name in self._extra_base:
                value = _DERIVED[name](samples, self) if name in _DERIVED else getattr(samples, name, None)
                if name == "delta_time":
                    value = integration_intervals(samples, self.sample_period_s, self._last_time_ns)
                elif value is None and name in _REQUIRED:
                    raise EncodeError(f"VectorNav fields {', '.join(self._fields_reading(name))}: the samples "
                                      f"carry no {name} (integrated outputs: run with increments)")
                parts.append(self._defaults[name] if value is None
                             else np.asarray(value, dtype=np.float64).reshape(len(samples), -1))
            if any(part.shape[0] != 1 for part in parts):
                steps[_SOURCE_ID["extra"]] = 1
                parts = [np.broadcast_to(part, (len(samples), part.shape[1])) for part in parts]
            arrays[_SOURCE_ID["extra"] - 1] = np.ascontiguousarray(np.hstack(parts))
        return arrays, steps

    def encode(self, samples: Samples) -> SerialBatch:
        n, size = len(samples), self.bytes_per_sample
        out = np.empty(n * size, dtype=np.uint8)
        arrays, steps = self._columns(samples)
        sat = np.zeros(len(self._items), dtype=np.int64)
        bad = _pack(out, size, self._header, self._items, self._scales, samples.time_ns, *arrays, steps, sat,
                    self.gps_offset_ns, samples.start_ns)
        if bad >= 0:
            samples.require_finite(self._sources)     # names field and sample
            raise EncodeError(f"non-finite value at sample {bad}")
        if sat.any():
            for j in np.flatnonzero(sat):
                self.saturated.add(self._item_field[j], int(sat[j]))
        if len(self._offsets) != n + 1:
            self._offsets = np.arange(n + 1, dtype=np.int64) * size
            self._offsets.flags.writeable = False
        if n:
            self._last_time_ns = int(samples.time_ns[-1])
        return SerialBatch(out.tobytes(), self._offsets)

    def _fields_reading(self, source: str) -> list[str]:
        return [f.key for f in self.layout.fields if any(q.source == source for q in f.quantities)]


# --- binary decoder --------------------------------------------------------------------------

def _field_values(field: _Field, raw: bytes, offset: int) -> dict:
    """One field's wire bytes -> {packet key: SI value}."""
    if not field.quantities:
        return {field.key: bytes(raw[offset:offset + field.size])}
    values = {}
    for q in field.quantities:
        count = len(q.order)
        wire = struct.unpack_from("<" + q.wire * count, raw, offset)
        offset += struct.calcsize(q.wire) * count
        key = f"{field.key}.{q.label}" if q.label else field.key
        if q.time:
            values[key] = int(wire[0])
            continue
        if count == 1:
            values[key] = float(wire[0]) / q.scale
            continue
        si = np.empty(count, dtype=np.float64)
        si[list(q.order)] = np.asarray(wire, dtype=np.float64) / q.scale
        values[key] = float(si[0]) if count == 1 else si
    return values


class BinaryDecoder:
    """Stream decoder for VectorNav binary output. The header names the layout, so any layout made of
    known fields is decoded; pass `fields` to accept only that one configuration (others are skipped
    like noise). `stats.skipped_bytes` counts every byte that did not end up in a yielded packet."""

    def __init__(self, fields=None):
        self.only = None if fields is None else parse_fields(fields).header
        self.stats = DecoderStats()
        self._buf = bytearray()
        self._layouts: dict = {}
        self._max_header = 1 + 2 * len(_FIELDS)

    def _layout(self, header: bytes):
        if header not in self._layouts:
            gbits = [b for b in range(8) if header[0] >> b & 1]
            masks = struct.unpack_from(f"<{len(gbits)}H", header, 1)
            self._layouts[header] = _layout_from_selection(dict(zip(gbits, masks)))
        return self._layouts[header]

    def feed(self, chunk: bytes) -> list:
        buf = self._buf
        buf += chunk
        packets, pos = [], 0
        while True:
            start = buf.find(SYNC, pos)
            if start < 0:
                self.stats.skipped_bytes += len(buf) - pos
                pos = len(buf)
                break
            self.stats.skipped_bytes += start - pos
            pos = start
            if len(buf) - pos < 2:
                break
            header_len = 1 + 2 * bin(buf[pos + 1]).count("1")
            if len(buf) - pos < 1 + header_len:
                break
            header = bytes(buf[pos + 1:pos + 1 + header_len])
            layout = None if buf[pos + 1] == 0 or header_len > self._max_header else self._layout(header)
            if layout is None or (self.only is not None and header != self.only):
                self.stats.skipped_bytes += 1
                pos += 1
                continue
            size = layout.packet_size
            if len(buf) - pos < size:
                break
            frame = bytes(buf[pos:pos + size])
            if crc16_ccitt_bytes(frame[1:]) != 0:
                # A false sync or a damaged packet: resume the hunt one byte on, since a real packet may
                # start inside what looked like this one.
                self.stats.bad_checksum += 1
                self.stats.skipped_bytes += 1
                pos += 1
                continue
            fields, offset = {}, 1 + header_len
            for field in layout.fields:
                fields.update(_field_values(field, frame, offset))
                offset += field.size
            packets.append(Packet("vectornav-binary", fields, frame))
            self.stats.packets += 1
            pos += size
        del buf[:pos]
        return packets


# --- registry --------------------------------------------------------------------------------

register(FormatInfo(
    name="vectornav-binary", kind="serial",
    description="VectorNav binary output (0xFA, user-chosen groups/fields, CRC-16/XMODEM; rate divisors divide the "
                "model's IMU rate: VN-300 400 Hz, others 800 Hz)",
    encoder=BinaryEncoder, decoder=BinaryDecoder,
    bytes_per_sample=parse_fields(DEFAULT_FIELDS).packet_size,
    options={"fields": f"groups and fields, e.g. 'common:timestartup,accel;imu:uncompgyro' "
                       f"(default {DEFAULT_FIELDS!r}, PX4's binary output 1)",
             "sample_period_s": "DeltaTheta's dtime in s, > 0, when the samples carry none (None: time since the "
                                "previous sample)",
             "gps_week_offset": "retired: GPS time follows --start-time (UTC) + scene time",
             "constants": "values for quantities no sample carries: " + ", ".join(_SETTABLE)
                          + " (e.g. {gnss_num_sats = 9})"},
))
