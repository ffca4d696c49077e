"""DroneCAN air data and GNSS, and the GNSS/compass/baro node they make together.

Messages (DSDL as shipped with pydronecan, dronecan/dsdl_specs/uavcan/equipment/; StaticPressure and
StaticTemperature, like ahrs.MagneticFieldStrength2, go out only where Samples.baro_new / mag_new mark a new
reading, every sample without the flags):

- 1028 air_data.StaticPressure, signature 0xCDC7C43412BDC89A: float32 static_pressure (Pa) |
  float16 static_pressure_variance (Pa^2, the `pressure_variance_pa2` option, default 0) = 6 bytes, one frame.
- 1029 air_data.StaticTemperature, signature 0x49272A6477D96271: float16 static_temperature (K, = degC +
  273.15) | float16 static_temperature_variance (K^2, `temperature_variance_k2`, default 0) = 4 bytes.
- 1063 gnss.Fix2, signature 0xCA41E7000F37435F, bit-packed (each field's little-endian bits written most
  significant bit first, libcanard's canardEncodeScalar): uint56 timestamp | uint56 gnss_timestamp |
  uint3 gnss_time_standard | void13 | uint8 num_leap_seconds | int37 longitude_deg_1e8 | int37 latitude_deg_1e8 |
  int27 height_ellipsoid_mm | int27 height_msl_mm | float32[3] ned_velocity | uint6 sats_used | uint2 status |
  uint4 mode | uint6 sub_mode | float16[<=36] covariance (6-bit length) | float16 pdop |
  ECEFPositionVelocity[<=1] (empty; the tail array, so no length on classic CAN) = 62 bytes, 10 frames.
  On CAN FD pydronecan packs without the tail array optimisation: the empty array's 1-bit length makes 63
  bytes, one 64-byte frame.

Fix2 values: timestamp = gnss_timestamp = the solution's time of validity, (time_ns - gnss_age_s) // 1000 us,
with gnss_time_standard UTC (2) (time_ns is UTC Unix ns: the run's --start-time + scene time,
firmware_protocols.gnss_time) and num_leap_seconds = gnss_time.GNSS_DEFAULTS["leap_seconds"]; longitude/latitude x 1e8,
heights in mm (no geoid model: height_msl =
ellipsoid height, as gnss_time's records); ned_velocity m/s; sats_used (0..63); status from Samples.gnss_fix
(0 no fix, 2 2D, 3 3D); mode SINGLE; covariance the diagonal [h^2, h^2, v^2, s^2, s^2, s^2] of the horizontal,
vertical and speed 1-sigma accuracies (what ArduPilot's AP_GPS_DroneCAN reads back as sqrt(cov[0]), sqrt(cov[2]),
sqrt(mean(cov[3:6]))); pdop = hypot(HDOP, VDOP). Absent quality fields take gnss_time.GNSS_DEFAULTS, an absent
receiver solution the sample's position_llh/velocity_ned (as MAVLink's GNSS messages do), neither: status NO_FIX.

The node ("dronecan-gnss-compass-baro"): one node id publishing ahrs.MagneticFieldStrength2 (gauss) on each new
magnetometer reading (Samples.mag_new), StaticPressure then StaticTemperature on each new barometer reading
(baro_new), Fix2 at each new GNSS solution (gnss_new): the scene's companion rates; each flag None means every
sample (the retired options `mag_rate_hz` / `baro_rate_hz` are refused in one line). A compass or baro message whose inputs are absent (no mag,
no pressure, no temperature) is not sent; Fix2 always is, with status NO_FIX when there is no position at all
(a receiver without a fix still reports, and ArduPilot then shows the GPS as present without a fix).
What ArduPilot expects (ArduPilot/ardupilot libraries/AP_Baro/AP_Baro_DroneCAN.cpp at 19351d4b,
AP_Compass/AP_Compass_DroneCAN.cpp at ee0da68c, AP_GPS/AP_GPS_DroneCAN.cpp at 00bc4884): a baro is registered by
the first StaticPressure from a node; StaticTemperature is taken only from a node already registered, in K
(KELVIN_TO_C); compass field in gauss (x 1000 to mGauss); Fix2 status 2/3 with lat/lon_deg_1e8 / 10, height_msl,
ned_velocity, covariance of 6, sats_used, pdop used for HDOP/VDOP when no Auxiliary message is seen.
"""
from __future__ import annotations


