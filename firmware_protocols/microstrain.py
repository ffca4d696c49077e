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

from firmware_protocols.base import DecoderStats, Packet, SaturationStats, Samples, SerialBatch
from firmware_protocols.registry import FormatInfo, register
from firmware_protocols.packing import (CHECKSUM_FLETCHER16, FROM_CONSTANT, FROM_FIELD, FROM_TIME_DIV,
                                      FROM_TIME_REM_S, KIND_F32, KIND_F64, KIND_SIZE, KIND_U16, NEED_MORE, Column,
                                      FixedPacketPacker, FrameScanner, as_int, parse_names)

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
GPS_FLAGS_DEFAULT = 0x1C


class MipEncoder:
    """Samples -> one MIP 0x80 packet per sample, fields in the order given."""

    def __init__(self, fields=DEFAULT_FIELDS, gps_week_offset: int = 0, gps_flags: int = GPS_FLAGS_DEFAULT):
        self.fields = parse_names(fields, FIELDS, "fields")
        gps_week_offset, gps_flags = as_int(gps_week_offset), as_int(gps_flags)
        if not 0 <= gps_flags <= 0xFFFF:
            raise ValueError(f"gps_flags: must fit in 16 bits, got {gps_flags!r}")
        self.gps_week_offset = gps_week_offset
        self.gps_flags = gps_flags
        self.saturated = SaturationStats()

        packet = bytearray((0x75, 0x65, SENSOR_DATA_SET, 0))
        columns = []
        for name in self.fields:
            f = FIELDS[name]
            if name == "gps_timestamp":
                offset = self.gps_week_offset * WEEK_NS
                layout = [Column(KIND_F64, 0, "gps_timestamp.tow", FROM_TIME_REM_S, divisor=WEEK_NS, offset=offset),
                          Column(KIND_U16, 0, "gps_timestamp.week", FROM_TIME_DIV, divisor=WEEK_NS, offset=offset),
                          Column(KIND_U16, 0, "gps_timestamp.flags", FROM_CONSTANT, constant=float(self.gps_flags))]
            else:
                layout = [Column(KIND_F32, 0, name, FROM_FIELD, f.source, c, 1.0 / f.unit) for c in range(f.count)]
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
        self._packer = FixedPacketPacker(bytes(packet) + b"\x00\x00", columns, CHECKSUM_FLETCHER16, defaults)

    @property
    def bytes_per_sample(self) -> int:
        return self._packer.packet_size

    def encode(self, samples: Samples) -> SerialBatch:
        return self._packer.pack(samples, self.saturated)


# --- decoding --------------------------------------------------------------------------------

def fletcher16(data: bytes) -> tuple[int, int]:
    """MIP checksum bytes (a, b): a = sum of bytes, b = sum of the running sums, both mod 256."""
    return sum(data) & 0xFF, sum(accumulate(data)) & 0xFF


def _mip_length(buf: bytearray, j: int) -> int:
    if len(buf) - j < 4:
        return NEED_MORE
    return 4 + buf[j + 3] + 2


def _mip_checksum_ok(frame: bytes) -> bool:
    return fletcher16(frame[:-2]) == (frame[-2], frame[-1])


class MipDecoder:
    """Bytes -> Packets. Set 0x80 becomes kind "mip-sensor" with SI fields; any other descriptor set
    (command replies, filter data) becomes kind "mip" with its set and raw (descriptor, data) fields.
    Never raises."""

    def __init__(self, gps_week_offset: int = 0):
        self.gps_week_offset = as_int(gps_week_offset)
        self._scanner = FrameScanner(SYNC, _mip_length, _mip_checksum_ok)

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
    "fields": f"comma-separated 0x80 fields in wire order (default {','.join(DEFAULT_FIELDS)}); "
              f"known: {', '.join(FIELDS)}",
    "gps_week_offset": "GPS week added to time_ns for the GPS timestamp field (default 0)",
    "gps_flags": f"GPS timestamp valid flags (default 0x{GPS_FLAGS_DEFAULT:02X}: initialized, TOW and week valid)",
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
