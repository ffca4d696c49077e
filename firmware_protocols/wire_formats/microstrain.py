"""MicroStrain (HBK / LORD) MIP packets: IMU "sensor data" set 0x80, GNSS sets 0x81 / 0x91 / 0x92 and filter set 0x82
(encoder; the stream decoder reads 0x80 into SI fields and passes the other sets' fields raw).

Frame: `75 65 descriptor_set payload_len field... checksum_a checksum_b`, each field
`field_len (incl. itself and the descriptor) descriptor data(big-endian)`. payload_len is one byte, so a
packet is at most 4 + 255 + 2 = 261 bytes. The checksum is Fletcher-16 over header and payload
(`a += byte; b += a`, mod 256), sent a then b; it reproduces the spec's published vector.

Fields of set 0x80 (field descriptors, types and units as declared in LORD-MicroStrain/mip_sdk,
src/mip/definitions/data_sensor.h):

| option name     | desc | data                                      | wire unit  | from Samples                  |
|-----------------|------|-------------------------------------------|------------|-------------------------------|
| accel           | 0x04 | 3 x f32 scaled accel                      | g          | accel / 9.80665               |
| gyro            | 0x05 | 3 x f32 scaled gyro                       | rad/s      | gyro                          |
| mag             | 0x06 | 3 x f32 scaled mag                        | gauss      | mag (default zeros)           |
| delta_theta     | 0x07 | 3 x f32                                   | rad        | delta_theta (default zeros)   |
| delta_velocity  | 0x08 | 3 x f32                                   | g*s        | delta_velocity / 9.80665      |
| quaternion      | 0x0A | 4 x f32 (w, x, y, z), vehicle -> NED      | -          | quat (default identity)       |
| euler           | 0x0C | 3 x f32 roll, pitch, yaw                  | rad        | euler (default zeros)         |
| gps_timestamp   | 0x12 | f64 time of week, u16 week, u16 flags     | s, weeks   | time_ns (see below)           |
| pressure        | 0x17 | 1 x f32 scaled pressure                   | mbar (hPa) | pressure_pa / 100 (101325 Pa) |

- g: the SDK only says "[g]"; this module uses standard gravity g = 9.80665 m/s^2 both ways.
- The quaternion and Euler angles are defined relative to NED (data_sensor.h: p_veh = q^-1 p_ned q),
  so the caller gives sensor->NED attitude in `quat`; nothing is converted here.
- GPS timestamp: GPS time of time_ns (UTC Unix ns, the run's --start-time + scene time) + 18 leap seconds -
  the GPS epoch (firmware_protocols.gnss_time); week = GPS time // 1 week (no 1024-week rollover), time of
  week = the remainder in seconds; the decoder gives time_ns back as UTC Unix ns. Flags (data_sensor.h): 0x01
  PPS valid, 0x02 time refreshed (toggles), 0x04 time initialized, 0x08 time of week valid, 0x10 week number valid;
  default 0x1C (no PPS line
  exists in an emulator). Weeks outside u16 saturate (counted).
Values beyond float32 range saturate to +-3.4e38 and are counted in `encoder.saturated`.

GNSS and filter sets (`descriptor_set`, tables GNSS_FIELDS and FILTER_FIELDS below): the GNSS fields carry the
receiver's solution (Samples.gnss_*: fix, satellites, accuracies, DOPs), the filter fields the unit's estimate
(position_llh, velocity_ned, quat, euler and their *_sigma) with the filter state its model family reports for
Samples.ins_mode. Fields the block lacks take the documented defaults (a healthy receiver under open sky, a
tracking filter, PX4 SITL's home position). A GNSS set's packet goes out only at the samples where a new solution
arrived (gnss_new), as the receiver reports each solution once; at every sample when the block has no gnss_new.
"""
from __future__ import annotations

import copy
import math
import struct
from dataclasses import dataclass, replace
from itertools import accumulate

import numpy as np

