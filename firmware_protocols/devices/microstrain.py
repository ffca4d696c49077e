"""A MicroStrain (HBK) inertial device speaking MIP: base and 3DM commands with ACK/NACK fields, and the
data sets the configuration turns on.

Sources: LORD-MicroStrain/mip_sdk (src/mip/definitions/commands_base.h, commands_3dm.h: descriptors and
reply fields; mip_result.h: ACK 0x00, NACK 0x01 unknown command, 0x02 invalid checksum, 0x03 invalid
parameter, 0x04 command failed), ../shared/specs/devices.md (what SDK clients send: ping, set idle, device
information and descriptors, message formats, enable streams, resume), and MicroStrain's own MSCL (pymscl)
as the client in tests/firmware_protocols/devices/test_device_microstrain.py.

A reply is one packet in the command's descriptor set: the ACK/NACK field `04 F1 <command> <code>`, then
any data the command returns. Commands:

    0x01 base:  01 ping, 02 set to idle (data stops), 03 get device information (field 0x81: firmware
                version u16, model name, model number, serial number, lot number, options: 16 chars each),
                04 get device descriptors (0x82: u16 set<<8|field for every command and data field
                supported), 05 built-in test (0x83: u32 0), 06 resume (data resumes), 07 get extended
                descriptors (0x86, none), 7E reset (back to the start-up configuration, streaming)
    0x0C 3DM:   06 / 07 get IMU / GNSS base rate (legacy; 0x83 / 0x84: u16 Hz), 0E get base rate (0x8E:
                set u8, Hz u16), 08 / 09 / 0A IMU / GNSS / filter message format (legacy: function, count,
                (field, decimation u16)...; read answers 0x80 / 0x81 / 0x82), 0F message format (function,
                set, count, entries; read answers 0x8F), 11 enable data stream (function, set, enable;
                read answers 0x85), 30 device settings (save / load / default: acknowledged)
    Functions: 1 apply, 2 read, 3 save, 4 load saved, 5 load default.

At start the device streams the `fields` of set 0x80 at every sample, or what a preset names (PRESETS: the sets,
fields and rates ArduPilot's MicroStrain5 / MicroStrain7 drivers expect of a unit configured beforehand; they
send no command). The data sets are 0x80 IMU, 0x81 GNSS, 0x91 / 0x92 GNSS receivers 1 / 2 (a GQ7's) and 0x82
filter; the filter state follows the samples' ins_mode in the numbering of the model's family (`filter_family`:
a model name containing GX5 numbers like a 3DM-GX5-45, others like a GQ7).

The base rate of every data set is the scene's sample rate (the emulator has no other), so a decimation d
sends the field every d-th sample; fields of one set due at the same sample share one packet, in the
configured order. A GNSS set (0x81, 0x91, 0x92) follows the receiver instead when the samples say when its
solutions arrive (gnss_new): a new solution goes out at once unless the set's period (its smallest decimation) has
not passed since the last packet, then when it has, so each solution is sent once, never repeated, at no more
than the configured rate. Data flow only while the device is not idle and the set's stream is enabled. A
field the emulator cannot produce is NACKed with 0x03 (invalid parameter) as a device does for a field it
lacks; an unknown command with 0x01; a packet with a bad checksum with 0x02 (echoing the first field's
descriptor; false syncs inside a packet just NACKed are not answered again); a command whose reply would
overflow the 255-byte reply packet with 0x04 (command failed), and a message format listing a field twice
with 0x03. Bytes outside packets are ignored and counted.
"""
from __future__ import annotations

import copy
import struct

from firmware_protocols.base import Samples
from firmware_protocols.devices.base import Device, SinceLastOutput, preset_settings, single
from firmware_protocols.wire_formats.microstrain import (DATA_SETS, DEFAULT_FIELDS, FILTER_SET, GNSS_RECEIVER_1,
                                                         GNSS_RECEIVER_2, GNSS_SET, GNSS_SETS, SENSOR_DATA_SET,
                                                         MipEncoder,
                                                         fletcher16, mip_checksum_ok, mip_length)
from firmware_protocols.packing import FrameScanner
from firmware_protocols.registry import attach_device

