"""An Xsens MTi on its Xbus serial link: configuration and measurement modes, the acknowledgements a
configuring client waits for, and the output configuration that defines the MTData2 items.

Sources: ../shared/specs/devices.md (ArduPilot's AP_ExternalAHRS_Xsens sequence: GoToConfig 0x30 -> 0x31,
SetOutputConfiguration 0xC0 -> 0xC1, SetAlignmentRotation 0xEC twice -> 0xED, GoToMeasurement 0x10 ->
0x11; it only checks the acknowledgement's message id and goes to an error state on Error 0x42; xsens-go
waits for acknowledgements without a timeout), Xsens' xstypes (xsresultvalue.h: error codes
XRV_INVALIDMSG 4, XRV_INVALIDPARAM 33; the Error message carries the code in its one data byte) and
the message ids of the issue: WakeUp 0x3E -> 0x3F, ReqDID 0x00 -> DeviceID 0x01 (u32), ReqProductCode
0x1C -> 0x1D (ASCII), ReqFWRev 0x12 -> 0x13 (major, minor, revision), Reset 0x40 -> 0x41.

Messages are `FA FF <MID> <LEN> <data> <checksum>` (extended length as in firmware_protocols.wire_formats.xsens); the
byte sum from FF through the checksum is 0.

- Modes: the device starts in measurement mode streaming the configured items (ArduPilot accepts a
  free-running unit). GoToConfig (or WakeUp) enters config mode: no MTData2 at all until GoToMeasurement.
  Reset acknowledges, then returns to measurement mode with the configuration in force.
- Output configuration: SetOutputConfiguration (0xC0 with data, config mode only: XRV_INVALIDMSG in
  measurement mode) takes `XDI (u16 BE), frequency (u16 BE)` pairs and is acknowledged with 0xC1 echoing
  them; 0xC0 without data asks for the configuration, answered the same way in either mode. The XDI's low
  bits choose each real item's precision (float32, FP12.20, FP16.32, float64) and, on orientation and
  velocity items, the frame. A frequency of 0xFFFF (or 0) means "with every packet"; other items go out
  every round(sample rate / frequency) samples; a packet is sent at each sample where some item is due and
  carries those items (plus the every-packet ones) in the configured order. UtcTime comes from the sample
  time, GnssPvtData from the GNSS receiver's solution in the samples (gnss_*; without one, the reported position
  and velocity with the options num_sats, gnss_fix, leap_seconds: wire_formats.xsens.receiver_pvt).
  MagneticField and BaroPressure carry the samples' mag (over mag_reference_gauss) and pressure_pa.
  Items the emulator cannot produce (any XDI it does not know) are acknowledged but left out, and a note says
  which, so nothing is dropped silently. A malformed configuration (odd length) is XRV_INVALIDPARAM.
- SetAlignmentRotation (0xEC: frame byte 0 sensor / 1 local, then a float32 quaternion w, x, y, z) is
  acknowledged with an empty 0xED and applied from the next sample (see `aligned` for the rotations);
  a quaternion that is not of unit length is XRV_INVALIDPARAM. With only the frame byte it is a request,
  answered with the stored quaternion.
- A frame (FA FF ...) with a bad checksum, and any message id not listed here, is answered with Error 0x42
  XRV_INVALIDMSG; bytes outside frames (a preamble not followed by bus id FF included) are ignored and
  counted.
"""
from __future__ import annotations

import dataclasses
import math
import struct

import numpy as np

from firmware_protocols import attitude
from firmware_protocols.axes import to_body_axes
from firmware_protocols.base import Samples
from firmware_protocols.devices.base import Device, SinceLastOutput, single
from firmware_protocols.registry import attach_device
from firmware_protocols.packing import FrameScanner
from firmware_protocols.wire_formats.xsens import (BUS_MASTER, DEFAULT_ITEMS, EXTENDED_LENGTH, FRAMES, ITEMS,
                                                   PRECISIONS, PREAMBLE, XsensEncoder, xbus_checksum_ok, xbus_length)