from firmware_protocols.gnss_time import GNSS_DEFAULTS, GPS_WEEK_OFFSET_RETIRED, dops, gps_offset_ns
from firmware_protocols.base import INCREMENT_FIELDS, DecoderStats, Packet, SaturationStats, Samples, SerialBatch
from firmware_protocols.registry import FormatInfo, register
from firmware_protocols.packing import (CHECKSUM_FLETCHER16, FROM_CONSTANT, FROM_FIELD, FROM_TIME_DIV,
                                      FROM_TIME_REM_S, KIND_F32, KIND_F64, KIND_SIZE, KIND_U8, KIND_U16, NEED_MORE,
                                      Column, FixedPacketPacker, FrameScanner, as_int, parse_names)

SYNC = b"\x75\x65"
SENSOR_DATA_SET = 0x80
MAX_PAYLOAD = 255
G = 9.80665                       # standard gravity, m/s^2 per g (both directions)
WEEK_NS = 7 * 86400 * 1_000_000_000


@dataclass(frozen=True)
class Field:
    descriptor: int
    source: str
    count: int
    unit: float = 1.0             # SI value of one wire unit
    default: tuple = ()
    kind: int = KIND_F32          # wire type of the `count` values
    first: int = 0                # first component of the source
    tail: tuple = ()              # constants after the values: ((kind, value), ...), e.g. valid flags


FIELDS = {
    "accel": Field(0x04, "accel", 3, G),
    "gyro": Field(0x05, "gyro", 3),
    "mag": Field(0x06, "mag", 3, default=(0.0, 0.0, 0.0)),
    "delta_theta": Field(0x07, "delta_theta", 3, default=(0.0, 0.0, 0.0)),
    "delta_velocity": Field(0x08, "delta_velocity", 3, G, default=(0.0, 0.0, 0.0)),
    "quaternion": Field(0x0A, "quat", 4, default=(1.0, 0.0, 0.0, 0.0)),
    "euler": Field(0x0C, "euler", 3, default=(0.0, 0.0, 0.0)),
    "gps_timestamp": Field(0x12, "time_ns", 3),
    "pressure": Field(0x17, "pressure_pa", 1, 100.0, default=(101325.0,)),
}
_BY_DESCRIPTOR = {f.descriptor: name for name, f in FIELDS.items()}
DEFAULT_FIELDS = ("accel", "gyro", "mag", "pressure", "quaternion", "gps_timestamp")

