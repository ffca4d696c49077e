"""A VectorNav VN-100 / VN-300 on its serial link: registers, commands, and the outputs they configure.

Sources: VectorNav's programming library (vnproglib 1.1 as vendored by dawonn/vectornav: vnenum.h for the
binary groups, field bits, async modes and the sensor error codes; vn/protocol/uart/types.h for the ASCII
async types VNOFF 0, VNYPR 1, VNYMR 14, VNIMU 19), the driver sequences in ../shared/specs/devices.md, ArduPilot's
AP_ExternalAHRS_VectorNav.cpp (resends each command every 500 ms until a reply whose first two terms match
it; panics on $VNERR, so every command it sends must succeed; matches packets by exact header) and PX4's
drivers/ins/vectornav (vnproglib: takes any reply as the answer, 1 s timeout).

Commands (`$<body>*<checksum>\\r\\n`; the checksum is the 8-bit XOR of the body as 2 hex digits, a CRC-16
as 4, or `XX` = unchecked; replies use the command's kind):

    $VNRRG,<reg>              read: `$VNRRG,<reg 2 digits>,<contents>`
    $VNWRG,<reg>,<values>     write: echoed (`$VNWRG,<reg 2 digits>,<values as sent>`), takes effect at the
                              next sample
    $VNASY,0 | 1              pause / resume every asynchronous output (binary and ASCII); echoed
    $VNWNV                    save the registers (what $VNRST restores); echoed
    $VNRFS                    restore factory settings (the emulator's start-up configuration); echoed
    $VNRST                    reset: back to the saved registers, outputs resumed; echoed

Registers: 0 user tag (<= 20 printable characters, writable), 1 model, 2 hardware revision, 3 serial
number, 4 firmware version (read-only: a write answers error 8), 5 baud rate (9600 ... 921600; the echo
goes out at the old rate, then the link follows), 6 async ASCII type (0 off, 1 VNYPR, 14 VNYMR, 19 VNIMU; other
types are error 7: the emulator cannot produce them) and 7 its frequency (1 ... 200 Hz as the device
allows), both with an optional serial port argument; 30 communication protocol control (7 integers),
32 synchronization control (9), 35 VPE basic control (4), 82 delta theta and delta velocity configuration
(5: IntegrationFrame 0 body / 1 NED, GyroCompensation, AccelCompensation 0 none / 1 bias, two reserved;
NED re-expresses DeltaTheta/DeltaVel in NED before summing, see _integration_frame): stored and read
back, and register 30's SerialChecksum field (1 8-bit, 2 CRC-16; the `checksum` option sets it at start) picks the checksum of the
asynchronous ASCII sentences (replies always use the command's kind); 75-77 binary outputs 1-3:
`asyncMode, rateDivisor, outputGroup (hex), groupField (hex) per set group bit`. A written binary output is sent
at base_rate_hz / rateDivisor, base_rate_hz being the model's IMU rate (VN-300 400 Hz, every other model 800 Hz,
as the manuals and ArduPilot's 800 / rate and 400 / rate divisors have it; the `base_rate_hz` option replaces it),
on every round(rateDivisor * scene rate / base_rate_hz)-th scene sample; a rate above the scene's gives every
sample and a note says so. asyncMode 0 or rateDivisor 0 turns it off (the ROS 2 node's `$VNWRG,76,0,0,0`). The
emulator's own start-up output (the `fields` option) goes out every scene sample. All outputs count samples
from one counter, so outputs with related divisors fall on the same samples as on the device. Every field the
ROS 1 / ROS 2 nodes and ArduPilot / PX4 ask for is produced (wire_formats.vectornav_binary lists what each
carries); the ones the emulator has no data for (Attitude Dcm, IMU Raw) are error 7, never a packet with
invented layout. The GPS groups (VN-200/300) carry the GNSS receiver's solution (Samples.gnss_*, else the INS
estimate and the configured satellite count, fix and uncertainties), GPS time = the sample time (UTC Unix ns:
the run's `--start-time` + scene time) + leap seconds, firmware_protocols.gnss_time: ArduPilot's VN-300
sequence (`$VNWRG,77,3,80,49,0003,26B8,0018`) gets its GNSS packet. A VN-200/300 also has the GNSS registers the ROS 2
node reads after configuring: 55 GNSS configuration (5 integers), 57 antenna
offset (3 reals) and, on a VN-300, 93 compass baseline (6 reals), stored and read back (a VN-1xx answers 8).

Errors (`$VNERR,<2 digits>`): 03 bad checksum (or none), 04 unknown command, 05 / 06 too few / too many
parameters, 07 invalid parameter, 08 invalid register (unknown, or read-only on write). Input that is not a
command line is ignored and counted; a line cut by a new `$` is answered as what it is (usually 03), but one
physical line (up to CR or LF) gets at most one error reply: a flood of `$` is answered once, not per byte.
"""
from __future__ import annotations