import numpy as np

from firmware_protocols.base import EncodeError, SaturationStats, Samples, empty_frames, saturate, to_int_field
from firmware_protocols.crc import crc16_ccitt_bytes
from firmware_protocols.gnss_time import GNSS_DEFAULTS, receiver_solution
from firmware_protocols.registry import FormatInfo, register
from firmware_protocols.update_rate import new_readings, refuse_retired, retired_help
from firmware_protocols.wire_formats.dronecan import (_COMMON_OPTIONS, OP_F16, OP_F32, DroneCanDecoder,
                                                      MagneticFieldStrength2Encoder, _DroneCanEncoder,
                                                      _f16_from_f32_bits, _Message, _half, _single, can_id_for,
                                                      transfer_frames)

KELVIN_OFFSET = 273.15
FLOAT16_MAX = 65504.0
FLOAT32_MAX = float(np.finfo(np.float32).max)
STATIC_PRESSURE_ID, STATIC_PRESSURE_SIGNATURE = 1028, 0xCDC7C43412BDC89A
STATIC_TEMPERATURE_ID, STATIC_TEMPERATURE_SIGNATURE = 1029, 0x49272A6477D96271
FIX2_ID, FIX2_SIGNATURE = 1063, 0xCA41E7000F37435F
TIME_STANDARD_UTC = 2
STATUS_NO_FIX = 0


def f16_bits(value: float) -> int:
    """libuavcan's float16 (ties away from zero) of a finite value within +-65504."""
    return int(_f16_from_f32_bits(int(np.array(value, dtype=np.float32).view(np.uint32))))