# Filter (0x82) and GNSS (0x81; 0x91 / 0x92 receivers 1 and 2 of a GQ7) data sets: what ArduPilot's MicroStrain
# 5/7 drivers read. Layouts from LORD-MicroStrain/mip_sdk src/mip/definitions/data_filter.h, data_gnss.h and
# data_shared.h (0xD3 GPS timestamp, a field of every set). Positions are geodetic (deg, deg, m above the WGS-84
# ellipsoid; the height above mean sea level is reported equal to it: no geoid model), velocities NED.
# A `tail` entry after a field's values is (kind, constant), (kind, None) = the previous value again, or
# (kind, "source:k") = component k of a source the encoder derives from Samples (see _derive).
FILTER_SET, GNSS_SET, GNSS_RECEIVER_1, GNSS_RECEIVER_2 = 0x82, 0x81, 0x91, 0x92
# Filter state by Samples.ins_mode (0 not tracking, 1 aligning, 2 tracking), per filter family; the codes are
# each family's own (data_filter.h FilterMode for the GQ7; the 3DM-GX5-45 manual's filter status 0x82/0x10:
# 0 startup, 1 initialization, 2 running - solution valid, 3 running - solution error).
FILTER_FAMILIES = {
    "gq7": (1, 1, 4),     # GQ7_INIT, GQ7_INIT, GQ7_FULL_NAV
    "gx5": (0, 1, 2),     # startup, initialization, running with a valid solution
}
_VALID = ((KIND_U16, "filter_valid:0"),)
FILTER_FIELDS = {
    "position_llh": Field(0x01, "position_llh", 3, kind=KIND_F64, tail=_VALID),
    "velocity_ned": Field(0x02, "velocity_ned", 3, tail=_VALID),
    "quaternion": Field(0x03, "quat", 4, default=(1.0, 0.0, 0.0, 0.0), tail=_VALID),
    "euler": Field(0x05, "euler", 3, default=(0.0, 0.0, 0.0), tail=_VALID),
    # 1-sigma north, east, down position (m) and velocity (m/s); roll, pitch, yaw (rad)
    "position_uncertainty": Field(0x08, "position_sigma_m", 3, default=(1.0, 1.0, 1.5), tail=_VALID),
    "velocity_uncertainty": Field(0x09, "velocity_sigma_mps", 3, default=(0.05, 0.05, 0.1), tail=_VALID),
    "euler_uncertainty": Field(0x0A, "attitude_sigma_rad", 3, default=(0.0087, 0.0087, 0.035), tail=_VALID),
    # filter state (from ins_mode, see FILTER_FAMILIES), dynamics mode (1 portable), status flags (none)
    "status": Field(0x10, "filter_state", 1, kind=KIND_U16, tail=((KIND_U16, 1.0), (KIND_U16, 0.0))),
    "gps_time": Field(0xD3, "time_ns", 3),
}
GNSS_FIELDS = {
    # lat, lon, height above ellipsoid, height above MSL (= ellipsoid here), horizontal and vertical
    # accuracy (m), valid flags (0x1F: all five; 0 without a fix, as for the velocity's 0x3F)
    "position_llh": Field(0x03, "gnss_llh", 3, kind=KIND_F64,
                          tail=((KIND_F64, None), (KIND_F32, "gnss_quality:0"), (KIND_F32, "gnss_quality:1"),
                                (KIND_U16, "gnss_quality:3"))),
    # north, east, down, speed, ground speed, heading (deg, 0..360), speed accuracy (m/s), heading accuracy (deg), valid
    "velocity_ned": Field(0x05, "gnss_velocity_ned", 3,
                          tail=((KIND_F32, "gnss_speed:0"), (KIND_F32, "gnss_speed:1"), (KIND_F32, "gnss_speed:2"),
                                (KIND_F32, "gnss_quality:2"), (KIND_F32, "gnss_speed:3"),
                                (KIND_U16, "gnss_quality:5"))),
    # gdop, pdop, hdop, vdop, tdop, ndop, edop, valid flags (those known: see _derive)
    "dop": Field(0x07, "gnss_dop", 7, tail=((KIND_U16, "gnss_quality:4"),)),
    # fix type (0 3D, 1 2D, 3 none), satellites used, fix flags, valid flags (all three)
    "fix_info": Field(0x0B, "gnss_fix_info", 2, kind=KIND_U8, tail=((KIND_U16, 0.0), (KIND_U16, 0x07))),
    # GPS time (time of week, week) of the solution, the sample time less Samples.gnss_age_s: the 3DM-GX5's GNSS GPS
    # time field, and the shared GPS timestamp (GQ7 and later firmware)
    "gps_time": Field(0x09, "time_ns", 3),
    "gps_timestamp": Field(0xD3, "time_ns", 3),
}
GNSS_SETS = (GNSS_SET, GNSS_RECEIVER_1, GNSS_RECEIVER_2)
DATA_SETS = {SENSOR_DATA_SET: FIELDS, GNSS_SET: GNSS_FIELDS, FILTER_SET: FILTER_FIELDS,
             GNSS_RECEIVER_1: GNSS_FIELDS, GNSS_RECEIVER_2: GNSS_FIELDS}
GPS_FLAGS_DEFAULT = 0x1C
# Samples.gnss_fix (0 none, 2 2D, 3 3D) -> MIP fix type (data_gnss.h FixInfo: 0 3D, 1 2D, 2 time only, 3 none)
_MIP_FIX = {0: 3, 2: 1, 3: 0}
# The receiver's figures when Samples carries none: a healthy receiver under open sky (firmware_protocols.gnss_time)
_GNSS_DEFAULTS = {"gnss_fix": 3.0, "gnss_satellites": float(GNSS_DEFAULTS["num_sats"]),
                  "gnss_horizontal_accuracy_m": GNSS_DEFAULTS["h_acc_m"],
                  "gnss_vertical_accuracy_m": GNSS_DEFAULTS["v_acc_m"],
                  "gnss_speed_accuracy_mps": GNSS_DEFAULTS["s_acc_mps"]}