import re

from firmware_protocols import attitude
from firmware_protocols.base import Samples
from firmware_protocols.devices.base import Device, LinkRequest, SinceLastOutput, preset_settings, single
from firmware_protocols.gnss_time import GPS_WEEK_OFFSET_RETIRED
from firmware_protocols.registry import attach_device
from firmware_protocols.vectornav_common import sentence, verify_line
from firmware_protocols.wire_formats.vectornav_ascii import AsciiEncoder
from firmware_protocols.wire_formats.vectornav_binary import (_FIELDS, DEFAULT_FIELDS, BinaryEncoder,
                                                              _layout_from_selection, every_field_layout,
                                                              parse_fields)

DEFAULT_MODEL = "VN-100T-CR"
ERR_CHECKSUM, ERR_COMMAND, ERR_FEW, ERR_MANY, ERR_PARAMETER, ERR_REGISTER = 3, 4, 5, 6, 7, 8
ASCII_TYPES = {0: None, 1: "VNYPR", 14: "VNYMR", 19: "VNIMU"}
ASCII_RATES = (1, 2, 4, 5, 10, 20, 25, 40, 50, 100, 200)
BAUD_RATES = (9600, 19200, 38400, 57600, 115200, 128000, 230400, 460800, 921600)
_CHECKSUM_CODE = {"xor": 1, "crc": 2}
_INT_REGISTERS = {30: (0, 0, 0, 0, 1, 0, 1), 32: (3, 0, 0, 0, 0, 0, 0, 100000000, 0), 35: (1, 1, 1, 1),
                  82: (0, 0, 0, 0, 0)}
# Register 82, Delta Theta and Delta Velocity Configuration (VectorNav's C library, VnSensor_read/
# writeDeltaThetaAndDeltaVelocityConfiguration: u8 IntegrationFrame, u8 GyroCompensation, u8 AccelCompensation,
# u8 Reserved1 (EarthRateCorrection in the newer SDK), u16 Reserved2; enums VnIntegrationFrame BODY 0 / NED 1,
# VnCompensationMode NONE 0 / BIAS 1): each field's allowed values.
_DELTA_CONFIG_VALUES = (range(2), range(2), range(2), range(256), range(65536))
INTEGRATION_NED = 1
# The GNSS registers of a VN-200/VN-300 (none on a VN-1xx, whose reads are error 8), which the ROS 2 node reads
# after configuring: 55 GNSS configuration (vnproglib `$VNWRG,55,%u,%u,5,0,0`: mode 0 internal receiver,
# PPS source 0, rate 5 Hz, two reserved), 57 antenna A offset (3 floats, m, body axes) and, on a VN-300, 93
# the compass baseline (position 3 floats m, uncertainty 3 floats m; the factory's 1 m forward, 0.0254 m).
_GNSS_INT_REGISTERS = {55: (0, 0, 5, 0, 0)}
_GNSS_FLOAT_REGISTERS = {57: (0.0, 0.0, 0.0)}
_COMPASS_FLOAT_REGISTERS = {93: (1.0, 0.0, 0.0, 0.0254, 0.0254, 0.0254)}
_MAX_LINE = 256
_LINE_END = re.compile(rb"[\r\n$]")