WAKEUP, GOTO_CONFIG, GOTO_MEASUREMENT, REQ_DID, REQ_PRODUCT_CODE, REQ_FW_REV = 0x3E, 0x30, 0x10, 0x00, 0x1C, 0x12
SET_OUTPUT_CONFIGURATION, SET_ALIGNMENT_ROTATION, RESET, ERROR = 0xC0, 0xEC, 0x40, 0x42
XRV_INVALIDMSG, XRV_INVALIDPARAM = 4, 33
EVERY_PACKET = (0xFFFF, 0)
_ITEM_BY_BASE = {item.xdi: name for name, item in ITEMS.items()}
_PRECISION_BY_BITS = {bits: name for name, (bits, _, _) in PRECISIONS.items()}
_FRAME_BY_BITS = {bits: name for name, bits in FRAMES.items()}
_IDENTITY = (1.0, 0.0, 0.0, 0.0)


def aligned(one: Samples, sensor, local, frame: str) -> Samples:
    """One sample (in the sensor frame S, forward-left-up: axes.to_body_axes) as an MTi with alignment rotations
    outputs it. `sensor` (RotSensor, q_OS) rotates sensor-frame
    vectors into the object frame O: x_O = q_OS x_S q_OS*, and the orientation becomes q_LO = q_LS (x) q_OS*.
    `local` (RotLocal, q_L'L) turns the declared reference frame L (ENU, NED or NWU): q_L'O = q_L'L (x) q_LO,
    done here on the sample's S -> NED attitude as q_NL (x) q_L'L (x) q_LN. Velocity stays in the unturned frame;
    an absent attitude is the documented default (identity). UNVERIFIED: which way each quaternion turns
    (q_OS or q_SO) is this module's reading, not checked against Xsens' manual; ArduPilot's two rotations
    (local (0, 1/sqrt 2, 1/sqrt 2, 0): ENU -> NED; sensor (0, 1, 0, 0): FLU -> FRD) are half-turns, the same
    either way, and give the NED/FRD output its EKF expects."""
    quat = one.quat if one.quat is not None else np.array([_IDENTITY])
    changes = {name: attitude.rotate(sensor, getattr(one, name))
               for name in ("accel", "gyro", "mag", "delta_velocity", "delta_theta") if getattr(one, name) is not None}
    if one.attitude_change is not None:     # the sensor's attitude change, seen in the object frame
        changes["attitude_change"] = attitude.canonical(attitude.multiply(
            attitude.multiply(np.array(sensor), one.attitude_change), attitude.conjugate(np.array(sensor))))
    quat = attitude.multiply(quat, attitude.conjugate(np.array(sensor)))
    to_frame = attitude.from_ned(np.array(_IDENTITY), frame)            # q_LN
    local_ned = attitude.multiply(attitude.multiply(attitude.conjugate(to_frame), np.array(local)), to_frame)
    changes["quat"] = attitude.canonical(attitude.multiply(local_ned, quat))
    changes["euler"] = attitude.to_euler(changes["quat"])
    return dataclasses.replace(one, **changes)


def xbus(mid: int, data: bytes = b"") -> bytes:
    """One Xbus message from the device (bus id FF)."""
    head = bytes([BUS_MASTER, mid]) + (bytes([len(data)]) if len(data) < EXTENDED_LENGTH
                                       else bytes([EXTENDED_LENGTH, len(data) >> 8, len(data) & 0xFF]))
    body = head + data
    return bytes([PREAMBLE]) + body + bytes([-sum(body) & 0xFF])