_DEFAULT_LLH = (47.397742, 8.545594, 488.0)


def _derive(samples: Samples, names: set, filter_states: tuple, filter_state: int | None) -> dict:
    """The sources the GNSS and filter fields compute from Samples (only those in `names`). The GNSS fields read
    the receiver's solution (gnss_*), falling back on the estimate (position_llh, velocity_ned), then on
    defaults; with no fix the position and velocity valid flags are 0, as a receiver clears them."""
    n = len(samples)
    out = {}
    llh = samples.gnss_llh if samples.gnss_llh is not None else samples.position_llh
    velocity = samples.gnss_velocity_ned if samples.gnss_velocity_ned is not None else samples.velocity_ned
    if llh is not None:
        out["gnss_llh"] = llh
    if velocity is not None:
        out["gnss_velocity_ned"] = velocity
    if {"gnss_quality", "gnss_fix_info", "gnss_speed", "gnss_dop"} & names:
        fix = samples.field_or("gnss_fix", _GNSS_DEFAULTS["gnss_fix"])
        code = np.full(n, 3.0)
        for ours, theirs in _MIP_FIX.items():
            code[fix == ours] = theirs
        fixed = fix >= 2
        known_dop = samples.gnss_hdop is not None and samples.gnss_vdop is not None
        out["gnss_quality"] = np.column_stack((
            samples.field_or("gnss_horizontal_accuracy_m", _GNSS_DEFAULTS["gnss_horizontal_accuracy_m"]),
            samples.field_or("gnss_vertical_accuracy_m", _GNSS_DEFAULTS["gnss_vertical_accuracy_m"]),
            samples.field_or("gnss_speed_accuracy_mps", _GNSS_DEFAULTS["gnss_speed_accuracy_mps"]),
            np.where(fixed, 0x1F, 0), np.full(n, 0x0E if known_dop else 0x7F), np.where(fixed, 0x3F, 0)))
        out["gnss_fix_info"] = np.column_stack((code, samples.field_or("gnss_satellites",
                                                                       _GNSS_DEFAULTS["gnss_satellites"])))
        if known_dop:          # p^2 = h^2 + v^2; the others are not known: 0 and not flagged valid
            h, v = samples.gnss_hdop, samples.gnss_vdop
            zero = np.zeros(n)
            out["gnss_dop"] = np.column_stack((zero, np.hypot(h, v), h, v, zero, zero, zero))
        else:
            g, p, t, v, h, north, east = dops(GNSS_DEFAULTS["dop_n"], GNSS_DEFAULTS["dop_e"],
                                              GNSS_DEFAULTS["dop_v"], GNSS_DEFAULTS["dop_t"])
            out["gnss_dop"] = np.tile((g, p, h, v, t, north, east), (n, 1))
        velocity = np.zeros((n, 3)) if velocity is None else velocity
        ground = np.hypot(velocity[:, 0], velocity[:, 1])
        # heading accuracy: the angle the speed's 1-sigma subtends at the ground speed
        heading_sigma = np.degrees(np.arctan2(out["gnss_quality"][:, 2], ground))
        out["gnss_speed"] = np.column_stack((np.linalg.norm(velocity, axis=1), ground,
                                             np.degrees(np.arctan2(velocity[:, 1], velocity[:, 0])) % 360.0, heading_sigma))
    if {"filter_state", "filter_valid"} & names:
        mode = np.clip(samples.field_or("ins_mode", 2.0), 0, 2).astype(np.int64)
        state = np.asarray(filter_states, dtype=np.float64)[mode]
        out["filter_state"] = state.reshape(n, 1) if filter_state is None else np.full((n, 1), float(filter_state))
        out["filter_valid"] = (mode == 2).astype(np.float64).reshape(n, 1)
    return out