# Presets: what a driver's parser expects before (or instead of) configuring the unit.
ARDUPILOT_IMU = "common:timestartup,angularrate,accel,imu,magpres"      # FA 01 21 07
ARDUPILOT_AHRS = "common:timestartup;attitude:yawpitchroll,quaternion,ypru"   # FA 11 01 00 06 01
PX4_OUTPUT2 = ("time:timestartup;imu:temp,pres,mag;attitude:quaternion,linearaccelned;"
               "ins:insstatus,poslla,velned,posu,velu")
PRESETS = {
    "ardupilot": ({"outputs": ((ARDUPILOT_IMU, 1), (ARDUPILOT_AHRS, 16)), "base_rate_hz": 800.0},
                  "ArduPilot's VN-100 pair: IMU packet FA 01 21 07 every sample, AHRS packet FA 11 01 00 06 01 "
                  "at 800/16 = 50 Hz of an 800 Hz unit"),
    "px4": ({"outputs": ((DEFAULT_FIELDS, 1), (PX4_OUTPUT2, 8))},
            "PX4's binary outputs 1 (TimeStartup; IMU Accel, AngularRate) and 2 (divider 8: IMU Temp, Pres, Mag; "
            "Attitude Quaternion, LinearAccelNed; INS InsStatus, PosLla, VelNed, PosU, VelU)"),
}


class _Reject(Exception):
    """A command the device answers with $VNERR,<code>."""

    def __init__(self, code: int):
        self.code = code


def imu_rate_hz(model: str) -> float:
    """The IMU rate a binary output's rate divisor divides on this model: 400 Hz on a VN-300, 800 Hz on the
    others (VN-100, VN-110, VN-200, VN-310), as their manuals and ArduPilot's AP_ExternalAHRS_VectorNav
    (which writes 800 / rate or, for a VN-300, 400 / rate) assume."""
    return 400.0 if str(model).startswith("VN-300") else 800.0


class _BinaryOutput:
    """One binary output register. `every`: the samples between packets when fixed by the emulator's own start-up
    configuration (every scene sample), else None: the divisor, scaled from the unit's IMU rate to the scene's."""

    def __init__(self, mode: int = 0, divisor: int = 1, layout=None, encoding: dict | None = None,
                 every: int | None = None):
        self.mode, self.divisor, self.layout, self.every = mode, divisor, layout, every
        self.encoder = BinaryEncoder(layout, **(encoding or {})) if layout is not None else None

    @property
    def active(self) -> bool:
        """Async mode 0 or rate divisor 0 turns the output off (vnproglib's ASYNCMODE_NONE; the ROS 2 driver's
        `$VNWRG,76,0,0,0` for an unused output)."""
        return bool(self.mode) and self.divisor > 0 and self.encoder is not None

    def register_text(self) -> str:
        if self.layout is None:
            return f"{self.mode},{self.divisor},00"
        return f"{self.mode},{self.divisor},{self.layout.groups:02X}," + ",".join(f"{m:04X}" for m in self.layout.masks)