class XsensDevice(Device):
    carries_increments = True    # a driver may configure the integrated outputs at any time
    def __init__(self, rate_hz: float, items=DEFAULT_ITEMS, precision: str = "float32", frame: str = "ENU",
                 mag_reference_gauss: float = 0.5, status_word: int = 0, packet_counter_start: int = 0,
                 device_id: int = 0x03780123, product_code: str = "MTi-300-2A8G4", firmware: str = "1.8.2",
                 num_sats: int | None = None, gnss_fix: int | None = None, leap_seconds: int | None = None):
        super().__init__(rate_hz)
        gnss = {name: value for name, value in (("num_sats", num_sats), ("fix_type", gnss_fix),
                                                 ("leap_seconds", leap_seconds)) if value is not None}
        self._encoder_options = {"mag_reference_gauss": mag_reference_gauss, "status_word": status_word,
                                 "gnss": gnss}
        encoder = XsensEncoder(items, precision, frame, **self._encoder_options)   # validates the options
        self.counter = int(packet_counter_start) & 0xFFFF
        self.device_id = int(device_id) & 0xFFFFFFFF
        self.product_code = str(product_code).encode("ascii")
        self.firmware = bytes(int(p) & 0xFF for p in str(firmware).split("."))[:3].ljust(3, b"\0")
        self.measuring = True
        self.alignment = {0: _IDENTITY, 1: _IDENTITY}
        self._block = self._block_in_s = None     # the last block given to output, and it in sensor axes
        # The configuration as the client would read it back: XDI with precision/frame bits, frequency.
        every = [n for n in encoder.items if n in ("packet_counter", "sample_time_fine", "sample_time_coarse")]
        self.config = [(self._xdi(n, precision, frame), 0xFFFF if n in every else min(0xFFFE, int(round(rate_hz))))
                       for n in encoder.items]
        self._apply(self.config)
        # Frames as the decoder finds them (preamble FA, bus id FF, length, byte-sum checksum, the SDK's
        # extended-length bounds); bytes outside them are ignored and counted.
        self._scanner = FrameScanner(bytes((PREAMBLE, BUS_MASTER)), xbus_length, xbus_checksum_ok)

    @staticmethod
    def _xdi(name: str, precision: str, frame: str) -> int:
        item = ITEMS[name]
        return item.xdi | (PRECISIONS[precision][0] if item.real else 0) | (FRAMES[frame] if item.has_frame else 0)

    def _apply(self, config: list) -> None:
        """Parse a configuration into (item name, precision, frame, samples per output or 0 = every packet)."""
        plan, left_out, frames = [], [], set()
        for xdi, frequency in config:
            name = _ITEM_BY_BASE.get(xdi & 0xFFF0)
            if name is None:
                left_out.append(f"{xdi:#06x}")
                continue
            item = ITEMS[name]
            precision = _PRECISION_BY_BITS[xdi & 0x3] if item.real else "float32"
            if item.has_frame:
                frames.add(_FRAME_BY_BITS.get(xdi & 0xC, "ENU"))
            every = 0 if frequency in EVERY_PACKET else max(1, int(round(self.rate_hz / frequency)))
            plan.append((name, precision, every))
        if len(frames) > 1:
            raise ValueError("mixed frames")
        self.frame = frames.pop() if frames else "ENU"
        self.plan = plan
        self._encoders = {}
        self.tick = 0
        self.increments = SinceLastOutput()
        if left_out:
            self.notes.append(f"output configuration: the emulator cannot produce {', '.join(left_out)}; "
                              "acknowledged and left out of MTData2")
        due = tuple(range(len(plan)))
        self.bytes_per_sample = self._encoder(due).bytes_per_sample if plan else 0

    def _encoder(self, due: tuple) -> XsensEncoder:
        if due not in self._encoders:
            names = [self.plan[j][0] for j in due]
            precisions = {self.plan[j][0]: self.plan[j][1] for j in due}
            self._encoders[due] = XsensEncoder(names, "float32", self.frame, precisions=precisions,
                                               **self._encoder_options)
        return self._encoders[due]

    def encoders(self):
        return self._encoders.values()

    # - output -
    def output(self, samples: Samples, i: int) -> bytes:
        tick = self.tick
        self.tick += 1
        # The MTi's sensor frame S (forward-left-up) first, once per block: the alignment rotations are defined
        # on S, and the increments summed since the last packet are the same sums seen from S.
        if samples is not self._block:
            self._block, self._block_in_s = samples, to_body_axes(samples, XsensEncoder.body_axes)
        samples = self._block_in_s
        self.increments.add(samples, i)
        if not self.measuring or not self.plan:
            return b""
        timed = [j for j, (_, _, every) in enumerate(self.plan) if every and tick % every == 0]
        if not timed and any(every for _, _, every in self.plan):
            return b""
        due = tuple(j for j, (_, _, every) in enumerate(self.plan) if every == 0 or j in timed)
        encoder = self._encoder(due)
        encoder.packet_counter = self.counter
        self.counter = (self.counter + 1) & 0xFFFF
        one = self.increments.attach(single(samples, i))
        if self.alignment[0] != _IDENTITY or self.alignment[1] != _IDENTITY:
            one = aligned(one, self.alignment[0], self.alignment[1], self.frame)
        data = encoder.encode_sensor_axes(one).data
        self.increments.sent(encoder)
        return data

    # - input -
    def _receive(self, data: bytes, now_ns: int) -> list:
        replies = []
        skipped = self._scanner.stats.skipped_bytes
        for frame, ok in self._scanner.candidates(data):
            if not ok:
                # A damaged frame, or a false preamble: say so; the scanner hunts on from the next byte.
                self.stats.errors += 1
                replies.append(xbus(ERROR, bytes([XRV_INVALIDMSG])))
                continue
            head = 6 if frame[3] == EXTENDED_LENGTH else 4
            replies.extend(self._message(frame[2], frame[head:-1]))
        self.stats.ignored_bytes += self._scanner.stats.skipped_bytes - skipped
        return replies

    def _drop_partial(self) -> int:
        return self._scanner.drop_partial()

    def _message(self, mid: int, data: bytes) -> list:
        reply = self._answer(mid, data)
        if reply[0] == ERROR:
            self.stats.errors += 1
        else:
            self.stats.commands += 1
        return [xbus(*reply)]

    def _answer(self, mid: int, data: bytes) -> tuple:
        if mid in (WAKEUP, GOTO_CONFIG):
            self.measuring = False
            return mid + 1, b""
        if mid == GOTO_MEASUREMENT:
            self.measuring = True
            self.tick = 0
            return mid + 1, b""
        if mid == RESET:
            self.measuring = True
            self.tick = 0
            return mid + 1, b""
        if mid == REQ_DID:
            return mid + 1, struct.pack(">I", self.device_id)
        if mid == REQ_PRODUCT_CODE:
            return mid + 1, self.product_code
        if mid == REQ_FW_REV:
            return mid + 1, self.firmware
        if mid == SET_OUTPUT_CONFIGURATION:
            return self._output_configuration(data)
        if mid == SET_ALIGNMENT_ROTATION:
            return self._alignment(data)
        return ERROR, bytes([XRV_INVALIDMSG])

    def _output_configuration(self, data: bytes) -> tuple:
        if data:
            if self.measuring:
                return ERROR, bytes([XRV_INVALIDMSG])
            if len(data) % 4:
                return ERROR, bytes([XRV_INVALIDPARAM])
            config = list(struct.iter_unpack(">HH", data))
            try:
                self._apply(config)
            except ValueError:
                self._apply(self.config)
                return ERROR, bytes([XRV_INVALIDPARAM])
            self.config = config
        return SET_OUTPUT_CONFIGURATION + 1, b"".join(struct.pack(">HH", *entry) for entry in self.config)

    def _alignment(self, data: bytes) -> tuple:
        if len(data) not in (1, 17) or data[0] not in self.alignment:
            return ERROR, bytes([XRV_INVALIDPARAM])
        if len(data) == 1:
            return SET_ALIGNMENT_ROTATION + 1, data + struct.pack(">4f", *self.alignment[data[0]])
        if self.measuring:
            return ERROR, bytes([XRV_INVALIDMSG])
        quat = struct.unpack(">4f", data[1:])
        norm = math.sqrt(sum(v * v for v in quat))
        if not 0.99 < norm < 1.01:      # finite, and a rotation (float32 rounding allowed)
            return ERROR, bytes([XRV_INVALIDPARAM])
        self.alignment[data[0]] = quat
        return SET_ALIGNMENT_ROTATION + 1, b""


attach_device("xsens-mtdata2", lambda rate_hz, **options: XsensDevice(rate_hz, **options),
              {"device_id": "DeviceID answered to ReqDID (default 0x03780123)",
               "product_code": "answered to ReqProductCode (default MTi-300-2A8G4)",
               "firmware": "major.minor.revision answered to ReqFWRev (default 1.8.2)",
               "num_sats": "GnssPvtData numSv (default 12)",
               "gnss_fix": "GnssPvtData fixType: 0 none ... 3 3D fix (default 3)",
               "leap_seconds": "GPS - UTC in seconds for GnssPvtData's iTOW (default 18)"},
              navigation=True, device_class=XsensDevice)