class MipEncoder:
    """Samples -> one MIP packet per sample (of the chosen descriptor set), fields in the order given."""
    # Axes: the MIP sensor frame is x forward, y right, z down (at rest, level, scaled accel z reads -1 g) and the
    # attitude is vehicle -> NED (mip_sdk data_sensor.h: p_veh = q^-1 p_ned q). Samples are already so.
    body_axes, reference = "FRD", "NED"
    axes_source = "MicroStrain MIP DCP: sensor frame x forward y right z down (-1 g on z at rest); data_sensor.h NED"


    def __init__(self, fields=DEFAULT_FIELDS, gps_week_offset=None, gps_flags: int = GPS_FLAGS_DEFAULT,
                 descriptor_set: int = SENSOR_DATA_SET, filter_family: str = "gq7", filter_state: int | None = None):
        if descriptor_set not in DATA_SETS:
            raise ValueError(f"descriptor_set: one of {', '.join(f'{d:#04x}' for d in DATA_SETS)}")
        if filter_family not in FILTER_FAMILIES:
            raise ValueError(f"filter_family: one of {', '.join(FILTER_FAMILIES)}, got {filter_family!r}")
        if filter_state is not None:
            filter_state = as_int(filter_state)
            if not 0 <= filter_state <= 0xFFFF:
                raise ValueError(f"filter_state: must fit in 16 bits, got {filter_state!r}")
        self.filter_states, self.filter_state = FILTER_FAMILIES[filter_family], filter_state
        table = DATA_SETS[descriptor_set]
        self.descriptor_set = descriptor_set
        self.fields = parse_names(fields, table, "fields")
        self.uses_increments = any(table[name].source in INCREMENT_FIELDS for name in self.fields)
        if gps_week_offset is not None:
            raise ValueError(GPS_WEEK_OFFSET_RETIRED)
        gps_flags = as_int(gps_flags)
        if not 0 <= gps_flags <= 0xFFFF:
            raise ValueError(f"gps_flags: must fit in 16 bits, got {gps_flags!r}")
        self.gps_flags = gps_flags
        self.saturated = SaturationStats()

        packet = bytearray((0x75, 0x65, descriptor_set, 0))
        columns = []
        for name in self.fields:
            f = table[name]
            if f.source == "time_ns":
                offset = gps_offset_ns()      # GPS time - time_ns
                # 0x80's flags are the GPS-correlation flags; the other sets' last word is valid flags
                flags = self.gps_flags if descriptor_set == SENSOR_DATA_SET else 0x3
                layout = [Column(KIND_F64, 0, f"{name}.tow", FROM_TIME_REM_S, divisor=WEEK_NS, offset=offset),
                          Column(KIND_U16, 0, f"{name}.week", FROM_TIME_DIV, divisor=WEEK_NS, offset=offset),
                          Column(KIND_U16, 0, f"{name}.flags", FROM_CONSTANT, constant=float(flags))]
            else:
                layout = [Column(f.kind, 0, name, FROM_FIELD, f.source, f.first + c, 1.0 / f.unit)
                          for c in range(f.count)]
                for k, (kind, value) in enumerate(f.tail):
                    if value is None:          # repeat the last value (height above MSL = ellipsoid height)
                        layout.append(replace(layout[f.count - 1], label=f"{name}.tail{k}"))
                    elif isinstance(value, str):
                        source, component = value.split(":")
                        layout.append(Column(kind, 0, f"{name}.{value}", FROM_FIELD, source, int(component)))
                    else:
                        layout.append(Column(kind, 0, f"{name}.tail{k}", FROM_CONSTANT, constant=float(value)))
            widths = [KIND_SIZE[c.kind] for c in layout]
            packet += bytes((2 + sum(widths), f.descriptor))
            for column, width in zip(layout, widths):
                columns.append(replace(column, position=len(packet)))
                packet += bytes(width)
        payload_len = len(packet) - 4
        if payload_len > MAX_PAYLOAD:
            raise ValueError(f"fields: payload of {payload_len} bytes exceeds MIP's {MAX_PAYLOAD}")
        packet[3] = payload_len
        defaults = {f.source: f.default for table in DATA_SETS.values() for f in table.values() if f.default}
        defaults.update(position_llh=_DEFAULT_LLH, velocity_ned=(0.0, 0.0, 0.0), gnss_llh=_DEFAULT_LLH,
                        gnss_velocity_ned=(0.0, 0.0, 0.0))
        self._packer = FixedPacketPacker(bytes(packet) + b"\x00\x00", columns, CHECKSUM_FLETCHER16, defaults)
        self._solution_time = table is GNSS_FIELDS and any(table[name].source == "time_ns" for name in self.fields)
        self._derived = set(self._packer.slots) & {"gnss_llh", "gnss_velocity_ned", "gnss_quality", "gnss_fix_info",
                                                   "gnss_speed", "gnss_dop", "filter_state", "filter_valid"}

    @property
    def bytes_per_sample(self) -> int:
        return self._packer.packet_size

    def encode(self, samples: Samples) -> SerialBatch:
        """One packet per sample; a GNSS set's only at the samples where the receiver has a new solution
        (gnss_new), as a receiver reports each solution once (every sample when the block has no gnss_new)."""
        if self.descriptor_set not in GNSS_SETS or samples.gnss_new is None:
            return self._encode(samples)
        samples.require_finite(("gnss_new",))
        due = np.flatnonzero(samples.gnss_new != 0)
        batch = self._encode(samples.rows(due))
        sizes = np.zeros(len(samples), dtype=np.int64)
        sizes[due] = np.diff(batch.offsets)
        offsets = np.zeros(len(samples) + 1, dtype=np.int64)
        np.cumsum(sizes, out=offsets[1:])
        return SerialBatch(batch.data, offsets)

    def _encode(self, samples: Samples) -> SerialBatch:
        extra = None
        if self._solution_time and samples.gnss_age_s is not None:
            # a GNSS set's GPS time is its solution's time of validity: the sample time less the solution's age
            samples.require_finite(["gnss_age_s"])
            samples = copy.copy(samples)
            samples.time_ns = samples.time_ns - np.rint(samples.gnss_age_s * 1e9).astype(np.int64)
        if self._derived:
            samples.require_finite(["gnss_llh", "gnss_velocity_ned", "gnss_fix", "gnss_satellites", "gnss_hdop",
                                    "gnss_vdop", "gnss_horizontal_accuracy_m", "gnss_vertical_accuracy_m",
                                    "gnss_speed_accuracy_mps", "ins_mode"])
            extra = _derive(samples, self._derived, self.filter_states, self.filter_state)
        return self._packer.pack(samples, self.saturated, extra=extra)


