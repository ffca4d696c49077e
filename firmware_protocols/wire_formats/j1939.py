"""SAE J1939 inertial messages: Angular Rate Information (ARI) and Acceleration Sensor (ACCS).

29-bit id: priority(3) << 26 | EDP(0) DP(0) | PF << 16 | PS << 8 | source address; for PF >= 240 the PS byte
is part of the PGN (broadcast). Signals little-endian, 8-byte frames.

ARI, PGN 61482 (0xF02A), default priority 3:
  bytes 0-1 pitch rate, 2-3 roll rate, 4-5 yaw rate: u16, 1/128 deg/s per bit, offset -250 deg/s
  byte 6 figures of merit, 2 bits each: pitch (bits 48-49), roll (50-51), yaw (52-53); bits 54-55 sent 0b11
  byte 7 measurement latency, 0.5 ms per bit
ACCS, PGN 61485 (0xF02D), default priority 2:
  bytes 0-1 lateral, 2-3 longitudinal, 4-5 vertical: u16, 0.01 m/s² per bit, offset -320 m/s²
  byte 6 figures of merit lateral/longitudinal/vertical at bits 48/50/52; bits 54-55 sent 0b00; byte 7 0xFF
(bits 54-55 and ACCS byte 7 as in the spec's vectors.)

J1939 reserves the top of each parameter's raw range (two-byte parameters: 0xFB00-0xFDFF reserved,
0xFE00-0xFEFF error, 0xFF00-0xFFFF not available; one byte: 0xFB-0xFF), so out-of-range values saturate to
0xFAFF (ARI: 251.99 deg/s, ACCS: 322.55 m/s²) or 0xFA (latency 125 ms), never into those codes. The same
valid span is quoted by Aceinna's J1939 IMU documentation ("-250 to +252 deg/s", Aceinna/docs_openrtk
tutorial/CAN/CAN_J1939_DataPacketMessages.rst).

Axis mapping. Vendors disagree on which sensor axis and sign feeds each J1939 quantity, so it is an
option (`AxisMap`: for each wire quantity the sensor axis index and a sign). Default: pitch rate = +gyro y,
roll rate = +gyro x, yaw rate = +gyro z; lateral = +accel y, longitudinal = +accel x, vertical = -accel z.
That is the spec's vector: with the common forward-right-down sample (at rest accel z = -9.81) it puts
+9.81 m/s² on vertical (up positive, as J1939 inclination/acceleration sensors report gravity) and the
rates unchanged.
"""
from __future__ import annotations

import math

import numpy as np

from firmware_protocols.base import CanStreamDecoder, DecoderStats, Packet, SaturationStats, Samples, to_int_field
from firmware_protocols.can_signals import AxisMap, Signal, SignalLayout, axis_map
from firmware_protocols.registry import FormatInfo, register

PGN_ARI = 0xF02A
PGN_ACCS = 0xF02D

RATE_SCALE_DEG = 1.0 / 128.0
RATE_OFFSET_DEG = -250.0
ACCEL_SCALE = 0.01
ACCEL_OFFSET = -320.0
LATENCY_SCALE_S = 0.0005
U16_VALID_MAX = 0xFAFF
U8_VALID_MAX = 0xFA


# --- J1939 ------------------------------------------------------------------------------------

DEFAULT_RATE_MAP = AxisMap((1, 0, 2), (1, 1, 1))          # pitch, roll, yaw
DEFAULT_ACCEL_MAP = AxisMap((1, 0, 2), (1, 1, -1))        # lateral, longitudinal, vertical


def j1939_id(priority: int, pgn: int, source_address: int) -> int:
    return (priority & 0x7) << 26 | (pgn & 0x3FFFF) << 8 | (source_address & 0xFF)


def _fom_byte(foms, high_bits: int) -> int:
    if len(foms) != 3 or any(not 0 <= int(f) <= 3 for f in foms):
        raise ValueError(f"figures of merit must be three values 0..3, got {foms}")
    return int(foms[0]) | int(foms[1]) << 2 | int(foms[2]) << 4 | high_bits << 6


