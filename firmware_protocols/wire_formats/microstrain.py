"""MicroStrain (HBK / LORD) MIP packets, IMU "sensor data" descriptor set 0x80: encoder and stream decoder.

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
- GPS timestamp: GPS time = time_ns + gps_week_offset weeks; week = GPS time // 1 week, time of week =
  the remainder in seconds. With a time base starting at 0 the default offset (0) gives week 0; pass the
  GPS week your scenario starts in. Flags (data_sensor.h): 0x01 PPS valid, 0x02 time refreshed (toggles),
  0x04 time initialized, 0x08 time of week valid, 0x10 week number valid; default 0x1C (no PPS line
  exists in an emulator). Weeks outside u16 saturate (counted).
Values beyond float32 range saturate to +-3.4e38 and are counted in `encoder.saturated`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from itertools import accumulate

import numpy as np

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

# Filter (0x82) and GNSS (0x81) data sets: what ArduPilot's MicroStrain 5/7 drivers need to report healthy.
# Layouts from LORD-MicroStrain/mip_sdk src/mip/definitions/data_filter.h and data_gnss.h; every field ends
# in valid flags. Positions are geodetic (deg, deg, m above the WGS-84 ellipsoid; mean-sea-level height is
# reported equal to it: no geoid model), velocities NED, attitude as given in `quat` / `euler`.
FILTER_SET, GNSS_SET = 0x82, 0x81
FILTER_STATE_FULL_NAV = 4          # GQ7 filter mode "full navigation" (data_filter.h FilterMode)
_VALID = ((KIND_U16, 1.0),)
FILTER_FIELDS = {
    "position_llh": Field(0x01, "position_llh", 3, kind=KIND_F64, tail=_VALID),
    "velocity_ned": Field(0x02, "velocity_ned", 3, tail=_VALID),
    "quaternion": Field(0x03, "quat", 4, default=(1.0, 0.0, 0.0, 0.0), tail=_VALID),
    "euler": Field(0x05, "euler", 3, default=(0.0, 0.0, 0.0), tail=_VALID),
    # filter state, dynamics mode (1 portable), status flags: constants (see MipEncoder filter_state)
    "status": Field(0x10, "", 0),
    "gps_time": Field(0xD3, "time_ns", 3),
}
GNSS_FIELDS = {
    # lat, lon, height above ellipsoid, height above MSL (= ellipsoid here), horizontal and vertical
    # accuracy (m), valid flags (all five quantities)
    "position_llh": Field(0x03, "position_llh", 3, kind=KIND_F64,
                          tail=((KIND_F64, None), (KIND_F32, 1.0), (KIND_F32, 1.5), (KIND_U16, 0x1F))),
    # north, east, down, speed, ground speed, heading (deg), speed and heading accuracy, valid flags
    "velocity_ned": Field(0x05, "velocity_ned", 3,
                          tail=((KIND_F32, "speed"), (KIND_F32, "ground_speed"), (KIND_F32, "heading_deg"),
                                (KIND_F32, 0.1), (KIND_F32, 1.0), (KIND_U16, 0x1F))),
    # fix type 0 = 3D, satellites, fix flags, valid flags
    "fix_info": Field(0x0B, "", 0, tail=((KIND_U8, 0.0), (KIND_U8, 12.0), (KIND_U16, 0.0), (KIND_U16, 0x07))),
    "gps_time": Field(0x09, "time_ns", 3),
}
DATA_SETS = {SENSOR_DATA_SET: FIELDS, GNSS_SET: GNSS_FIELDS, FILTER_SET: FILTER_FIELDS}
GPS_FLAGS_DEFAULT = 0x1C


class MipEncoder:
    """Samples -> one MIP 0x80 packet per sample, fields in the order given."""
    # Axes: the MIP sensor frame is x forward, y right, z down (at rest, level, scaled accel z reads -1 g) and the
    # attitude is vehicle -> NED (mip_sdk data_sensor.h: p_veh = q^-1 p_ned q). Samples are already so.
    body_axes, reference = "FRD", "NED"
    axes_source = "MicroStrain MIP DCP: sensor frame x forward y right z down (-1 g on z at rest); data_sensor.h NED"


    def __init__(self, fields=DEFAULT_FIELDS, gps_week_offset: int = 0, gps_flags: int = GPS_FLAGS_DEFAULT,
                 descriptor_set: int = SENSOR_DATA_SET, filter_state: int = FILTER_STATE_FULL_NAV):
        if descriptor_set not in DATA_SETS:
            raise ValueError(f"descriptor_set: one of {', '.join(f'{d:#04x}' for d in DATA_SETS)}")
        table = DATA_SETS[descriptor_set]
        self.descriptor_set = descriptor_set
        self.fields = parse_names(fields, table, "fields")
        self.uses_increments = any(table[name].source in INCREMENT_FIELDS for name in self.fields)
        gps_week_offset, gps_flags = as_int(gps_week_offset), as_int(gps_flags)
        if not 0 <= gps_flags <= 0xFFFF:
            raise ValueError(f"gps_flags: must fit in 16 bits, got {gps_flags!r}")
        self.gps_week_offset = gps_week_offset
        self.gps_flags = gps_flags
        self.saturated = SaturationStats()

        packet = bytearray((0x75, 0x65, descriptor_set, 0))
        columns = []
        self._derived = False
        for name in self.fields:
            f = table[name]
            if f.source == "time_ns":
                offset = self.gps_week_offset * WEEK_NS
                # 0x80's flags are the GPS-correlation flags; the other sets' last word is valid flags
                flags = self.gps_flags if descriptor_set == SENSOR_DATA_SET else 0x3
                layout = [Column(KIND_F64, 0, f"{name}.tow", FROM_TIME_REM_S, divisor=WEEK_NS, offset=offset),
                          Column(KIND_U16, 0, f"{name}.week", FROM_TIME_DIV, divisor=WEEK_NS, offset=offset),
                          Column(KIND_U16, 0, f"{name}.flags", FROM_CONSTANT, constant=float(flags))]
            elif name == "status":
                layout = [Column(KIND_U16, 0, "status.filter_state", FROM_CONSTANT, constant=float(filter_state)),
                          Column(KIND_U16, 0, "status.dynamics_mode", FROM_CONSTANT, constant=1.0),
                          Column(KIND_U16, 0, "status.flags", FROM_CONSTANT, constant=0.0)]
            else:
                layout = [Column(f.kind, 0, name, FROM_FIELD, f.source, f.first + c, 1.0 / f.unit)
                          for c in range(f.count)]
                for k, (kind, value) in enumerate(f.tail):
                    if value is None:          # repeat the last value (height above MSL = ellipsoid height)
                        layout.append(replace(layout[f.count - 1], label=f"{name}.tail{k}"))
                    elif isinstance(value, str):
                        self._derived = True
                        layout.append(Column(kind, 0, f"{name}.{value}", FROM_FIELD, "gnss_speed",
                                             ("speed", "ground_speed", "heading_deg").index(value)))
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
        defaults = {f.source: f.default for f in FIELDS.values() if f.default}
        defaults.update(position_llh=(47.397742, 8.545594, 488.0), velocity_ned=(0.0, 0.0, 0.0),
                        gnss_speed=(0.0, 0.0, 0.0))
        self._packer = FixedPacketPacker(bytes(packet) + b"\x00\x00", columns, CHECKSUM_FLETCHER16, defaults)

    @property
    def bytes_per_sample(self) -> int:
        return self._packer.packet_size

    def encode(self, samples: Samples) -> SerialBatch:
        extra = None
        if self._derived and samples.velocity_ned is not None:
            v = samples.velocity_ned
            ground = np.hypot(v[:, 0], v[:, 1])
            extra = {"gnss_speed": np.column_stack((np.linalg.norm(v, axis=1), ground,
                                                    np.degrees(np.arctan2(v[:, 1], v[:, 0]))))}
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
    (command replies, filter data) becomes kind "mip" with its set and raw (descriptor, data) fields.
    Never raises."""

    def __init__(self, gps_week_offset: int = 0):
        self.gps_week_offset = as_int(gps_week_offset)
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
                    out["time_ns"] = (week - self.gps_week_offset) * WEEK_NS + round(tow * 1e9)
            elif name is not None and name != "gps_timestamp" and len(data) == 4 * FIELDS[name].count:
                f = FIELDS[name]
                values = tuple(float(v) * f.unit for v in np.frombuffer(data, ">f4"))
                key = {"pressure": "pressure_pa", "quaternion": "quat"}.get(name, name)
                out[key] = values[0] if f.count == 1 else values
            else:
                out.setdefault("unknown", {})[descriptor] = data
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
    "fields": "comma-separated 0x80 fields in wire order; "
              f"known: {', '.join(FIELDS)}",
    "gps_week_offset": "GPS week added to time_ns for the GPS timestamp field, >= 0",
    "gps_flags": "GPS timestamp valid flags 0..0xFFFF (0x1C: initialized, TOW and week valid)",
    "descriptor_set": "MIP data set: 0x80 sensor, 0x81 GNSS or 0x82 filter data (each with its own fields)",
    "filter_state": "filter data set's constant filter state field 0..0xFFFF",
}

register(FormatInfo(
    name="microstrain-mip",
    kind="serial",
    description="MicroStrain MIP sensor data (descriptor set 0x80), big-endian, Fletcher-16",
    encoder=MipEncoder,
    decoder=MipDecoder,
    bytes_per_sample=MipEncoder().bytes_per_sample,
    options=_OPTIONS,
))