# --- decoding --------------------------------------------------------------------------------

def fletcher16(data: bytes) -> tuple[int, int]:
    """MIP checksum bytes (a, b): a = sum of bytes, b = sum of the running sums, both mod 256."""
    return sum(data) & 0xFF, sum(accumulate(data)) & 0xFF


def mip_length(buf: bytearray, j: int) -> int:
    if len(buf) - j < 4:
        return NEED_MORE
    return 4 + buf[j + 3] + 2


def mip_checksum_ok(frame: bytes) -> bool:
    return fletcher16(frame[:-2]) == (frame[-2], frame[-1])


class MipDecoder:
    """Bytes -> Packets. Set 0x80 becomes kind "mip-sensor" with SI fields; any other descriptor set
    (command replies, GNSS and filter data) becomes kind "mip" with its set and raw (descriptor, data) fields,
    and for the GNSS and filter sets also "values": {field name: its numbers as on the wire, valid flags
    included}. Never raises."""

    def __init__(self, gps_week_offset=None):
        if gps_week_offset is not None:
            raise ValueError(GPS_WEEK_OFFSET_RETIRED)
        self._scanner = FrameScanner(SYNC, mip_length, mip_checksum_ok)

    @property
    def stats(self) -> DecoderStats:
        return self._scanner.stats

    def feed(self, chunk: bytes) -> list[Packet]:
        packets = []
        for frame in self._scanner.frames(chunk):
            raw_fields, malformed = _split_fields(frame[4:-2])
            if frame[2] == SENSOR_DATA_SET:
                fields = self._sensor_fields(raw_fields)
                kind = "mip-sensor"
            else:
                fields = {"descriptor_set": frame[2], "fields": raw_fields}
                if frame[2] in DATA_SETS:
                    fields["values"] = _set_values(DATA_SETS[frame[2]], raw_fields)
                kind = "mip"
            if malformed:
                fields["malformed"] = True
            packets.append(Packet(kind, fields, frame))
            self.stats.packets += 1
        return packets

    def _sensor_fields(self, raw_fields) -> dict:
        out: dict = {"descriptors": [d for d, _ in raw_fields]}
        for descriptor, data in raw_fields:
            name = _BY_DESCRIPTOR.get(descriptor)
            if name == "gps_timestamp" and len(data) == 12:
                tow = float(np.frombuffer(data[:8], ">f8")[0])
                week, flags = int.from_bytes(data[8:10], "big"), int.from_bytes(data[10:12], "big")
                out.update(gps_tow=tow, gps_week=week, gps_flags=flags)
                if math.isfinite(tow):
                    out["time_ns"] = week * WEEK_NS + round(tow * 1e9) - gps_offset_ns()   # UTC Unix ns
            elif name is not None and name != "gps_timestamp" and len(data) == 4 * FIELDS[name].count:
                f = FIELDS[name]
                values = tuple(float(v) * f.unit for v in np.frombuffer(data, ">f4"))
                key = {"pressure": "pressure_pa", "quaternion": "quat"}.get(name, name)
                out[key] = values[0] if f.count == 1 else values
            else:
                out.setdefault("unknown", {})[descriptor] = data
        return out