def _variance(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= FLOAT16_MAX:
        raise ValueError(f"{name}: a number 0..{FLOAT16_MAX:g}, got {value!r}")
    return float(value)


# value then variance, each a source column the kernel converts (float16 as libuavcan rounds it)
STATIC_PRESSURE = _Message("uavcan.equipment.air_data.StaticPressure", STATIC_PRESSURE_ID, STATIC_PRESSURE_SIGNATURE,
                           [(OP_F32, 0, 0, 0), (OP_F16, 1, 0, 1)], sources=["pressure_pa", "pressure_variance_pa2"],
                           counters=["static_pressure", "static_pressure_variance"], tail_array=False)
STATIC_TEMPERATURE = _Message("uavcan.equipment.air_data.StaticTemperature", STATIC_TEMPERATURE_ID,
                              STATIC_TEMPERATURE_SIGNATURE, [(OP_F16, 0, 0, 0), (OP_F16, 1, 0, 1)],
                              sources=["temperature_c", "temperature_variance_k2"],
                              counters=["static_temperature", "static_temperature_variance"], tail_array=False)


class StaticPressureEncoder(_DroneCanEncoder):
    """Static pressure in Pa from Samples.pressure_pa (101325 Pa when absent), on the barometer's new readings (Samples.baro_new)."""
    new_flag = "baro_new"
    frames_vary = True

    message = STATIC_PRESSURE

    def __init__(self, pressure_variance_pa2: float = 0.0, **options):
        self.variance = _variance("pressure_variance_pa2", pressure_variance_pa2)
        super().__init__(**options)

    def _program(self, samples: Samples):
        return self.message, (samples.field_or("pressure_pa", 101325.0).reshape(-1, 1),
                              np.full((len(samples), 1), self.variance))


class StaticTemperatureEncoder(_DroneCanEncoder):
    """Static temperature in K from Samples.temperature_c (25 degC when absent), on the barometer's new readings (Samples.baro_new)."""
    new_flag = "baro_new"
    frames_vary = True

    message = STATIC_TEMPERATURE

    def __init__(self, temperature_variance_k2: float = 0.0, **options):
        self.variance = _variance("temperature_variance_k2", temperature_variance_k2)
        super().__init__(**options)

    def _program(self, samples: Samples):
        return self.message, ((samples.field_or("temperature_c", 25.0) + KELVIN_OFFSET).reshape(-1, 1),
                              np.full((len(samples), 1), self.variance))


# --- Fix2 ---------------------------------------------------------------------------------------

class _Bits:
    """A DSDL bit stream: each value's little-endian bytes, the last one holding only its low bits, copied most
    significant bit first (libcanard canardEncodeScalar + copyBitArray). Kept as one Python integer."""

    def __init__(self):
        self.value = 0
        self.count = 0

    def put(self, value: int, width: int) -> None:
        value &= (1 << width) - 1
        sequence = 0
        for shift in range(0, width, 8):
            used = min(8, width - shift)                 # bits of this byte in the field (the last may be short)
            sequence = (sequence << used) | ((value >> shift) & ((1 << used) - 1))
        self.value = (self.value << width) | sequence
        self.count += width

    def bytes(self) -> bytes:
        pad = -self.count % 8
        return (self.value << pad).to_bytes((self.count + pad) // 8, "big")


class _Fix2Message:
    """What the decoder needs of Fix2 (its layout is written by Fix2Encoder, read by _parse_fix2)."""

    name = "uavcan.equipment.gnss.Fix2"
    dtid = FIX2_ID
    signature = FIX2_SIGNATURE
    signature_crc = crc16_ccitt_bytes(FIX2_SIGNATURE.to_bytes(8, "little"), 0xFFFF)
    payload_len = {False: 62, True: 63}


FIX2 = _Fix2Message()


def _signed_range(bits: int) -> tuple:
    return -(1 << (bits - 1)), (1 << (bits - 1)) - 1


class Fix2Encoder:
    """Samples -> gnss.Fix2 transfers (classic CAN), one at each new solution; frame rows as the other encoders."""
    # Axes: no body vector; Fix2's ned_velocity is north, east, down (DSDL 1063.Fix2).
    body_axes, reference = "FRD", "NED"
    axes_source = "DSDL 1063.Fix2: ned_velocity north, east, down; no body vectors"

    frames_vary = True     # a transfer only at samples with a new solution

    _CHECKED = ("gnss_llh", "gnss_velocity_ned", "gnss_fix", "gnss_satellites", "gnss_hdop", "gnss_vdop",
                "gnss_horizontal_accuracy_m", "gnss_vertical_accuracy_m", "gnss_speed_accuracy_mps", "gnss_age_s",
                "position_llh", "velocity_ned")

    def __init__(self, node_id: int = 42, priority: int = 31, fd: bool = False, transfer_id: int = 0):
        if not 1 <= int(node_id) <= 127:
            raise ValueError(f"node_id must be 1..127 (0 is anonymous), got {node_id}")
        if not 0 <= int(priority) <= 31:
            raise ValueError(f"priority must be 0..31, got {priority}")
        self.node_id, self.priority, self.fd = int(node_id), int(priority), bool(fd)
        self.transfer_id = int(transfer_id) & 0x1F
        self.can_id = can_id_for(FIX2_ID, self.node_id, self.priority)
        self.saturated = SaturationStats()
        self._lengths = tuple(len(f) for f in transfer_frames(bytes(FIX2.payload_len[self.fd]), FIX2_SIGNATURE, 0,
                                                              self.fd))

    @property
    def frames_per_sample(self) -> tuple:
        return tuple((length, True, False) for length in self._lengths)

    def _wire(self, samples: Samples, index: np.ndarray) -> dict:
        """The block's wire values at `index`, saturated (and counted) in one pass per field."""
        g = {k: v[index] for k, v in receiver_solution(samples).items()}
        g["status"] = np.where(np.isin(g["fix"], (2, 3)), g["fix"], STATUS_NO_FIX)
        g["pdop"] = np.hypot(g["hdop"], g["vdop"])
        g["h"], g["v"], g["s"] = g["h_acc"], g["v_acc"], g["s_acc"]
        sat = self.saturated
        age_ns = np.rint(samples.field_or("gnss_age_s", 0.0)[index] * 1e9).astype(np.int64)
        usec = (samples.time_ns[index] - age_ns) // 1000
        sat.add("timestamp", int(np.count_nonzero(usec < 0)))
        llh = g["llh"]
        ints = {name: to_int_field(values, scale, 0, *_signed_range(bits), name, sat, np.int64)
                for name, values, scale, bits in (("longitude_deg_1e8", llh[:, 1], 1e-8, 37),
                                                  ("latitude_deg_1e8", llh[:, 0], 1e-8, 37),
                                                  ("height_ellipsoid_mm", llh[:, 2], 1e-3, 27))}
        variances = np.column_stack([g["h"] ** 2, g["h"] ** 2, g["v"] ** 2, g["s"] ** 2, g["s"] ** 2, g["s"] ** 2])
        halves = np.column_stack([saturate(variances, -FLOAT16_MAX, FLOAT16_MAX, "covariance", sat),
                                  saturate(g["pdop"], -FLOAT16_MAX, FLOAT16_MAX, "pdop", sat)])
        return {"usec": np.maximum(usec, 0), **ints,
                "velocity": saturate(g["vel"], -FLOAT32_MAX, FLOAT32_MAX, "ned_velocity", sat).astype(np.float32)
                .view(np.uint32).astype(np.int64),
                "sats": to_int_field(g["sats"], 1, 0, 0, 63, "sats_used", sat, np.int64),
                "status": g["status"].astype(np.int64),
                "halves": [[f16_bits(v) for v in row] for row in halves.tolist()]}

    def payload(self, w: dict, k: int) -> bytes:
        """Transfer k of the block's wire values `w` as DSDL bytes."""
        usec = int(w["usec"][k])
        height_mm = int(w["height_ellipsoid_mm"][k])
        bits = _Bits()
        for value, width in ((usec, 56), (usec, 56), (TIME_STANDARD_UTC, 3), (0, 13),
                             (int(GNSS_DEFAULTS["leap_seconds"]), 8), (int(w["longitude_deg_1e8"][k]), 37),
                             (int(w["latitude_deg_1e8"][k]), 37), (height_mm, 27), (height_mm, 27),
                             *((int(v), 32) for v in w["velocity"][k]), (int(w["sats"][k]), 6),
                             (int(w["status"][k]), 2), (0, 4), (0, 6),       # MODE_SINGLE, sub_mode
                             (6, 6),            # covariance: the diagonal of position N, E, D and velocity N, E, D
                             *((h, 16) for h in w["halves"][k])):             # six variances, then pdop
            bits.put(value, width)
        if self.fd:
            bits.put(0, 1)       # ecef_position_velocity's length: no tail array optimisation on FD
        return bits.bytes()

    def encode(self, samples: Samples) -> np.ndarray:
        samples.require_finite(("gnss_new",))
        due = np.ones(len(samples), bool) if samples.gnss_new is None else samples.gnss_new != 0
        picked = np.flatnonzero(due)
        per = len(self._lengths)
        frames = empty_frames(len(picked) * per, self.fd)
        if not len(picked):
            return frames          # the held solution between fixes is not sent, so not checked either
        samples.require_finite(self._CHECKED, picked)
        wire = self._wire(samples, picked)
        width = frames["data"].shape[1]
        data = bytearray()
        for k in range(len(picked)):
            for chunk in transfer_frames(self.payload(wire, k), FIX2_SIGNATURE, self.transfer_id, self.fd):
                data += chunk.ljust(width, b"\0")
            self.transfer_id = (self.transfer_id + 1) & 0x1F
        frames["data"] = np.frombuffer(bytes(data), dtype=np.uint8).reshape(-1, width)
        frames["sample"] = np.repeat(picked, per)
        frames["can_id"], frames["extended"], frames["fd"] = self.can_id, True, self.fd
        frames["length"] = np.tile(self._lengths, len(picked))
        return frames


# --- the node -----------------------------------------------------------------------------------

class GnssCompassBaroEncoder:
    """One node's messages: MagneticFieldStrength2, StaticPressure, StaticTemperature, Fix2, each at its rate."""
    # Axes: the magnetic field in the body axes RawIMU names (X forward, Y right, Z down), as ArduPilot's
    # AP_Compass_DroneCAN reads it; Fix2's velocity NED.
    body_axes, reference = "FRD", "NED"
    axes_source = "DSDL 1002.MagneticFieldStrength2 body axes as 1003.RawIMU (X forward, Y right, Z down); Fix2 NED"

    frames_vary = True     # frames_per_sample is the worst case (every message due at one sample)

    def __init__(self, node_id: int = 42, priority: int = 31, fd: bool = False, transfer_id: int = 0,
                 sensor_id: int = 0, mag_rate_hz: float | None = None, baro_rate_hz: float | None = None,
                 pressure_variance_pa2: float = 0.0, temperature_variance_k2: float = 0.0):
        common = dict(node_id=node_id, priority=priority, fd=fd, transfer_id=transfer_id)
        self.mag = MagneticFieldStrength2Encoder(sensor_id=sensor_id, **common)
        self.pressure = StaticPressureEncoder(pressure_variance_pa2, **common)
        self.temperature = StaticTemperatureEncoder(temperature_variance_k2, **common)
        self.fix = Fix2Encoder(**common)
        self.node_id, self.fd = self.mag.node_id, self.mag.fd
        refuse_retired(mag_rate_hz=mag_rate_hz, baro_rate_hz=baro_rate_hz)
        self.saturated = SaturationStats()

    @property
    def frames_per_sample(self) -> tuple:
        """The worst case: every message due at one sample."""
        return sum((e.frames_per_sample for e in (self.mag, self.pressure, self.temperature, self.fix)), ())

    def encode(self, samples: Samples) -> np.ndarray:
        parts = []
        samples.require_finite(("mag_new", "baro_new"))
        mag_due, baro_due = new_readings(samples.mag_new, len(samples)), new_readings(samples.baro_new, len(samples))
        # between readings (a device's sample, mostly) a message is left out before building anything for it
        if samples.mag is not None and mag_due.any():
            parts.append(self._at(self.mag, samples, mag_due))
        if samples.pressure_pa is not None and baro_due.any():
            parts.append(self._at(self.pressure, samples, baro_due))
            if samples.temperature_c is not None:     # ArduPilot takes temperature only from a registered baro
                parts.append(self._at(self.temperature, samples, baro_due))
        parts.append(self.fix.encode(samples))
        for encoder in (self.mag, self.pressure, self.temperature, self.fix):
            for name, count in encoder.saturated.counts.items():
                self.saturated.add(name, count)
            encoder.saturated.counts.clear()
        if not parts:
            return empty_frames(0, self.fd)
        if len({p.dtype for p in parts}) > 1:
            parts = [p.astype(parts[0].dtype) if p.dtype != parts[0].dtype else p for p in parts]
        frames = np.concatenate(parts)
        # by sample; within a sample mag, pressure, temperature, fix, each transfer's frames in order
        return frames[np.argsort(frames["sample"], kind="stable")]

    @staticmethod
    def _at(encoder, samples: Samples, due: np.ndarray) -> np.ndarray:
        index = np.flatnonzero(due)
        if len(index) == len(samples):
            return encoder.encode(samples)
        kw = {name: getattr(samples, name)[index] for name in ("accel", "gyro")}
        for name in ("mag", "pressure_pa", "temperature_c"):
            value = getattr(samples, name)
            kw[name] = None if value is None else value[index]
        frames = encoder.encode(Samples(samples.time_ns[index], **kw, start_ns=samples.start_ns))
        frames["sample"] = index[frames["sample"]]
        return frames


# --- decoding -----------------------------------------------------------------------------------

def _parse_static_pressure(p: bytes) -> dict:
    return {"pressure_pa": float(_single(p, 0, 1)[0]), "variance": float(_half(p, 4, 1)[0])}


def _parse_static_temperature(p: bytes) -> dict:
    kelvin = float(_half(p, 0, 1)[0])
    return {"temperature_c": kelvin - KELVIN_OFFSET, "temperature_k": kelvin, "variance": float(_half(p, 2, 1)[0])}


class _BitReader:
    """The inverse of _Bits."""

    def __init__(self, data: bytes):
        self.value = int.from_bytes(data, "big")
        self.left = 8 * len(data)

    def get(self, width: int, signed: bool = False) -> int:
        if width > self.left:
            raise EncodeError("Fix2 payload too short")      # caught by the decoder: counted as ignored
        self.left -= width
        sequence = (self.value >> self.left) & ((1 << width) - 1)
        value, shift = 0, 0
        for start in range(0, width, 8):
            used = min(8, width - start)
            byte = (sequence >> (width - start - used)) & ((1 << used) - 1)
            value |= byte << shift
            shift += 8
        if signed and value >> (width - 1):
            value -= 1 << width
        return value


def _parse_fix2(p: bytes) -> dict:
    r = _BitReader(p)
    timestamp, gnss_timestamp, standard = r.get(56), r.get(56), r.get(3)
    r.get(13)
    leap = r.get(8)
    lon, lat = r.get(37, True) / 1e8, r.get(37, True) / 1e8
    h_ell, h_msl = r.get(27, True) / 1e3, r.get(27, True) / 1e3
    vel = [float(np.array(r.get(32), dtype=np.uint32).view(np.float32)) for _ in range(3)]
    sats, status, mode, sub_mode = r.get(6), r.get(2), r.get(4), r.get(6)
    cov = [float(np.array(r.get(16), dtype=np.uint16).view(np.float16)) for _ in range(r.get(6))]
    pdop = float(np.array(r.get(16), dtype=np.uint16).view(np.float16))
    return {"time_ns": timestamp * 1000, "gnss_timestamp_us": gnss_timestamp, "gnss_time_standard": standard,
            "num_leap_seconds": leap, "llh": (lat, lon, h_ell), "height_msl_m": h_msl, "velocity_ned": vel,
            "sats_used": sats, "status": status, "mode": mode, "sub_mode": sub_mode, "covariance": cov, "pdop": pdop}


SENSOR_MESSAGES = {
    STATIC_PRESSURE_ID: (STATIC_PRESSURE, _parse_static_pressure),
    STATIC_TEMPERATURE_ID: (STATIC_TEMPERATURE, _parse_static_temperature),
    FIX2_ID: (FIX2, _parse_fix2),
}


def _decoder(*ids):
    return lambda **_: DroneCanDecoder(ids, messages=SENSOR_MESSAGES)


def _frames(encoder) -> tuple:
    return encoder.frames_per_sample


register(FormatInfo(
    name="dronecan-static-pressure", kind="can",
    description="DroneCAN uavcan.equipment.air_data.StaticPressure (id 1028): static pressure, Pa",
    encoder=StaticPressureEncoder, decoder=_decoder(STATIC_PRESSURE_ID), frames_per_sample=_frames(
        StaticPressureEncoder()),
    options={**_COMMON_OPTIONS, "pressure_variance_pa2": "static_pressure_variance to send, Pa^2 (default 0)"},
))
register(FormatInfo(
    name="dronecan-static-temperature", kind="can",
    description="DroneCAN uavcan.equipment.air_data.StaticTemperature (id 1029): static temperature, K",
    encoder=StaticTemperatureEncoder, decoder=_decoder(STATIC_TEMPERATURE_ID),
    frames_per_sample=_frames(StaticTemperatureEncoder()),
    options={**_COMMON_OPTIONS, "temperature_variance_k2": "static_temperature_variance to send, K^2 (default 0)"},
))
register(FormatInfo(
    name="dronecan-fix2", kind="can",
    description="DroneCAN uavcan.equipment.gnss.Fix2 (id 1063): the GNSS fix, on each new solution",
    encoder=Fix2Encoder, decoder=_decoder(FIX2_ID), frames_per_sample=_frames(Fix2Encoder()),
    options=dict(_COMMON_OPTIONS),
))
register(FormatInfo(
    name="dronecan-gnss-compass-baro", kind="can",
    description="DroneCAN GNSS/compass/baro node: MagneticFieldStrength2, StaticPressure/Temperature, Fix2",
    encoder=GnssCompassBaroEncoder, decoder=_decoder(1002, STATIC_PRESSURE_ID, STATIC_TEMPERATURE_ID, FIX2_ID),
    frames_per_sample=_frames(GnssCompassBaroEncoder()),
    options={**_COMMON_OPTIONS, "sensor_id": "compass sensor id 0..255",
             "mag_rate_hz": retired_help("mag_rate_hz"), "baro_rate_hz": retired_help("baro_rate_hz"),
             "pressure_variance_pa2": "static_pressure_variance, Pa^2 (default 0)",
             "temperature_variance_k2": "static_temperature_variance, K^2 (default 0)"},
))