class VectorNavDevice(Device):
    carries_increments = True    # a driver may configure the integrated outputs at any time
    def __init__(self, rate_hz: float, fields=None, ascii_type: int = 0, checksum: str = "xor",
                 model: str = DEFAULT_MODEL, preset: str | None = None, base_rate_hz: float | None = None,
                 serial_number: int = 100012345, firmware: str = "2.1.0.0", hardware_revision: int = 2,
                 baud: int = 115200, gps_week_offset=None, num_sats: int | None = None,
                 gnss_fix: int | None = None, gnss_pos_u=None, gnss_vel_u: float | None = None):
        super().__init__(rate_hz)
        constants = {name: value for name, value in (("gnss_num_sats", num_sats), ("gnss_fix", gnss_fix),
                                                      ("gnss_pos_u", gnss_pos_u), ("gnss_vel_u", gnss_vel_u))
                     if value is not None}
        # every binary output's encoder, the configured ones and those a register write makes, encodes so
        if gps_week_offset is not None:
            raise ValueError(GPS_WEEK_OFFSET_RETIRED)
        self._encoding = {"constants": constants}
        BinaryEncoder(DEFAULT_FIELDS, **self._encoding)      # bad values fail here, at start
        outputs = ((fields if fields is not None else DEFAULT_FIELDS, 1),) if ascii_type == 0 else ()
        if preset is not None:
            settings = preset_settings(PRESETS, preset, fields is not None)
            outputs = settings["outputs"]
            base_rate_hz = settings.get("base_rate_hz", base_rate_hz) if base_rate_hz is None else base_rate_hz
        every = None if preset is not None else 1      # the plain stream: every scene sample
        if not str(model).startswith("VN-"):
            raise ValueError(f"model: VectorNav model numbers begin 'VN-' (drivers check), got {model!r}")
        if baud not in BAUD_RATES:
            raise ValueError(f"baud: one of {', '.join(map(str, BAUD_RATES))}, got {baud}")
        if base_rate_hz is not None and (isinstance(base_rate_hz, bool) or not isinstance(base_rate_hz, (int, float))
                                         or not 0 < base_rate_hz < 1e6):
            raise ValueError(f"base_rate_hz: a rate in Hz > 0, got {base_rate_hz!r}")
        self.base_rate_hz = float(base_rate_hz or imu_rate_hz(model))
        if checksum not in _CHECKSUM_CODE:
            raise ValueError(f"checksum: 'xor' or 'crc', got {checksum!r}")
        ints = dict(_INT_REGISTERS)
        gnss = not str(model).startswith("VN-1")
        if gnss:
            ints.update(_GNSS_INT_REGISTERS)
        floats = {**(_GNSS_FLOAT_REGISTERS if gnss else {}),
                  **(_COMPASS_FLOAT_REGISTERS if str(model).startswith("VN-3") else {})}
        ints[30] = ints[30][:4] + (_CHECKSUM_CODE[checksum],) + ints[30][5:]
        self.fixed = {1: str(model), 2: str(int(hardware_revision)), 3: str(int(serial_number)), 4: str(firmware)}
        factory = {"user_tag": "", "baud": baud, "ascii_type": ascii_type,
                   "ascii_rate": min(ASCII_RATES, key=lambda r: abs(r - rate_hz)) if ascii_type else 40,
                   "ints": ints, "floats": floats,
                   "binary": [(3, divisor, parse_fields(spec), every) for spec, divisor in outputs]}
        self._factory = factory
        self._saved = factory
        self._ascii_encoders = {}
        self._made = []
        self._apply(factory)
        self.tick = 0
        self.increments = SinceLastOutput()
        self.paused = False
        self._buf = bytearray()
        self._line_erred = False     # this physical line has had its one error reply (see _receive)
        self.bytes_per_sample = sum(out.layout.packet_size for out in self.binary if out.layout is not None) or (
            self._ascii_encoder().bytes_per_sample if self.ascii_type else 0)

    # - configuration -
    def _apply(self, settings: dict) -> None:
        self.user_tag, self.baud = settings["user_tag"], settings["baud"]
        self.ascii_type, self.ascii_rate = settings["ascii_type"], settings["ascii_rate"]
        self.ints = dict(settings["ints"])
        self.floats = dict(settings["floats"])
        self.binary = [_BinaryOutput(mode, divisor, layout, self._encoding, every)
                       for mode, divisor, layout, every in settings["binary"]]
        self.binary += [_BinaryOutput() for _ in range(3 - len(self.binary))]
        self._made += [o.encoder for o in self.binary if o.encoder is not None]

    def _snapshot(self) -> dict:
        return {"user_tag": self.user_tag, "baud": self.baud, "ascii_type": self.ascii_type,
                "ascii_rate": self.ascii_rate, "ints": dict(self.ints), "floats": dict(self.floats),
                "binary": [(o.mode, o.divisor, o.layout, o.every) for o in self.binary]}

    def _ascii_encoder(self):
        # Asynchronous sentences carry the checksum register 30's SerialChecksum field selects (2 = CRC-16).
        key = (ASCII_TYPES[self.ascii_type], "crc" if self.ints[30][4] == 2 else "xor")
        if key not in self._ascii_encoders:
            self._ascii_encoders[key] = AsciiEncoder(*key)
        return self._ascii_encoders[key]

    def _samples_per(self, output: _BinaryOutput) -> int:
        if output.every is not None:
            return output.every
        return max(1, int(round(output.divisor * self.rate_hz / self.base_rate_hz)))

    def _note_rate(self, register: int, output: _BinaryOutput) -> None:
        """Say so when a written output asks for more than the scene's samples give (nothing is invented)."""
        if output.active and self.base_rate_hz / output.divisor > self.rate_hz * 1.001:
            self.notes.append(f"VectorNav register {register}: {self.base_rate_hz:g} / {output.divisor} = "
                              f"{self.base_rate_hz / output.divisor:g} Hz asked, the scene's {self.rate_hz:g} Hz "
                              "samples give every sample instead")

    def encoders(self):
        # every encoder ever made, so replaced outputs' saturation counts stay in the total
        return self._made + list(self._ascii_encoders.values())

    # - output -
    def output(self, samples: Samples, i: int) -> bytes:
        tick = self.tick
        self.tick += 1
        self.increments.add(samples, i, self._integration_frame(samples, i))
        if self.paused:
            return b""
        parts = []
        one = None
        for out in self.binary:
            if out.active and tick % self._samples_per(out) == 0:
                one = one or self.increments.attach(single(samples, i))
                parts.append(out.encoder.encode(one).data)
                self.increments.sent(out.encoder)
        if self.ascii_type and tick % max(1, int(round(self.rate_hz / self.ascii_rate))) == 0:
            parts.append(self._ascii_encoder().encode(one or single(samples, i)).data)
        return b"".join(parts)

    def _integration_frame(self, samples: Samples, i: int):
        """Register 82's IntegrationFrame NED: each interval's increments re-expressed in NED before they are
        summed (the device integrates in that frame), from the sample's attitude; None keeps body axes.
        GyroCompensation/AccelCompensation BIAS subtract the device's own filter's bias estimate, which this
        emulation does not run (its estimate is zero); Reserved1 (EarthRateCorrection in newer firmware) and
        Reserved2 are stored and read back, not applied."""
        if self.ints[82][0] != INTEGRATION_NED or samples.delta_theta is None:
            return None
        quat = samples.quat[i] if samples.quat is not None else (1.0, 0.0, 0.0, 0.0)
        return attitude.increments_in_reference(quat, samples.delta_theta[i], samples.delta_velocity[i])

    # - input -
    def warm_up(self, samples: Samples) -> None:
        """Every binary field a driver may ask for (register 75-77), encoded once: the derived quantities' compiled
        code (vectornav_quantities) is then loaded before the first deadline, not at the driver's write."""
        BinaryEncoder(every_field_layout(samples.delta_theta is not None), **self._encoding).encode(samples)

    def _receive(self, data: bytes, now_ns: int) -> list:
        """Lines out of the byte stream in one pass: positions move forward and the buffer is cut once, since
        cutting or searching from its start per line is quadratic in a flood of lines (`$VNRRG,` x 128 KiB: 42 s).
        A line cut by a new `$` is answered, but a physical line (up to CR / LF) gets at most one error reply:
        a flood of `$` or of cut commands is answered once, not byte by byte."""
        buf = self._buf
        buf += data
        replies = []
        pos, size = 0, len(buf)
        while pos < size:
            start = buf.find(b"$", pos)
            if start < 0:
                break
            self.stats.ignored_bytes += start - pos
            pos = start
            end = _LINE_END.search(buf, pos + 1)
            if end is None:
                if size - pos > _MAX_LINE:        # a '$' followed by a flood without a line end
                    self.stats.ignored_bytes += size - pos
                    pos = size
                break
            line = bytes(buf[pos:min(end.start(), pos + _MAX_LINE)])
            cut = buf[end.start()] == ord("$")
            pos = end.start()
            while pos < size and buf[pos] in b"\r\n":
                pos += 1
            errors = self.stats.errors
            reply = self._answer(line)
            if self.stats.errors == errors:
                replies.append(reply)
            elif not self._line_erred:
                replies.append(reply)
                self._line_erred = cut
            else:                                   # a second error on one line: not answered
                self.stats.errors -= 1
                self.stats.ignored_bytes += len(line)
            if not cut:
                self._line_erred = False
        if pos == size or buf.find(b"$", pos) < 0:
            self.stats.ignored_bytes += size - pos
            pos = size
        del buf[:pos]
        return replies

    def _drop_partial(self) -> int:
        n = len(self._buf)
        self._buf.clear()
        self._line_erred = False
        return n

    def _answer(self, line: bytes) -> bytes:
        body, star, cs = line[1:].partition(b"*")
        kind = "crc" if len(cs) == 4 else "xor"
        try:
            if not star or (cs.upper() != b"XX" and verify_line(line) is None):
                raise _Reject(ERR_CHECKSUM)
            try:
                text = body.decode("ascii")
            except UnicodeDecodeError:
                raise _Reject(ERR_COMMAND) from None
            command, *args = text.split(",")
            reply = self._command(command, args)
        except _Reject as reject:
            self.stats.errors += 1
            return sentence(f"VNERR,{reject.code:02d}".encode("ascii"), kind)
        self.stats.commands += 1
        return sentence(reply.encode("ascii"), kind)

    def _command(self, command: str, args: list) -> str:
        if command == "VNRRG":
            register = self._register_number(args, 1)
            return f"VNRRG,{register:02d},{self._read(register)}"
        if command == "VNWRG":
            register = self._register_number(args, 2)
            self._write(register, args[1:])
            return ",".join([f"VNWRG,{register:02d}"] + args[1:])
        if command == "VNASY":
            _count(args, 1, 1)
            if args[0] not in ("0", "1"):
                raise _Reject(ERR_PARAMETER)
            self.paused = args[0] == "0"
            return f"VNASY,{args[0]}"
        if command in ("VNWNV", "VNRFS", "VNRST"):
            _count(args, 0, 0)
            if command == "VNWNV":
                self._saved = self._snapshot()
            elif command == "VNRFS":
                self._saved = self._factory
                self._apply(self._factory)
            else:
                old_baud = self.baud
                self._apply(self._saved)
                self.paused = False
                if self.baud != old_baud:
                    self.link_requests.append(LinkRequest(baud=self.baud))
            return command
        raise _Reject(ERR_COMMAND)

    @staticmethod
    def _register_number(args: list, least: int) -> int:
        if len(args) < least or not args[0]:
            raise _Reject(ERR_FEW)
        if not args[0].isdigit():
            raise _Reject(ERR_PARAMETER)
        return int(args[0])

    def _read(self, register: int) -> str:
        if register in self.fixed:
            return self.fixed[register]
        if register == 0:
            return self.user_tag
        if register == 5:
            return str(self.baud)
        if register == 6:
            return str(self.ascii_type)
        if register == 7:
            return str(self.ascii_rate)
        if register in self.ints:
            return ",".join(map(str, self.ints[register]))
        if register in self.floats:
            return ",".join(f"{v:+.6f}" for v in self.floats[register])
        if 75 <= register <= 77:
            return self.binary[register - 75].register_text()
        raise _Reject(ERR_REGISTER)

    def _write(self, register: int, values: list) -> None:
        if register in self.fixed or not (register in (0, 5, 6, 7) or register in self.ints or register in self.floats
                                          or 75 <= register <= 77):
            raise _Reject(ERR_REGISTER)
        if register == 0:
            _count(values, 1, 1)
            tag = values[0]
            if len(tag) > 20 or not tag.isprintable():
                raise _Reject(ERR_PARAMETER)
            self.user_tag = tag
        elif register in (5, 6, 7):       # value [, serial port 1 or 2]
            _count(values, 1, 2)
            value = _integer(values[0])
            if len(values) == 2 and values[1] not in ("1", "2"):
                raise _Reject(ERR_PARAMETER)
            if register == 5:
                if value not in BAUD_RATES:
                    raise _Reject(ERR_PARAMETER)
                if value != self.baud:
                    self.baud = value
                    self.link_requests.append(LinkRequest(baud=value))
            elif register == 6:
                if value not in ASCII_TYPES:
                    raise _Reject(ERR_PARAMETER)
                self.ascii_type = value
            else:
                if value not in ASCII_RATES:
                    raise _Reject(ERR_PARAMETER)
                self.ascii_rate = value
        elif register in self.floats:
            expected = len(self.floats[register])
            _count(values, expected, expected)
            self.floats[register] = tuple(_real(v) for v in values)
        elif register in self.ints:
            expected = len(self.ints[register])
            _count(values, expected, expected)
            numbers = tuple(_integer(v) for v in values)
            if register == 82 and any(v not in allowed for v, allowed in zip(numbers, _DELTA_CONFIG_VALUES)):
                raise _Reject(ERR_PARAMETER)
            self.ints[register] = numbers
        else:
            self.binary[register - 75] = output = self._binary_output(values, self._encoding)
            if output.encoder is not None:
                self._made.append(output.encoder)
            self._note_rate(register, output)

    @staticmethod
    def _binary_output(values: list, encoding: dict) -> _BinaryOutput:
        _count(values, 3, 3 + 7)
        mode, divisor = _integer(values[0]), _integer(values[1])
        groups = _hex(values[2])
        if not 0 <= mode <= 3 or not 0 <= divisor <= 65535 or not 0 <= groups <= 0x7F:
            raise _Reject(ERR_PARAMETER)
        bits = [b for b in range(8) if groups >> b & 1]
        _count(values[3:], len(bits), len(bits))
        if not bits:
            return _BinaryOutput(mode, divisor)
        selection = dict(zip(bits, (_hex(v) for v in values[3:])))
        if any(b not in _FIELDS for b in bits) or any(not 0 < m <= 0xFFFF for m in selection.values()):
            raise _Reject(ERR_PARAMETER)
        layout = _layout_from_selection(selection)
        if layout is None or any(not f.quantities for f in layout.fields):
            raise _Reject(ERR_PARAMETER)       # a field the emulator has no data for
        return _BinaryOutput(mode, divisor, layout, encoding)


