"""Bosch MM7.10 inertial sensor: three classic CAN frames (11-bit ids) per sample.

Layout (little-endian unsigned; bit numbers as in Bosch's own ROS driver, bosch-engineering/
off_highway_sensor_drivers, off_highway_mm7p10/src/receiver.cpp, which matches the spec):
  0x174 TX1: yaw rate 0-15 | CLU_STAT 16-19 | YawRate_STAT 20-23 | TEMP_RATE_Z 24-31 (1 °C, -50 °C) |
             AY 32-47 | MSG_CNT 48-51 | AY_STAT 52-55 | CRC 56-63
  0x178 TX2: roll rate 0-15 | CLU_STAT5 16-19 | RollRate_STAT 20-23 | CLU_DIAG 24-31 | AX 32-47 |
             MSG_CNT 48-51 | AX_STAT 52-55 | CRC 56-63
  0x17C TX3: pitch rate 0-15 | HW_Index 16-19 | PitchRate_STAT 20-23 | reserved 24-31 | AZ 32-47 |
             MSG_CNT 48-51 | AZ_STAT 52-55 | CRC 56-63
  rates 0.005 deg/s per bit, offset -163.84 deg/s; accelerations 0.000127465 g per bit, offset -4.1768 g.
Status, CLU and HW index fields are sent as 0 (all OK; Bosch's driver flags bits 0x1/0x2/0x4 as errors).
Temperature: 0xFF means "CRC error or below -50 °C" and 0xC9 "above 150 °C" in that driver, so the valid
span 0..200 (-50..150 °C) is what we saturate to. Rates and accelerations saturate at raw 0..65534: Bosch's
driver tests use 163.83 deg/s and 4.176618 g (raw 65534) as the maximum and the MM5.10 DBC declares the
same ranges, so 0xFFFF is left unused.

The 4-bit message counter (bits 48-51) is the same in the three frames of a sample and steps by one per
sample (mod 16), continuing across encode calls; Bosch's receiver drops a set whose counters differ.

CRC byte: UNVERIFIED. Bosch's driver does not check it (crc_index = nullopt) and no public Bosch document
found states the algorithm. We send CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xorout 0xFF, not reflected)
over data bytes 0-6, the algorithm an independent MM7.10 emulator uses (IanLyuWellysun/TestSonar,
T77_TT1_IMU_C/Core/Src/main.c, Crc8Saej1850 over 7 bytes) and common on Bosch automotive sensors;
its README still lists the checksum as undecided. Receivers that ignore the CRC (Bosch's own) are unaffected.

Axes: Bosch's driver maps yaw -> +z, pitch -> +y, roll -> -x ("Roll is received negative as per
right-hand rule"), AX/AY/AZ -> +x/+y/+z of a forward-left-up frame (ROS REP-103). The encoder re-expresses the
forward-right-down Samples in those forward-left-up chip axes first (`body_axes`), and the AxisMaps (default:
that driver's mapping) read them; the decoder's `gyro`/`accel` are in the same forward-left-up axes.
"""
from __future__ import annotations

import math

import numpy as np

from firmware_protocols.axes import to_body_axes
from firmware_protocols.base import CanStreamDecoder, DecoderStats, Packet, SaturationStats, Samples
from firmware_protocols.can_signals import CRC8_J1850_TABLE, AxisMap, Signal, SignalLayout, axis_map
from firmware_protocols.registry import FormatInfo, register

IDS = (0x174, 0x178, 0x17C)
STANDARD_GRAVITY = 9.80665
RATE_SCALE_DEG = 0.005
RATE_OFFSET_DEG = -163.84
ACCEL_SCALE_G = 0.000127465
ACCEL_OFFSET_G = -4.1768
RAW_MAX = 65534
TEMP_OFFSET_C = -50.0
TEMP_RAW_MAX = 200

DEFAULT_RATE_MAP = AxisMap((2, 0, 1), (1, -1, 1))     # TX1 yaw, TX2 roll, TX3 pitch
DEFAULT_ACCEL_MAP = AxisMap((1, 0, 2), (1, 1, 1))     # TX1 AY, TX2 AX, TX3 AZ


def crc8_sae_j1850(data: bytes) -> int:
    crc = 0xFF
    for byte in data:
        crc = int(CRC8_J1850_TABLE[crc ^ byte])
    return crc ^ 0xFF