class J1939Encoder:
    """ARI then ACCS for every sample.

    Figures of merit: 0 fully functional (default), 1 degraded, 2 error, 3 not available.
    latency_s: the ARI latency byte (0.5 ms per bit, 0..125 ms); default 2.5 ms as in the spec's vector.
    """
    # Axes: the AxisMaps read FRD vectors (the module docstring: vertical = -accel z puts +g up at rest); J1939
    # itself names quantities (pitch, roll, yaw rate; lateral, longitudinal, vertical), not axes. No attitude.
    body_axes, reference = "FRD", None
    axes_source = "SAE J1939-71 ARI/ACCS name quantities, not axes: the rate_axes/accel_axes maps read FRD"


    def __init__(self, source_address: int = 0x90, ari_priority: int = 3, accs_priority: int = 2,
                 rate_axes=DEFAULT_RATE_MAP, accel_axes=DEFAULT_ACCEL_MAP,
                 rate_fom=(0, 0, 0), accel_fom=(0, 0, 0), latency_s: float = 0.0025):
        if not 0 <= int(source_address) <= 253:
            raise ValueError(f"source_address must be 0..253 (254 null, 255 global), got {source_address}")
        for name, value in (("ari_priority", ari_priority), ("accs_priority", accs_priority)):
            if not 0 <= int(value) <= 7:
                raise ValueError(f"{name} must be 0..7, got {value}")
        if not (math.isfinite(latency_s) and latency_s >= 0):
            raise ValueError(f"latency_s must be a non-negative number, got {latency_s}")
        self.source_address = int(source_address)
        self.rate_axes = axis_map(rate_axes)
        self.accel_axes = axis_map(accel_axes)
        self.ids = (j1939_id(int(ari_priority), PGN_ARI, self.source_address),
                    j1939_id(int(accs_priority), PGN_ACCS, self.source_address))
        self.saturated = SaturationStats()
        latency = int(to_int_field(np.array([latency_s]), LATENCY_SCALE_S, 0.0, 0, U8_VALID_MAX,
                                   "latency", self.saturated, np.int64)[0])
        template = np.zeros((2, 8))
        template[0, 6:] = _fom_byte(rate_fom, 0b11), latency
        template[1, 6:] = _fom_byte(accel_fom, 0b00), 0xFF
        # sources: gyro x y z (0-2), accel x y z (3-5)
        signals = []
        for i, name in enumerate(("pitch_rate", "roll_rate", "yaw_rate")):
            signals.append(Signal(name, 0, 2 * i, 2, self.rate_axes.axes[i], math.degrees(1.0) * self.rate_axes.signs[i],
                                  RATE_SCALE_DEG, RATE_OFFSET_DEG, 0, U16_VALID_MAX))
        for i, name in enumerate(("lateral_acceleration", "longitudinal_acceleration", "vertical_acceleration")):
            signals.append(Signal(name, 1, 2 * i, 2, 3 + self.accel_axes.axes[i], self.accel_axes.signs[i],
                                  ACCEL_SCALE, ACCEL_OFFSET, 0, U16_VALID_MAX))
        self.layout = SignalLayout(self.ids, True, template, signals)

    frames_per_sample = ((8, True, False), (8, True, False))

    def encode(self, samples: Samples) -> np.ndarray:
        samples.require_finite(("gyro", "accel"))
        return self.layout.pack(np.column_stack((samples.gyro, samples.accel)), 0, self.saturated)


def _u16_si(data: bytes, byte: int, scale: float, offset: float) -> float:
    raw = data[byte] | data[byte + 1] << 8
    return raw * scale + offset if raw <= U16_VALID_MAX else math.nan


class J1939Decoder(CanStreamDecoder):
    """ARI / ACCS frames from any source address -> packets in SI (rad/s, m/s², s).

    Raw values in J1939's error / not-available ranges decode to NaN. `gyro` / `accel` give the same
    vector back in sensor axes through the decoder's axis maps (the encoder's defaults unless told).
    """

    def __init__(self, rate_axes=DEFAULT_RATE_MAP, accel_axes=DEFAULT_ACCEL_MAP, source_address: int | None = None):
        self.rate_axes = axis_map(rate_axes)
        self.accel_axes = axis_map(accel_axes)
        self.source_address = source_address
        self.stats = DecoderStats()

    def _feed(self, can_id, data, extended, fd):
        pgn = (can_id >> 8) & 0x3FFFF
        source = can_id & 0xFF
        if (not extended or can_id > 0x1FFFFFFF or len(data) != 8 or pgn not in (PGN_ARI, PGN_ACCS)
                or (self.source_address is not None and source != self.source_address)):
            self.stats.ignored_frames += 1
            return []
        fom = (data[6] & 3, data[6] >> 2 & 3, data[6] >> 4 & 3)
        common = {"source_address": source, "priority": can_id >> 26 & 7, "figure_of_merit": fom}
        if pgn == PGN_ARI:
            rates = np.radians([_u16_si(data, b, RATE_SCALE_DEG, RATE_OFFSET_DEG) for b in (0, 2, 4)])
            latency = data[7] * LATENCY_SCALE_S if data[7] <= U8_VALID_MAX else math.nan
            fields = {"pitch_rate": rates[0], "roll_rate": rates[1], "yaw_rate": rates[2],
                      "gyro": self.rate_axes.to_sensor(rates), "latency_s": latency, **common}
            kind = "ARI"
        else:
            acc = np.array([_u16_si(data, b, ACCEL_SCALE, ACCEL_OFFSET) for b in (0, 2, 4)])
            fields = {"lateral_acceleration": acc[0], "longitudinal_acceleration": acc[1],
                      "vertical_acceleration": acc[2], "accel": self.accel_axes.to_sensor(acc), **common}
            kind = "ACCS"
        self.stats.packets += 1
        return [Packet(kind=kind, fields=fields, raw=data)]


register(FormatInfo(
    name="j1939", kind="can",
    description="SAE J1939 Angular Rate Information (PGN 61482) + Acceleration Sensor (PGN 61485) per sample",
    encoder=J1939Encoder,
    decoder=lambda rate_axes=DEFAULT_RATE_MAP, accel_axes=DEFAULT_ACCEL_MAP, **_: J1939Decoder(rate_axes, accel_axes),
    frames_per_sample=J1939Encoder.frames_per_sample,
    options={
        "source_address": "J1939 source address 0..253",
        "ari_priority": "ARI priority 0..7",
        "accs_priority": "ACCS priority 0..7",
        "rate_axes": "(axes, signs) feeding pitch, roll, yaw rate; axes 0..2, signs +-1",
        "accel_axes": "(axes, signs) feeding lateral, longitudinal, vertical; axes 0..2, signs +-1",
        "rate_fom": "figures of merit pitch, roll, yaw, each 0..3 (0: fully functional)",
        "accel_fom": "figures of merit lateral, longitudinal, vertical, each 0..3",
        "latency_s": "ARI latency byte in s, 0..0.125 in 0.5 ms steps",
    },
))