def _count(values: list, least: int, most: int) -> None:
    if len(values) < least:
        raise _Reject(ERR_FEW)
    if len(values) > most:
        raise _Reject(ERR_MANY)


def _integer(text: str) -> int:
    try:
        value = int(text, 10)
    except ValueError:
        raise _Reject(ERR_PARAMETER) from None
    return value


def _real(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _Reject(ERR_PARAMETER) from None
    if not abs(value) < 1e6:            # nan, inf, and offsets no antenna has
        raise _Reject(ERR_PARAMETER)
    return value


def _hex(text: str) -> int:
    try:
        return int(text, 16)
    except ValueError:
        raise _Reject(ERR_PARAMETER) from None


_OPTIONS = {
    "model": f"register 1, the model number (default {DEFAULT_MODEL}; ArduPilot picks AHRS or INS by it)",
    "preset": "named output set: " + "; ".join(f"{k}: {v[1]}" for k, v in PRESETS.items()),
    "base_rate_hz": "the IMU rate that binary-output rate divisors divide (default: the model's, VN-300 400 Hz, "
                    "others 800 Hz)",
    "serial_number": "register 3 (default 100012345)",
    "firmware": "register 4 (default 2.1.0.0)",
    "hardware_revision": "register 2 (default 2)",
    "baud": "register 5 at start (default 115200)",
    "gps_week_offset": "retired: GPS time follows --start-time (UTC) + scene time",
    "num_sats": "GNSS NumSats (default 12)",
    "gnss_fix": "GNSS Fix: 0 none, 1 time only, 2 2D, 3 3D (default 3)",
    "gnss_pos_u": "GNSS PosU, 1 sigma north, east, down in m (default [1.0, 1.0, 1.5])",
    "gnss_vel_u": "GNSS VelU, 1 sigma speed in m/s (default 0.05)",
}
_PRESET_LIST = {name: (settings, text) for name, (settings, text) in PRESETS.items()}
attach_device("vectornav-binary", lambda rate_hz, **options: VectorNavDevice(rate_hz, **options), _OPTIONS,
              _PRESET_LIST, navigation=True, device_class=VectorNavDevice)
for _type, _name in ((14, "VNYMR"), (19, "VNIMU")):
    attach_device(f"vectornav-{_name.lower()}",
                  lambda rate_hz, _t=_type, **options: VectorNavDevice(rate_hz, ascii_type=_t, **options),
                  {k: v for k, v in _OPTIONS.items() if k != "preset"}, navigation=True,
                  device_class=VectorNavDevice)