BASE_SET, DM_SET = 0x01, 0x0C
ACK_FIELD = 0xF1
ACK_OK, NACK_UNKNOWN, NACK_CHECKSUM, NACK_PARAM, NACK_FAILED = 0, 1, 2, 3, 4
APPLY, READ, SAVE, LOAD, DEFAULT = 1, 2, 3, 4, 5
_LEGACY_FORMAT = {0x08: SENSOR_DATA_SET, 0x09: GNSS_SET, 0x0A: FILTER_SET}
_LEGACY_REPLY = {SENSOR_DATA_SET: 0x80, GNSS_SET: 0x81, FILTER_SET: 0x82}
_BASE_COMMANDS = (0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x7E)
_DM_COMMANDS = (0x06, 0x07, 0x08, 0x09, 0x0A, 0x0E, 0x0F, 0x11, 0x30)
_MAX_PAYLOAD = 255           # a MIP packet's payload length is one byte
_ACK_LEN = 4                 # 04 F1 <command> <code>

# What ArduPilot's MicroStrain drivers expect a unit to stream at power-on: they send no command at all
# (AP_ExternalAHRS_MicroStrain5.cpp / _MicroStrain7.cpp, ArduPilot/ardupilot 8d81ecff / 07874551; parser
# MicroStrain_common.cpp 634f47ff). healthy() wants an IMU packet (0x80) younger than 40 ms (MicroStrain5) or
# 44 ms (MicroStrain7), a GNSS packet younger than 500 / 550 ms and a filter packet (0x82) younger than 500 /
# 44 ms; pre-arm wants a 3D fix and filter state 2 (GX5 "running, solution valid") or 3 / 4 (GQ7 AHRS / full
# navigation). Rates in Hz; each set's decimation is the largest that keeps at least that rate
# (_decimation). IMU and filter at 50 Hz, twice the 25 Hz the MicroStrain7 driver's comment names, so that a
# packet is never older than the 40 / 44 ms allowed; GNSS at the receiver's rate: 2 Hz on a GQ7 (the driver's
# "GPS: 2Hz"), 4 Hz on a GX5-45 (its maximum; MicroStrain5 wants strictly less than 500 ms between packets).
# The GQ7's two receivers both report the one GNSS solution the samples carry.
_AP_IMU = ("accel", "gyro", "mag", "pressure")
_AP_GNSS = ("gps_timestamp", "fix_info", "position_llh", "velocity_ned", "dop")
PRESETS = {
    "ardupilot": ({"model_name": "3DM-GQ7", "model_number": "6284-4220", "filter_family": "gq7",
                   "sets": {SENSOR_DATA_SET: (_AP_IMU, 50.0), GNSS_RECEIVER_1: (_AP_GNSS, 2.0),
                            GNSS_RECEIVER_2: (_AP_GNSS, 2.0),
                            FILTER_SET: (("gps_time", "status", "position_llh", "velocity_ned", "quaternion",
                                          "position_uncertainty", "velocity_uncertainty"), 50.0)}},
                  "a 3DM-GQ7 as ArduPilot's MicroStrain7 driver (EAHRS_TYPE 7) reads it: IMU 0x80 (accel, gyro, "
                  "mag, pressure) 50 Hz, GNSS receivers 0x91 and 0x92 2 Hz, filter 0x82 (state 4 full navigation, "
                  "position, velocity, quaternion, uncertainties) 50 Hz"),
    "ardupilot-gx5": ({"model_name": "3DM-GX5-45", "model_number": "6251-4220", "filter_family": "gx5",
                       "sets": {SENSOR_DATA_SET: (_AP_IMU + ("quaternion",), 50.0),
                                GNSS_SET: (("gps_time", "fix_info", "position_llh", "velocity_ned", "dop"), 4.0),
                                FILTER_SET: (("gps_time", "status", "position_llh", "velocity_ned"), 50.0)}},
                      "a 3DM-GX5-45 as ArduPilot's MicroStrain5 driver (EAHRS_TYPE 2) reads it: IMU 0x80 (accel, "
                      "gyro, mag, pressure, quaternion) 50 Hz, GNSS 0x81 4 Hz, filter 0x82 (state 2 running, "
                      "position, velocity) 50 Hz"),
}


def _held_solution(one: Samples) -> Samples:
    """The sample without its gnss_new mark (a copy): the receiver's solution it holds, sent now."""
    held = copy.copy(one)
    held.gnss_new = None
    return held


