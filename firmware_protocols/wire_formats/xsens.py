"""Xsens MTi "MTData2" output (Xbus message 0x36): encoder and stream decoder.

Frame (Xbus, as sent over a serial port):

    FA  FF  36  len  payload  checksum             payload length 0..254
    FA  FF  36  FF  len_hi len_lo  payload  checksum    payload length 255..8185

- FA is the preamble, FF the master bus id, 36 the MTData2 message id.
- The checksum makes the byte sum from FF through the checksum 0 mod 256.
- A length byte of 0xFF announces a 2-byte big-endian length (high byte first), used for any payload
  longer than 254 bytes. Verified against Movella's own xstypes/xsmessage.c
  (XsMessage_constructSized: `if (dataSize > 254) { m_length = XS_EXTLENCODE; ptr[0] = dataSize >> 8;
  ptr[1] = dataSize; }`, XsMessageHeader_dataSize rejects extended lengths < 255 or > XS_MAXMSGLEN;
  XS_MAXDATALEN = 8192 - 7). Note ethz-asl/ethzasl_xsens_driver's write_msg puts the two bytes the
  other way round, but its own read_msg (and the SDK) read them big-endian.
- Payload: a sequence of items `XDI (u16 BE) size (u8) data (big-endian)`, in the order the output
  configuration lists them (the recorded MTi-300 packet is not sorted by XDI).

Data identifier low nibble: bits 0-1 precision (0 float32, 1 fixed 12.20, 2 fixed 16.32, 3 float64);
bits 2-3 coordinate system (0 ENU, 4 NED, 8 NWU). The SDK names the coordinate-system mask "the
coordinate system part of the orientation data identifier" (xstypes/xsdataidentifier.h) and sets it only
on orientation (and velocity/position) items when converting legacy packets, so this encoder declares the
frame on Quaternion, EulerAngles and VelocityXYZ. Samples carry sensor -> NED attitude and NED velocity (as for
every format); the encoder re-expresses both in the declared frame. The vectors (acceleration, rate of turn,
magnetic field, increments) go out in the MTi's sensor frame S, x forward, y left, z up whatever the frame (the
coordinate-system setting turns the reference frame only): Samples' forward-right-down vectors are re-expressed.

Fixed point (xstypes/xsmessage.c, XsMessage_setDataF1220 / XsMessage_setDataFP1632):
- 12.20: int32 = value * 2**20, range [-2048, 2048 - 2**-20].
- 16.32: 48 bits = value * 2**32, sent as the low 32 bits (fraction) FIRST, then the high 16 bits
  (integer part), each big-endian; range [-32768, 32768 - 2**-32]. (The SDK also copies the float's
  last mantissa bit into the lowest wire bit; that is below one LSB and not reproduced.)

Items, units on the wire, source in `Samples`:

| item               | XDI    | wire                               | from                         |
|--------------------|--------|------------------------------------|------------------------------|
| packet_counter     | 0x1020 | u16, +1 per packet, wraps 65535->0 | encoder state                |
| sample_time_fine   | 0x1060 | u32, 10 kHz ticks, wraps at 2**32  | (time_ns - start_ns) // 1e5  |
| sample_time_coarse | 0x1070 | u32, whole seconds                 | (time_ns - start_ns) // 1e9  |
| quaternion         | 0x2010 | 4 reals (w, x, y, z)               | quat (default identity)      |
| euler_angles       | 0x2030 | 3 reals roll, pitch, yaw in DEGREES| euler (rad; default zeros)   |
| baro_pressure      | 0x3010 | u32 Pa                             | pressure_pa (default 101325) |
| delta_v            | 0x4010 | 3 reals m/s                        | delta_velocity (default 0)   |
| acceleration       | 0x4020 | 3 reals m/s^2                      | accel                        |
| acceleration_hr    | 0x4040 | 3 reals m/s^2                      | accel                        |
| rate_of_turn       | 0x8020 | 3 reals rad/s                      | gyro                         |
| delta_q            | 0x8030 | 4 reals (w, x, y, z)               | attitude_change, else the    |
|                    |        |                                    | rotation by delta_theta      |
| rate_of_turn_hr    | 0x8040 | 3 reals rad/s                      | gyro                         |
| magnetic_field     | 0xC020 | 3 reals, arbitrary units           | mag / mag_reference_gauss    |
| temperature        | 0x0810 | 1 real, deg C                      | temperature_c (default 25)   |
| status_word        | 0xE020 | u32                                | the `status_word` option     |
| gnss_pvt_data      | 0x7010 | XsRawGnssPvtData, 94 bytes         | gnss_* (receiver_pvt)        |
| lat_lon            | 0x5040 | 2 reals, degrees                   | position_llh[0:2] (default   |
|                    |        |                                    | origin, see Samples)         |
| altitude_ellipsoid | 0x5020 | 1 real, m above WGS-84             | position_llh[2]              |
| velocity_xyz       | 0xD010 | 3 reals m/s in the declared frame  | velocity_ned, re-ordered and |
|                    |        |                                    | signed for ENU / NWU         |

Each real item may have its own precision (`precisions`, e.g. ArduPilot asks float32 for the IMU items but
FP16.32 for LatLon, AltitudeEllipsoid and VelocityXYZ); the XDI announces it per item.

SampleTimeFine is in 10 kHz ticks: Movella's ROS 2 driver (xsenssupport/Xsens_MTi_ROS_Driver_and_Ntrip_Client,
messagepublishers/timereferencepublisher.h) converts it with SAMPLE_TIME_FINE_HZ = 10000.

MagneticField is not in gauss: the same driver (magneticfieldpublisher.h) says "Sensor gives normalized
magnetic field vector with unknown units"; Xsens calls them arbitrary units, normalised to the field
strength where the device was calibrated (MT Low-Level Communication Protocol, MagneticField: "a.u.",
normalised to the field where the magnetic field mapping was done). `mag_reference_gauss` is the field strength
that reads 1.0. Its default, 0.49 G, is what the drivers assume: ArduPilot's AP_ExternalAHRS_Xsens.cpp
(ArduPilot/ardupilot 1056c40f, publish_sensor_data: "1 a.u = 0.49Gauss", A_U_TO_MILLIGAUSS = 490) multiplies
by exactly that, so with the default the compass ArduPilot reads equals the samples' field. The decoder
multiplies back by the same option.

"reals" are float32 / 12.20 / 16.32 / float64 by the `precision` option. Values outside a type's range
saturate to the nearest representable value and are counted in `encoder.saturated` (for float32 that is
+-3.4e38; for float64 nothing finite saturates except after unit scaling overflows).

The batch packer and the frame scanner are format-neutral and live in firmware_protocols.packing, shared
with firmware_protocols.wire_formats.microstrain (MIP).
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from firmware_protocols.axes import to_body_axes
from firmware_protocols.base import (INCREMENT_FIELDS, DecoderStats, Packet, SaturationStats, Samples,
                                     SerialBatch)
from firmware_protocols import attitude
from firmware_protocols.gnss_time import gnss_pvt_rows, gnss_settings, utc_rows
from firmware_protocols.packing import (CHECKSUM_XBUS, FROM_CONSTANT, FROM_COUNTER, FROM_FIELD, FROM_TIME_DIV,
                                        KIND_F32, KIND_F64, KIND_FP1220, KIND_FP1632, KIND_I32, KIND_SIZE, KIND_U8,
                                        KIND_U16, KIND_U32, NEED_MORE, NOT_A_FRAME, Column, FixedPacketPacker,
                                        FrameScanner, as_int, parse_names)
from firmware_protocols.registry import FormatInfo, register

# ============================================================================================
# Xsens MTData2
# ============================================================================================

PREAMBLE = 0xFA
BUS_MASTER = 0xFF
MID_MTDATA2 = 0x36
EXTENDED_LENGTH = 0xFF
MAX_DATA_LENGTH = 8192 - 7          # XS_MAXDATALEN in xsmessage.h
TICKS_PER_SECOND = 10_000           # SampleTimeFine
NS_PER_TICK = 1_000_000_000 // TICKS_PER_SECOND
#: gauss that read 1.0 a.u. of MagneticField: ArduPilot's A_U_TO_MILLIGAUSS = 490 (see the module docstring)
MAG_REFERENCE_GAUSS = 0.49

PRECISIONS = {"float32": (0, KIND_F32, 4), "fp1220": (1, KIND_FP1220, 4),
              "fp1632": (2, KIND_FP1632, 6), "float64": (3, KIND_F64, 8)}
FRAMES = {"ENU": 0x0, "NED": 0x4, "NWU": 0x8}


@dataclass(frozen=True)
class Item:
    xdi: int
    count: int            # values in the item
    real: bool            # takes the precision bits (else a fixed integer kind)
    int_kind: int = KIND_U32
    has_frame: bool = False
    source: str = ""      # Samples field the values come from ("" for time, state and options)
    unit: float = 1.0     # SI -> wire multiplier
    first: int = 0        # first component of the source


ITEMS = {
    "packet_counter": Item(0x1020, 1, False, KIND_U16),
    "sample_time_fine": Item(0x1060, 1, False, KIND_U32),
    "sample_time_coarse": Item(0x1070, 1, False, KIND_U32),
    "quaternion": Item(0x2010, 4, True, has_frame=True, source="quat"),
    "euler_angles": Item(0x2030, 3, True, has_frame=True, source="euler", unit=180.0 / math.pi),
    "baro_pressure": Item(0x3010, 1, False, KIND_U32, source="pressure_pa"),
    "delta_v": Item(0x4010, 3, True, source="delta_velocity"),
    "acceleration": Item(0x4020, 3, True, source="accel"),
    "acceleration_hr": Item(0x4040, 3, True, source="accel"),
    "rate_of_turn": Item(0x8020, 3, True, source="gyro"),
    "delta_q": Item(0x8030, 4, True, source="delta_q"),
    "rate_of_turn_hr": Item(0x8040, 3, True, source="gyro"),
    "magnetic_field": Item(0xC020, 3, True, source="mag"),
    "temperature": Item(0x0810, 1, True, source="temperature_c"),
    "status_word": Item(0xE020, 1, False, KIND_U32),
    "lat_lon": Item(0x5040, 2, True, source="position_llh"),
    "altitude_ellipsoid": Item(0x5020, 1, True, source="position_llh", first=2),
    "velocity_xyz": Item(0xD010, 3, True, has_frame=True, source="velocity_ned"),
    # Records of mixed integer fields, computed per block (firmware_protocols.gnss_time) into one source row
    # each; their wire layout is _RECORDS'.
    "utc_time": Item(0x1010, 8, False, source="utc"),
    "gnss_pvt_data": Item(0x7010, 35, False, source="gnss_pvt"),
}
# UtcTime (xstypes XsUtcTime): nano u32, year u16, month, day, hour, minute, second, flags u8 = 12 bytes.
# GnssPvtData (xstypes XsRawGnssPvtData, packed, 94 bytes): iTOW u32 ms, year u16, month, day, hour, min, sec,
# valid u8, tAcc u32 ns, nano i32, fixType, flags, numSv, res1 u8, lon, lat i32 1e-7 deg, height, hMSL i32 mm,
# hAcc, vAcc u32 mm, velN, velE, velD, gSpeed i32 mm/s, headMot i32 1e-5 deg, sAcc u32 mm/s, headAcc u32
# 1e-5 deg, headVeh i32 1e-5 deg, gdop, pdop, tdop, vdop, hdop, ndop, edop u16 0.01.
_RECORDS = {
    "utc_time": (KIND_U32, KIND_U16) + (KIND_U8,) * 6,
    "gnss_pvt_data": (KIND_U32, KIND_U16) + (KIND_U8,) * 6 + (KIND_U32, KIND_I32) + (KIND_U8,) * 4
                     + (KIND_I32,) * 4 + (KIND_U32,) * 2 + (KIND_I32,) * 5 + (KIND_U32,) * 2 + (KIND_I32,)
                     + (KIND_U16,) * 7,
}
assert all(len(kinds) == ITEMS[name].count for name, kinds in _RECORDS.items())
_RECORD_DTYPES = {name: np.dtype([(f"f{k}", {KIND_U8: ">u1", KIND_U16: ">u2", KIND_U32: ">u4", KIND_I32: ">i4"}[kind])
                                  for k, kind in enumerate(kinds)]) for name, kinds in _RECORDS.items()}
# velocity_xyz in each declared frame: (component of NED, sign) per axis
_VELOCITY_AXES = {"ENU": ((1, 1.0), (0, 1.0), (2, -1.0)), "NED": ((0, 1.0), (1, 1.0), (2, 1.0)),
                  "NWU": ((0, 1.0), (1, -1.0), (2, -1.0))}
_ITEM_BY_XDI = {item.xdi: name for name, item in ITEMS.items()}
# Decoded but never encoded: free acceleration needs gravity removed in the navigation frame, which is
# the kernel's business, not the packetizer's. The recorded MTi-300 packet carries it.
_DECODE_ONLY = {0x4030: ("free_acceleration", Item(0x4030, 3, True))}

DEFAULT_ITEMS = ("packet_counter", "sample_time_fine", "acceleration", "rate_of_turn")
_DEFAULTS = {"quat": (1.0, 0.0, 0.0, 0.0), "euler": (0.0, 0.0, 0.0), "pressure_pa": (101325.0,),
             "position_llh": (47.397742, 8.545594, 488.0), "velocity_ned": (0.0, 0.0, 0.0),
             "delta_velocity": (0.0, 0.0, 0.0), "mag": (0.0, 0.0, 0.0), "temperature_c": (25.0,),
             "delta_q": (1.0, 0.0, 0.0, 0.0)}






_RECEIVER_FIELDS = ("gnss_llh", "gnss_velocity_ned", "gnss_fix", "gnss_satellites", "gnss_hdop", "gnss_vdop",
                    "gnss_horizontal_accuracy_m", "gnss_vertical_accuracy_m", "gnss_speed_accuracy_mps")


def receiver_pvt(samples: Samples, settings: dict) -> np.ndarray:
    """(n, 35) GnssPvtData rows: the GNSS receiver's solution (Samples.gnss_*) where the block carries it, else the
    position and velocity the unit reports (position_llh, velocity_ned, or the default origin at rest) with the
    `gnss` settings' figures. fixType is u-blox's (0 none, 2 2D, 3 3D: Samples.gnss_fix's own numbering); flags
    bit 0 gnssFixOK is set with a fix. With hDOP and vDOP given, pDOP^2 = h^2 + v^2, north and east take
    h / sqrt 2 each and gDOP^2 = p^2 + t^2 with the settings' tDOP, so the seven stay consistent."""
    samples.require_finite(("position_llh", "velocity_ned") + _RECEIVER_FIELDS)
    llh = samples.gnss_llh if samples.gnss_llh is not None else samples.field_or("position_llh",
                                                                                  _DEFAULTS["position_llh"])
    velocity = (samples.gnss_velocity_ned if samples.gnss_velocity_ned is not None
                else samples.field_or("velocity_ned", _DEFAULTS["velocity_ned"]))
    rows = gnss_pvt_rows(samples.time_ns, llh, velocity, settings)
    if samples.gnss_fix is not None:
        rows[:, 10] = samples.gnss_fix
        rows[:, 11] = (samples.gnss_fix >= 2).astype(np.float64)
    for column, name, scale in ((12, "gnss_satellites", 1.0), (18, "gnss_horizontal_accuracy_m", 1e3),
                                (19, "gnss_vertical_accuracy_m", 1e3), (25, "gnss_speed_accuracy_mps", 1e3)):
        if getattr(samples, name) is not None:
            rows[:, column] = getattr(samples, name) * scale
    if samples.gnss_hdop is not None and samples.gnss_vdop is not None:
        h, v, t = samples.gnss_hdop, samples.gnss_vdop, settings["dop_t"]
        p = np.hypot(h, v)
        rows[:, 28:35] = np.column_stack((np.hypot(p, t), p, np.full(len(h), t), v, h, h / math.sqrt(2),
                                          h / math.sqrt(2))) * 100.0
    return rows


class XsensEncoder:
    """Samples -> MTData2 packets, one per sample. Stateful: the packet counter continues across calls."""
    # Axes: the MTi's sensor-fixed frame S is x forward, y left, z up as printed on the housing (at rest
    # acceleration z reads +9.81); orientation is S -> L with L ENU by default, NED or NWU by the coordinate-system
    # bits (the `frame` option): choosing NED or NWU turns L only ("apply the following rotation matrix in
    # RotLocal", MTi User Manual MT0605P.E §4.2.3/5.4), never S. So encode re-expresses the FRD Samples in FLU.
    body_axes, reference = "FLU", "ENU"     # reference: the `frame` option's (the instance's self.reference)
    axes_source = "Xsens MT0605P.E 4.2: sensor frame S x fwd y left z up; L by option frame: ENU, NED, NWU"


    def __init__(self, items=DEFAULT_ITEMS, precision: str = "float32", frame: str = "ENU",
                 mag_reference_gauss: float = MAG_REFERENCE_GAUSS, status_word: int = 0, packet_counter_start: int = 0,
                 precisions: dict | None = None, gnss: dict | None = None):
        """`gnss`: settings of the GnssPvtData record (firmware_protocols.gnss_time.GNSS_DEFAULTS)."""
        self.items = parse_names(items, ITEMS, "items")
        self.gnss = gnss_settings(gnss)
        precisions = dict(precisions or {})
        for name, value in [("precision", precision)] + [(f"precisions[{k}]", v) for k, v in precisions.items()]:
            if value not in PRECISIONS:
                raise ValueError(f"{name}: {value!r}; choose from {', '.join(PRECISIONS)}")
        frame = str(frame).upper()
        if frame not in FRAMES:
            raise ValueError(f"frame: {frame!r}; choose from {', '.join(FRAMES)}")
        mag_reference_gauss = float(mag_reference_gauss)
        if not (mag_reference_gauss > 0 and math.isfinite(mag_reference_gauss)):
            raise ValueError(f"mag_reference_gauss: must be a positive number, got {mag_reference_gauss!r}")
        status_word, packet_counter_start = as_int(status_word), as_int(packet_counter_start)
        if not 0 <= status_word <= 0xFFFFFFFF:
            raise ValueError(f"status_word: must fit in 32 bits, got {status_word!r}")
        self.precision, self.frame = precision, frame
        self.reference = frame                  # the declared reference follows the configuration
        self.mag_reference_gauss = mag_reference_gauss
        self.status_word = status_word
        self.packet_counter = packet_counter_start & 0xFFFF
        self.saturated = SaturationStats()

        payload = bytearray()
        placed = []                   # (item name, payload offset of its data, value kind, value width)
        for name in self.items:
            item = ITEMS[name]
            prec_bits, real_kind, real_size = PRECISIONS[precisions.get(name, precision)]
            kind, width = (real_kind, real_size) if item.real else (item.int_kind, KIND_SIZE[item.int_kind])
            size = sum(KIND_SIZE[k] for k in _RECORDS[name]) if name in _RECORDS else item.count * width
            xdi = item.xdi | (prec_bits if item.real else 0) | (FRAMES[frame] if item.has_frame else 0)
            payload += bytes((xdi >> 8, xdi & 0xFF, size))
            placed.append((name, len(payload), kind, width))
            payload += bytes(size)
        if len(payload) <= 254:
            header = bytes((PREAMBLE, BUS_MASTER, MID_MTDATA2, len(payload)))
        else:
            header = bytes((PREAMBLE, BUS_MASTER, MID_MTDATA2, EXTENDED_LENGTH, len(payload) >> 8,
                            len(payload) & 0xFF))
        columns = []
        for name, offset, kind, width in placed:
            columns += self._columns(name, len(header) + offset, kind, width)
        self._packer = FixedPacketPacker(header + bytes(payload) + b"\x00", columns, CHECKSUM_XBUS, _DEFAULTS)
        self._wants_delta_q = "delta_q" in self.items
        self.uses_increments = self._wants_delta_q or any(ITEMS[n].source in INCREMENT_FIELDS for n in self.items)
        self._wants_utc = "utc_time" in self.items
        self._wants_attitude = bool({"quaternion", "euler_angles"} & set(self.items))
        self._wants_pvt = "gnss_pvt_data" in self.items

    def _columns(self, name: str, position: int, kind: int, width: int) -> list:
        if name == "packet_counter":
            return [Column(kind, position, name, FROM_COUNTER, modulus=1 << 16)]
        if name == "sample_time_fine":
            return [Column(kind, position, name, FROM_TIME_DIV, divisor=NS_PER_TICK, modulus=1 << 32)]
        if name == "sample_time_coarse":
            return [Column(kind, position, name, FROM_TIME_DIV, divisor=1_000_000_000, modulus=1 << 32)]
        if name == "status_word":
            return [Column(kind, position, name, FROM_CONSTANT, constant=float(self.status_word))]
        if name in _RECORDS:
            columns = []
            for c, record_kind in enumerate(_RECORDS[name]):
                columns.append(Column(record_kind, position, name, FROM_FIELD, ITEMS[name].source, c))
                position += KIND_SIZE[record_kind]
            return columns
        item = ITEMS[name]
        if name == "velocity_xyz":
            return [Column(kind, position + c * width, name, FROM_FIELD, item.source, axis, sign)
                    for c, (axis, sign) in enumerate(_VELOCITY_AXES[self.frame])]
        unit = item.unit / self.mag_reference_gauss if name == "magnetic_field" else item.unit
        return [Column(kind, position + c * width, name, FROM_FIELD, item.source, item.first + c, unit)
                for c in range(item.count)]

    @property
    def bytes_per_sample(self) -> int:
        return self._packer.packet_size

    def encode(self, samples: Samples) -> SerialBatch:
        """Samples (FRD, attitude FRD -> NED) -> packets in the MTi's own sensor axes and declared frame."""
        return self.encode_sensor_axes(to_body_axes(samples, self.body_axes))

    def encode_sensor_axes(self, samples: Samples) -> SerialBatch:
        """Samples already in the MTi's sensor frame S (forward-left-up; attitude S -> NED): what the device
        calls after its alignment rotations, which are defined on S."""
        extra = {}
        if self._wants_delta_q and samples.attitude_change is not None:
            samples.require_finite(["attitude_change"])
            extra["delta_q"] = samples.attitude_change
        elif self._wants_delta_q and samples.delta_theta is not None:
            # without the attitudes at the interval's ends (an encoder fed increments alone): the rotation by
            # the increment, which leaves out coning
            samples.require_finite(["delta_theta"])     # name the caller's field, not the derived one
            extra["delta_q"] = attitude.from_rotation_vector(samples.delta_theta)
        if self._wants_attitude and self.frame != "NED":
            # Samples carry sensor -> NED attitude; the XDI declares this encoder's frame, so convert here
            quat = samples.quat if samples.quat is not None else (
                attitude.from_euler(samples.euler) if samples.euler is not None
                else np.broadcast_to(_DEFAULTS["quat"], (len(samples), 4)))
            extra["quat"] = attitude.from_ned(quat, self.frame)
            extra["euler"] = attitude.to_euler(extra["quat"])
        if self._wants_utc:
            extra["utc"] = utc_rows(samples.time_ns, self.gnss)
        if self._wants_pvt:
            extra["gnss_pvt"] = receiver_pvt(samples, self.gnss)
        if samples.start_ns:
            # SampleTimeFine / Coarse are the unit's clock since power-up: the run's start (UtcTime and GnssPvtData,
            # above, took the UTC time_ns)
            samples = copy.copy(samples)
            samples.time_ns = samples.time_ns - np.int64(samples.start_ns)
        batch = self._packer.pack(samples, self.saturated, self.packet_counter, extra)
        self.packet_counter = (self.packet_counter + len(samples)) & 0xFFFF
        return batch


# --- decoding --------------------------------------------------------------------------------

def xbus_length(buf: bytearray, j: int) -> int:
    if len(buf) - j < 4:
        return NEED_MORE
    length = buf[j + 3]
    if length != EXTENDED_LENGTH:
        return 4 + length + 1
    if len(buf) - j < 6:
        return NEED_MORE
    length = (buf[j + 4] << 8) | buf[j + 5]
    if length < 255 or length > MAX_DATA_LENGTH:   # the SDK's sanity check (XsMessageHeader_dataSize)
        return NOT_A_FRAME
    return 6 + length + 1


def xbus_checksum_ok(frame: bytes) -> bool:
    if len(frame) > 512:
        # An extended header may promise 8 KiB; a flood of such false headers costs one sum per byte of
        # input, which numpy does 6x faster than sum() (and sum() is faster on the usual short frames).
        return int(np.frombuffer(frame, np.uint8, offset=1).sum()) & 0xFF == 0
    return sum(frame[1:]) & 0xFF == 0


def _read_reals(data: bytes, precision: int, count: int):
    """Big-endian reals of the given precision bits -> tuple of floats, or None if the size is wrong."""
    width = (4, 4, 6, 8)[precision]
    if len(data) != width * count:
        return None
    if precision == 0:
        return tuple(float(v) for v in np.frombuffer(data, dtype=">f4"))
    if precision == 3:
        return tuple(float(v) for v in np.frombuffer(data, dtype=">f8"))
    if precision == 1:
        return tuple(float(v) / 2.0 ** 20 for v in np.frombuffer(data, dtype=">i4"))
    out = []
    for k in range(count):
        frac = int.from_bytes(data[6 * k:6 * k + 4], "big")
        whole = int.from_bytes(data[6 * k + 4:6 * k + 6], "big", signed=True)
        out.append(((whole << 32) | frac) / 2.0 ** 32)
    return tuple(out)


class XsensDecoder:
    """Bytes -> Packets. MTData2 messages become kind "mtdata2" with SI fields; any other Xbus message
    (acks, errors) becomes kind "xbus" with its message id and raw data. Never raises."""

    def __init__(self, mag_reference_gauss: float = MAG_REFERENCE_GAUSS):
        self.mag_reference_gauss = float(mag_reference_gauss)
        self._scanner = FrameScanner(bytes((PREAMBLE, BUS_MASTER)), xbus_length, xbus_checksum_ok)

    @property
    def stats(self) -> DecoderStats:
        return self._scanner.stats

    def feed(self, chunk: bytes) -> list[Packet]:
        packets = []
        for frame in self._scanner.frames(chunk):
            header = 6 if frame[3] == EXTENDED_LENGTH else 4
            data = frame[header:-1]
            if frame[2] == MID_MTDATA2:
                packets.append(Packet("mtdata2", self._mtdata2_fields(data), frame))
            else:
                packets.append(Packet("xbus", {"mid": frame[2], "data": data}, frame))
            self.stats.packets += 1
        return packets

    def _mtdata2_fields(self, payload: bytes) -> dict:
        fields: dict = {"xdis": []}
        k = 0
        while k < len(payload):
            if len(payload) - k < 3 or len(payload) - k - 3 < payload[k + 2]:
                fields["malformed"] = True      # an item runs past the payload: keep what came before
                break
            xdi = (payload[k] << 8) | payload[k + 1]
            data = payload[k + 3:k + 3 + payload[k + 2]]
            k += 3 + payload[k + 2]
            fields["xdis"].append(xdi)
            self._decode_item(xdi, data, fields)
        return fields

    def _decode_item(self, xdi: int, data: bytes, fields: dict) -> None:
        name = _ITEM_BY_XDI.get(xdi & 0xFFF0)
        item = ITEMS.get(name)
        if item is None and (xdi & 0xFFF0) in _DECODE_ONLY:
            name, item = _DECODE_ONLY[xdi & 0xFFF0]
        if item is None:
            fields.setdefault("unknown", {})[xdi] = data
            return
        if name in _RECORDS:
            if len(data) != sum(KIND_SIZE[k] for k in _RECORDS[name]):
                fields.setdefault("unknown", {})[xdi] = data
                return
            fields[name] = tuple(int(v) for v in np.frombuffer(data, dtype=_RECORD_DTYPES[name])[0])
            return
        if not item.real:
            width = KIND_SIZE[item.int_kind]
            if len(data) != width:
                fields.setdefault("unknown", {})[xdi] = data
                return
            value = int.from_bytes(data, "big")
            if name == "sample_time_fine":
                fields["sample_time_fine"] = value
                fields["time_ns"] = value * NS_PER_TICK     # modulo the 2**32-tick wrap (~5 days)
            elif name == "sample_time_coarse":
                fields["sample_time_coarse"] = value
            elif name == "baro_pressure":
                fields["pressure_pa"] = float(value)
            else:
                fields[name] = value
            return
        values = _read_reals(data, xdi & 0x3, item.count)
        if values is None:
            fields.setdefault("unknown", {})[xdi] = data
            return
        fields.setdefault("precision", {})[name] = next(p for p, v in PRECISIONS.items() if v[0] == xdi & 0x3)
        if item.has_frame:
            fields["frame"] = next((f for f, bits in FRAMES.items() if bits == xdi & 0xC), "reserved")
        si = {"quaternion": "quat", "euler_angles": "euler", "delta_v": "delta_velocity",
              "acceleration": "accel", "acceleration_hr": "accel_hr", "rate_of_turn": "gyro",
              "rate_of_turn_hr": "gyro_hr", "magnetic_field": "mag", "temperature": "temperature_c",
              "delta_q": "delta_q", "free_acceleration": "free_accel", "lat_lon": "lat_lon",
              "altitude_ellipsoid": "altitude_ellipsoid", "velocity_xyz": "velocity"}[name]
        if name == "magnetic_field":
            fields["mag_au"] = values
            values = tuple(v * self.mag_reference_gauss for v in values)
        elif name == "euler_angles":
            values = tuple(math.radians(v) for v in values)
        fields[si] = values[0] if item.count == 1 else values


_OPTIONS = {
    "items": "comma-separated MTData2 items in wire order; "
             f"known: {', '.join(ITEMS)}",
    "precision": "float32, float64, fp1220 or fp1632 for real-valued items",
    "precisions": "per-item precision overriding `precision`, e.g. {acceleration = 'fp1632'}",
    "frame": "ENU, NED or NWU: declared in the orientation and velocity XDIs; attitude and velocity are "
             "converted to it",
    "mag_reference_gauss": "field strength in gauss that reads 1.0 arbitrary unit, > 0 (default 0.49, ArduPilot's)",
    "status_word": "constant StatusWord value 0..0xFFFFFFFF",
    "packet_counter_start": "first PacketCounter value 0..65535; wraps 65535 -> 0",
    "gnss": "GnssPvtData / UtcTime settings (firmware_protocols.gnss_time.GNSS_DEFAULTS), e.g. {num_sats = 9}",
}

register(FormatInfo(
    name="xsens-mtdata2",
    kind="serial",
    description="Xsens MTi MTData2 (Xbus MID 0x36), big-endian items, byte-sum checksum",
    encoder=XsensEncoder,
    decoder=XsensDecoder,
    bytes_per_sample=XsensEncoder().bytes_per_sample,
    options=_OPTIONS,
))