class BoschMM7Encoder:
    # Axes: the chip's axes are forward-left-up (at rest AZ reads +1 g): Bosch's ROS driver maps AX/AY/AZ to
    # +x/+y/+z of REP 103's forward-left-up frame (module docstring). The AxisMaps read those axes, so encode
    # re-expresses the FRD Samples in FLU first. No attitude.
    body_axes, reference = "FLU", None
    axes_source = "Bosch off_highway_mm7p10 receiver.cpp: AX/AY/AZ, rates on forward-left-up (REP 103) axes"

    def __init__(self, rate_axes=DEFAULT_RATE_MAP, accel_axes=DEFAULT_ACCEL_MAP, counter: int = 0):
        self.rate_axes = axis_map(rate_axes)
        self.accel_axes = axis_map(accel_axes)
        self.counter = int(counter) & 0xF
        self.saturated = SaturationStats()
        # sources: gyro x y z (0-2), accel x y z (3-5), temperature (6)
        signals = [Signal("temperature", 0, 3, 1, 6, 1.0, 1.0, TEMP_OFFSET_C, 0, TEMP_RAW_MAX)]
        for message, (rate, accel) in enumerate((("yaw_rate", "ay"), ("roll_rate", "ax"), ("pitch_rate", "az"))):
            signals.append(Signal(rate, message, 0, 2, self.rate_axes.axes[message],
                                  math.degrees(1.0) * self.rate_axes.signs[message],
                                  RATE_SCALE_DEG, RATE_OFFSET_DEG, 0, RAW_MAX))
            signals.append(Signal(accel, message, 4, 2, 3 + self.accel_axes.axes[message],
                                  self.accel_axes.signs[message] / STANDARD_GRAVITY,
                                  ACCEL_SCALE_G, ACCEL_OFFSET_G, 0, RAW_MAX))
        # status nibbles (bits 20-23, 52-55) and CLU/HW fields stay 0: all OK
        self.layout = SignalLayout(IDS, False, np.zeros((3, 8)), signals, counter_byte=6, crc8=True)

    frames_per_sample = ((8, False, False),) * 3

    def encode(self, samples: Samples) -> np.ndarray:
        samples.require_finite(("gyro", "accel", "temperature_c"))
        samples = to_body_axes(samples, self.body_axes)
        temperature = samples.field_or("temperature_c", 25.0)
        frames = self.layout.pack(np.column_stack((samples.gyro, samples.accel, temperature)), self.counter,
                                  self.saturated)
        self.counter = (self.counter + len(samples)) & 0xF
        return frames


class BoschMM7Decoder(CanStreamDecoder):
    """Collects TX1, TX2, TX3 with equal counters (in that order, as the sensor sends them) into one
    packet per sample. A frame with a wrong CRC counts in bad_checksum and breaks the set in progress;
    a set broken by a missing or reordered frame is dropped (its frames count in ignored_frames)."""

    def __init__(self, rate_axes=DEFAULT_RATE_MAP, accel_axes=DEFAULT_ACCEL_MAP):
        self.rate_axes = axis_map(rate_axes)
        self.accel_axes = axis_map(accel_axes)
        self.stats = DecoderStats()
        self._set: list[bytes] = []

    def _drop_set(self) -> None:
        self.stats.ignored_frames += len(self._set)
        self._set = []

    def _feed(self, can_id, data, extended, fd):
        if extended or fd or can_id not in IDS or len(data) != 8:
            self.stats.ignored_frames += 1
            return []
        if crc8_sae_j1850(data[:7]) != data[7]:
            self.stats.bad_checksum += 1
            self._drop_set()
            return []
        position = IDS.index(can_id)
        if position != len(self._set) or (self._set and (self._set[0][6] & 0xF) != (data[6] & 0xF)):
            self._drop_set()
            if position != 0:
                self.stats.ignored_frames += 1
                return []
        self._set.append(data)
        if len(self._set) < 3:
            return []
        tx = self._set
        self._set = []
        rates = np.radians([(f[0] | f[1] << 8) * RATE_SCALE_DEG + RATE_OFFSET_DEG for f in tx])
        accels = np.array([(f[4] | f[5] << 8) * ACCEL_SCALE_G + ACCEL_OFFSET_G for f in tx]) * STANDARD_GRAVITY
        temperature = tx[0][3] + TEMP_OFFSET_C if tx[0][3] <= TEMP_RAW_MAX else math.nan
        fields = {"gyro": self.rate_axes.to_sensor(rates), "accel": self.accel_axes.to_sensor(accels),
                  "yaw_rate": rates[0], "roll_rate": rates[1], "pitch_rate": rates[2],
                  "ay": accels[0], "ax": accels[1], "az": accels[2],
                  "temperature_c": temperature, "counter": tx[0][6] & 0xF,
                  "status": tuple(f[2] >> 4 for f in tx) + tuple(f[6] >> 4 for f in tx),
                  "hw_index": tx[2][2] & 0xF}
        self.stats.packets += 1
        return [Packet(kind="MM7.10", fields=fields, raw=b"".join(tx))]


register(FormatInfo(
    name="bosch-mm7", kind="can",
    description="Bosch MM7.10: TX1/TX2/TX3 (0x174/0x178/0x17C), shared message counter, CRC-8 (UNVERIFIED)",
    encoder=BoschMM7Encoder,
    decoder=lambda rate_axes=DEFAULT_RATE_MAP, accel_axes=DEFAULT_ACCEL_MAP, **_: BoschMM7Decoder(rate_axes,
                                                                                                  accel_axes),
    frames_per_sample=BoschMM7Encoder.frames_per_sample,
    options={
        "rate_axes": "(axes, signs) feeding yaw, roll, pitch rate; axes 0..2, signs +-1",
        "accel_axes": "(axes, signs) feeding AY, AX, AZ; axes 0..2, signs +-1",
        "counter": "first message counter 0..15",
    },
))