def _decimation(rate_hz: float, wanted_hz: float) -> int:
    """Every d-th sample, d the largest with rate / d >= wanted (1 when the scene is slower than wanted)."""
    return max(1, int(rate_hz // wanted_hz))


def _count_fields(payload: bytes, k: int) -> int:
    """Well-formed fields of a command payload from offset k on."""
    n = 0
    while k + 2 <= len(payload) and payload[k] >= 2 and k + payload[k] <= len(payload):
        n, k = n + 1, k + payload[k]
    return n


def packet(descriptor_set: int, fields: list) -> bytes:
    """75 65 set len (len desc data)... checksum: one MIP packet from (descriptor, data) fields."""
    payload = b"".join(bytes([2 + len(data), descriptor]) + data for descriptor, data in fields)
    head = bytes([0x75, 0x65, descriptor_set, len(payload)]) + payload
    return head + bytes(fletcher16(head))


def _text(value: str) -> bytes:
    return str(value).encode("ascii", "replace")[:16].rjust(16)


class MipDevice(Device):
    carries_increments = True    # a driver may configure the integrated outputs at any time
    def __init__(self, rate_hz: float, fields=DEFAULT_FIELDS, gps_week_offset=None, gps_flags: int = 0x1C,
                 model_name: str | None = None, model_number: str | None = None, serial_number: str = "6284.12345",
                 firmware_version: int = 1100, filter_family: str | None = None, filter_state: int | None = None,
                 preset: str | None = None):
        super().__init__(rate_hz)
        startup = {descriptor_set: [] for descriptor_set in DATA_SETS}
        if preset is not None:
            settings = preset_settings(PRESETS, preset, fields is not DEFAULT_FIELDS)
            model_name = model_name or settings["model_name"]          # what the user names wins
            model_number = model_number or settings["model_number"]
            filter_family = filter_family or settings["filter_family"]
            for descriptor_set, (names, wanted_hz) in settings["sets"].items():
                startup[descriptor_set] = [(name, _decimation(rate_hz, wanted_hz)) for name in names]
                if rate_hz < wanted_hz:
                    self.notes.append(f"preset {preset}: set {descriptor_set:#04x} wants {wanted_hz:g} Hz but the "
                                      f"scene samples at {rate_hz:g} Hz; ArduPilot's healthy() may fail")
        else:
            if isinstance(fields, str):
                fields = [f.strip() for f in fields.split(",") if f.strip()]
            startup[SENSOR_DATA_SET] = [(name, 1) for name in fields]
        model_name, model_number = model_name or "3DM-GQ7", model_number or "6284-4220"
        # the filter's state codes are the model family's (GX5 and GQ7 number them differently)
        filter_family = filter_family or ("gx5" if "GX5" in str(model_name).upper() else "gq7")
        self._options = {"gps_week_offset": gps_week_offset, "gps_flags": gps_flags, "filter_state": filter_state,
                         "filter_family": filter_family}
        for descriptor_set, entries in startup.items():     # validates the fields and options now
            if entries or descriptor_set == SENSOR_DATA_SET:
                MipEncoder(tuple(name for name, _ in entries) or DEFAULT_FIELDS, descriptor_set=descriptor_set,
                           **self._options)
        self.info = (struct.pack(">H", int(firmware_version)) + _text(model_name) + _text(model_number)
                     + _text(serial_number) + _text("") + _text("emulated"))
        self._startup = self._saved = startup
        self.formats = {k: list(v) for k, v in startup.items()}
        self.enabled = {k: True for k in DATA_SETS}
        self.idle = False
        self.tick = 0
        self._gnss = {}                # GNSS set -> (a solution waiting to be sent, tick of the last packet)
        self.increments = SinceLastOutput()
        self._encoders: dict = {}
        self._scanner = FrameScanner(b"\x75\x65", mip_length, mip_checksum_ok)   # as the decoder finds packets
        # the link budget's figure: every set's packet, each at its share of the samples
        self.bytes_per_sample = max(1, round(sum(
            self._encoder(descriptor_set, tuple(name for name, _ in entries)).bytes_per_sample
            / min(d for _, d in entries) for descriptor_set, entries in startup.items() if entries)))

    def _encoder(self, descriptor_set: int, names: tuple) -> MipEncoder:
        key = (descriptor_set, names)
        if key not in self._encoders:
            self._encoders[key] = MipEncoder(names, descriptor_set=descriptor_set, **self._options)
        return self._encoders[key]

    def encoders(self):
        return self._encoders.values()

    # - output -
    def output(self, samples: Samples, i: int) -> bytes:
        tick = self.tick
        self.tick += 1
        self.increments.add(samples, i)
        if self.idle:
            return b""
        parts, one = [], None
        for descriptor_set, entries in self.formats.items():
            if not self.enabled[descriptor_set]:
                continue
            solution = descriptor_set in GNSS_SETS and samples.gnss_new is not None
            if solution:
                due = self._gnss_due(descriptor_set, entries, tick, samples.gnss_new[i] != 0)
            else:
                due = tuple(name for name, decimation in entries if tick % decimation == 0)
            if due:
                one = one or self.increments.attach(single(samples, i))
                encoder = self._encoder(descriptor_set, due)
                # the device decided when: the encoder sends this sample's held solution whatever its gnss_new
                parts.append(encoder.encode(_held_solution(one) if solution else one).data)
                self.increments.sent(encoder)
        return b"".join(parts)

    def _gnss_due(self, descriptor_set: int, entries: list, tick: int, new: bool) -> tuple:
        pending, last = self._gnss.get(descriptor_set, (False, None))
        pending = pending or new
        if not entries or not pending or (last is not None and tick - last < min(d for _, d in entries)):
            self._gnss[descriptor_set] = (pending, last)
            return ()
        self._gnss[descriptor_set] = (False, tick)
        return tuple(name for name, _ in entries)

    # - input -
    def _receive(self, data: bytes, now_ns: int) -> list:
        replies = []
        skipped = self._scanner.stats.skipped_bytes
        for frame, ok in self._scanner.candidates(data):
            if not ok:
                # NACK the command it claims to be (a packet may begin inside it: the scanner hunts on)
                first = frame[5] if len(frame) > 6 else 0
                replies.append(packet(frame[2], [(ACK_FIELD, bytes([first, NACK_CHECKSUM]))]))
                self.stats.errors += 1
                continue
            replies.append(self._command_packet(frame[2], frame[4:-2]))
        self.stats.ignored_bytes += self._scanner.stats.skipped_bytes - skipped
        return replies

    def _drop_partial(self) -> int:
        return self._scanner.drop_partial()

    def _command_packet(self, descriptor_set: int, payload: bytes) -> bytes:
        """The one reply packet of a command packet. Its payload holds 255 bytes (the length is a u8): a command
        whose data would not fit is answered NACK 0x04 (mip_result.h: "The device could not complete the
        command") without its data; when only one acknowledgement still fits and more commands follow, that one
        is a NACK 0x04 for the next command and the rest are not run (counted as errors), so the driver learns
        where its packet stopped."""
        out, k, room = [], 0, _MAX_PAYLOAD
        while k + 2 <= len(payload):
            size, command = payload[k], payload[k + 1]
            if size < 2 or k + size > len(payload):
                break
            more = k + size + 2 <= len(payload)
            if more and room < 2 * _ACK_LEN:
                out.append((ACK_FIELD, bytes([command, NACK_FAILED])))
                self.stats.errors += _count_fields(payload, k)
                break
            code, reply_fields = self._command(descriptor_set, command, payload[k + 2:k + size])
            reply_fields = reply_fields if code == ACK_OK else []
            need = _ACK_LEN + sum(2 + len(data) for _, data in reply_fields) + (_ACK_LEN if more else 0)
            if need > room:
                code, reply_fields = NACK_FAILED, []
            if code == ACK_OK:
                self.stats.commands += 1
            else:
                self.stats.errors += 1
            out.append((ACK_FIELD, bytes([command, code])))
            out.extend(reply_fields)
            room -= _ACK_LEN + sum(2 + len(data) for _, data in reply_fields)
            k += size
        if not out:                  # an empty or malformed payload: answer it as an unknown command
            self.stats.errors += 1
            out.append((ACK_FIELD, bytes([payload[1] if len(payload) > 1 else 0, NACK_UNKNOWN])))
        return packet(descriptor_set, out)

    def _command(self, descriptor_set: int, command: int, args: bytes):
        try:
            if descriptor_set == BASE_SET and command in _BASE_COMMANDS:
                return self._base(command)
            if descriptor_set == DM_SET and command in _DM_COMMANDS:
                return self._dm(command, args)
        except (struct.error, IndexError, KeyError, ValueError):
            return NACK_PARAM, []
        return NACK_UNKNOWN, []

    def _base(self, command: int):
        if command == 0x02:
            self.idle = True
        elif command == 0x06:
            self.idle = False
        elif command == 0x7E:
            self.formats = {k: list(v) for k, v in self._startup.items()}
            self.enabled = {k: True for k in DATA_SETS}
            self.idle = False
            self._gnss = {}
        elif command == 0x03:
            return ACK_OK, [(0x81, self.info)]
        elif command == 0x04:
            return ACK_OK, [(0x82, self._descriptors())]
        elif command == 0x05:
            return ACK_OK, [(0x83, struct.pack(">I", 0))]
        elif command == 0x07:
            return ACK_OK, [(0x86, b"")]
        return ACK_OK, []

    def _descriptors(self) -> bytes:
        pairs = [(BASE_SET, c) for c in _BASE_COMMANDS] + [(DM_SET, c) for c in _DM_COMMANDS]
        pairs += [(s, f.descriptor) for s, table in DATA_SETS.items() for f in table.values()]
        return b"".join(struct.pack(">BB", *pair) for pair in pairs)

    def _dm(self, command: int, args: bytes):
        rate = struct.pack(">H", min(0xFFFF, int(round(self.rate_hz))))
        if command in (0x06, 0x07):
            return ACK_OK, [(0x83 if command == 0x06 else 0x84, rate)]
        if command == 0x0E:
            if args[0] not in DATA_SETS:
                return NACK_PARAM, []
            return ACK_OK, [(0x8E, bytes([args[0]]) + rate)]
        if command in _LEGACY_FORMAT:
            descriptor_set = _LEGACY_FORMAT[command]
            code, entries = self._format(args[0], descriptor_set, args[1:])
            return code, [(_LEGACY_REPLY[descriptor_set], entries)] if entries is not None else []
        if command == 0x0F:
            code, entries = self._format(args[0], args[1], args[2:])
            return code, [(0x8F, bytes([args[1]]) + entries)] if entries is not None else []
        if command == 0x11:
            function, descriptor_set = args[0], args[1]
            if descriptor_set not in DATA_SETS:
                return NACK_PARAM, []
            if function == APPLY:
                self.enabled[descriptor_set] = bool(args[2])
            elif function == READ:
                return ACK_OK, [(0x85, bytes([descriptor_set, int(self.enabled[descriptor_set])]))]
            return ACK_OK, []
        # 0x30 device settings: save / load / default of everything configured
        function = args[0]
        if function == SAVE:
            self._saved = {k: list(v) for k, v in self.formats.items()}
        elif function == LOAD:
            self.formats = {k: list(v) for k, v in self._saved.items()}
        elif function == DEFAULT:
            self.formats = {k: list(v) for k, v in self._startup.items()}
        else:
            return NACK_PARAM, []
        return ACK_OK, []

    def _format(self, function: int, descriptor_set: int, rest: bytes):
        """Message format command for one set: (ack code, reply entries for READ or None)."""
        if descriptor_set not in DATA_SETS:
            return NACK_PARAM, None
        by_descriptor = {f.descriptor: name for name, f in DATA_SETS[descriptor_set].items()}
        if function == APPLY:
            count = rest[0]
            entries = [struct.unpack_from(">BH", rest, 1 + 3 * j) for j in range(count)]
            if len(rest) != 1 + 3 * count or any(d not in by_descriptor or rate == 0 for d, rate in entries):
                return NACK_PARAM, None
            names = tuple(by_descriptor[d] for d, _ in entries)
            if len(set(names)) != len(names):
                return NACK_PARAM, None        # a field listed twice: a packet cannot carry it twice
            if names:
                self._encoder(descriptor_set, names)   # what the encoder refuses (too long a packet) is refused now
            self.formats[descriptor_set] = [(by_descriptor[d], rate) for d, rate in entries]
            return ACK_OK, None
        if function == READ:
            table = DATA_SETS[descriptor_set]
            entries = self.formats[descriptor_set]
            return ACK_OK, bytes([len(entries)]) + b"".join(struct.pack(">BH", table[n].descriptor, d)
                                                             for n, d in entries)
        if function == SAVE:
            self._saved = {**self._saved, descriptor_set: list(self.formats[descriptor_set])}
        elif function == LOAD:
            self.formats[descriptor_set] = list(self._saved[descriptor_set])
        elif function == DEFAULT:
            self.formats[descriptor_set] = list(self._startup[descriptor_set])
        else:
            return NACK_PARAM, None
        return ACK_OK, None


attach_device("microstrain-mip", lambda rate_hz, **options: MipDevice(rate_hz, **options),
              {"model_name": "device information: model name (default the preset's, else 3DM-GQ7)",
               "model_number": "device information: model number (default the preset's, else 6284-4220)",
               "serial_number": "device information",
               "firmware_version": "device information: firmware version number (default 1100)",
               "filter_family": "filter state codes: gq7 or gx5 (default: gx5 for a GX5 model name, else gq7)",
               "filter_state": "a constant filter state (0x82, 0x10) instead of the one ins_mode gives",
               "preset": "start-up streams a flight stack expects: " + "; ".join(
                   f"{name}: {text}" for name, (_, text) in PRESETS.items())},
              {name: (settings, text) for name, (settings, text) in PRESETS.items()}, navigation=True,
              device_class=MipDevice)