_STRUCT_CODE = {KIND_U8: "B", KIND_U16: "H", KIND_F32: "f", KIND_F64: "d"}


def _set_values(table: dict, raw_fields) -> dict:
    """{name: numbers} of the fields of a GNSS or filter set whose size matches the table's layout."""
    out = {}
    for name, f in table.items():
        kinds = ((KIND_F64, KIND_U16, KIND_U16) if f.source == "time_ns"
                 else (f.kind,) * f.count + tuple(kind for kind, _ in f.tail))
        layout = struct.Struct(">" + "".join(_STRUCT_CODE[k] for k in kinds))
        for descriptor, data in raw_fields:
            if descriptor == f.descriptor and len(data) == layout.size:
                out[name] = layout.unpack(data)
    return out


def _split_fields(payload: bytes):
    fields, k = [], 0
    while k < len(payload):
        size = payload[k]
        if size < 2 or k + size > len(payload):
            return fields, True          # a field runs past the payload: keep what came before
        fields.append((payload[k + 1], payload[k + 2:k + size]))
        k += size
    return fields, False


_OPTIONS = {
    "fields": "comma-separated fields of the descriptor set in wire order; "
              f"0x80: {', '.join(FIELDS)}; 0x81, 0x91, 0x92: {', '.join(GNSS_FIELDS)}; "
              f"0x82: {', '.join(FILTER_FIELDS)}",
    "gps_week_offset": "retired: GPS time follows --start-time (UTC) + scene time",
    "gps_flags": "GPS timestamp valid flags 0..0xFFFF (0x1C: initialized, TOW and week valid)",
    "descriptor_set": "MIP data set: 0x80 sensor, 0x81 GNSS (0x91, 0x92: GNSS receiver 1, 2) or 0x82 filter "
                      "data (each with its own fields)",
    "filter_family": "filter state codes of: gq7 (1 init, 4 full navigation) or gx5 (0 startup, 1 "
                     "initialization, 2 running, solution valid); the state follows Samples.ins_mode",
    "filter_state": "a constant filter state 0..0xFFFF instead of the one ins_mode gives",
}

register(FormatInfo(
    name="microstrain-mip",
    kind="serial",
    description="MicroStrain MIP sensor (0x80), GNSS (0x81, 0x91, 0x92) or filter (0x82) data, big-endian, Fletcher-16",
    encoder=MipEncoder,
    decoder=MipDecoder,
    bytes_per_sample=MipEncoder().bytes_per_sample,
    options=_OPTIONS,
))
