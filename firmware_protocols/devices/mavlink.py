"""A MAVLink IMU component that announces itself and honours rate requests.

What a ground station or companion library needs (../shared/specs/devices.md, "MAVLink"): MAVSDK calls a
system connected, and MAVProxy keeps a link up, only while HEARTBEAT (msg 0) arrives at 1 Hz; rates are
asked for with COMMAND_LONG (msg 76) carrying MAV_CMD_SET_MESSAGE_INTERVAL (511: param1 message id,
param2 interval in us, -1 = off, 0 = default) or MAV_CMD_REQUEST_MESSAGE (512: param1 message id), and
every COMMAND_LONG addressed to us is answered with COMMAND_ACK (msg 77). Message layouts, CRC_EXTRA
values and enum values are those of MAVLink's common.xml as pymavlink generates it (HEARTBEAT 50,
COMMAND_LONG 152, COMMAND_ACK 143; MAV_TYPE_IMU 40, MAV_AUTOPILOT_INVALID 8, MAV_STATE_ACTIVE 4,
MAV_RESULT ACCEPTED 0 / DENIED 2 / UNSUPPORTED 3).

- HEARTBEAT goes out from the stream's sysid/compid once per second of sample time, interleaved with the IMU
  messages on the same link and sharing their sequence numbers (one sender, one sequence). Type and
  autopilot are options; the default describes a sensor component (MAV_TYPE_IMU, MAV_AUTOPILOT_INVALID).
- A COMMAND_LONG is ours when its target system is ours or 0 (broadcast) and its target component is ours
  or 0. Others are ignored (counted as ignored input): on a shared link they belong to someone else.
- SET_MESSAGE_INTERVAL for the streamed IMU message sets a divider of the sample rate: the interval is
  rounded to the nearest whole number of sample periods (at least one), since samples exist only at the
  scene's rate; -1 stops the message, 0 restores every sample. For HEARTBEAT it sets the heartbeat
  period the same way. Other message ids: DENIED (we cannot stream them). So are the values common.xml does
  not allow: a message id or interval that is NaN or infinite, a negative interval other than -1, and one
  longer than MESSAGE_INTERVAL's int32 microseconds could report back.
- REQUEST_MESSAGE for the IMU message or HEARTBEAT: ACCEPTED and the message is sent once with the next
  sample; others: DENIED. Any other command: UNSUPPORTED.
- GET_MESSAGE_INTERVAL (510, param1 message id), and REQUEST_MESSAGE for MESSAGE_INTERVAL (param1 244,
  param2 message id) that replaces it: MESSAGE_INTERVAL (msg 244, CRC_EXTRA 95: interval_us i32, message_id
  u16) goes out at once, then COMMAND_ACK ACCEPTED (ArduPilot's order). interval_us is the divider in
  sample periods (rounded to whole microseconds), -1 for a stream turned off, 0 for a message this
  component does not stream (the values common.xml gives MESSAGE_INTERVAL).
- Signing as configured: with a signing key every frame we send (HEARTBEAT and COMMAND_ACK too) is signed on
  the encoder's SigningLink, so timestamps stay increasing across all of them; incoming commands must
  then carry a valid signature with that key (unsigned or forged ones are counted as errors and not
  answered, as MAVLink's signing rules ask).
- `also`: more messages of the sensor head on the same link (comma-separated format names, e.g.
  "mavlink-hil-gps,mavlink-scaled-pressure,mavlink-attitude"; wire_formats.mavlink_nav), sharing the sequence
  numbers and the signing link. Each goes out at the samples its encoder sends it (GNSS fixes on new solutions,
  SCALED_PRESSURE on new barometer readings (Samples.baro_new), attitude every sample), thinned by its own divider that
  SET_MESSAGE_INTERVAL sets and GET_MESSAGE_INTERVAL reports like the IMU message's; REQUEST_MESSAGE sends one
  with the next sample (a GNSS or pressure message then repeats the solution or reading held). A message thinned
  by its divider carries the new readings (Samples.*_new) of the samples it skipped: HIL_SENSOR at 33 Hz still
  flags every reading of a 10 Hz barometer, in the first message after it. Also any nav format streamed alone.
Incoming frames may be MAVLink 1 or 2; replies are MAVLink 2.
"""
from __future__ import annotations

import hashlib
import math
import re
import struct

import numpy as np


from firmware_protocols.base import EncodeError, Samples
from firmware_protocols.crc import crc16_mcrf4xx_bytes
from firmware_protocols.devices.base import Device, Divider, Periodic, single, view
from firmware_protocols.wire_formats.mavlink import (HEADER_LEN, INCOMPAT_SIGNED, MESSAGES, P_COMPID, P_SEQ, P_SYSID,
                                                     SIGNATURE_LEN, STX_V1, STX_V2, MavlinkEncoder)
from firmware_protocols.wire_formats.mavlink import pack_frame as wire_frame
from firmware_protocols.wire_formats.mavlink_nav import NAV_MESSAGES, MavlinkNavEncoder
from firmware_protocols.registry import attach_device

HEARTBEAT, COMMAND_LONG, COMMAND_ACK, MESSAGE_INTERVAL = 0, 76, 77, 244
_CRC_EXTRA = {HEARTBEAT: 50, COMMAND_LONG: 152, COMMAND_ACK: 143, MESSAGE_INTERVAL: 95}
MAV_CMD_GET_MESSAGE_INTERVAL, MAV_CMD_SET_MESSAGE_INTERVAL, MAV_CMD_REQUEST_MESSAGE = 510, 511, 512
MAV_RESULT_ACCEPTED, MAV_RESULT_DENIED, MAV_RESULT_UNSUPPORTED = 0, 2, 3
MAV_TYPE_IMU, MAV_AUTOPILOT_INVALID, MAV_STATE_ACTIVE = 40, 8, 4
MAVLINK_VERSION = 3
_COMMAND_LONG = struct.Struct("<7fHBBB")
# Ranges shorter than this are encoded sample by sample: one call for a range costs about three samples' calls.
_MANY_AT_ONCE = 4
# Samples `output` encodes at once (MavlinkDevice.ahead): one encoder call per sample was most of the live sender's
# work at 10 kHz (about 45 us of CPU when called every 100 us, caches cold between calls, of the 100 us a sample
# has), and a call for 16 samples costs less than two single ones (tools/bench_catch_up.py).
_AHEAD = 16
_COMMAND_LONG_LEN = _COMMAND_LONG.size   # 33
_STX = re.compile(bytes([ord("["), STX_V2, STX_V1, ord("]")]))
_INT32_MAX = 2 ** 31 - 1     # MESSAGE_INTERVAL.interval_us is an int32: a longer interval could not be read back


def pack_frame(msgid: int, payload: bytes, seq: int, sysid: int, compid: int, link=None) -> bytes:
    """One MAVLink 2 frame of a message whose CRC_EXTRA is in _CRC_EXTRA, signed with the wall clock's time."""
    return wire_frame(msgid, _CRC_EXTRA[msgid], payload, seq, sysid, compid, link)


class _FrameReader:
    """Byte stream -> (msgid, payload, sysid, compid, signed frame bytes or None) for the message ids we
    know the CRC_EXTRA of; everything else is skipped and counted. Never raises."""

    def __init__(self):
        self.buf = bytearray()
        self.skipped = 0

    def feed(self, data: bytes) -> list:
        buf = self.buf
        buf += data
        out, pos = [], 0
        while True:
            # One search for either start byte: finding each separately rescans the rest of the buffer for
            # the absent one at every false start, quadratic in a flood of the other (0xFD x 2 MB: minutes).
            match = _STX.search(buf, pos)
            start = len(buf) if match is None else match.start()
            self.skipped += start - pos
            pos = start
            if pos >= len(buf):
                break
            step = self._frame(buf, pos, out)
            if step is None:
                break
            pos += step
        del buf[:pos]
        if len(buf) > 4096:          # a flood of half frames must not grow memory
            self.skipped += len(buf)
            del buf[:]
        return out

    def drop_partial(self) -> int:
        """Forget a frame still waiting for its end (a datagram is whole: the rest will never come); how many
        bytes that was."""
        n = len(self.buf)
        self.skipped += n
        del self.buf[:]
        return n

    def _frame(self, buf, pos, out):
        """Bytes consumed at pos: a frame's length, 1 for a false start, None when more bytes are needed."""
        v2 = buf[pos] == STX_V2
        head = HEADER_LEN if v2 else 6
        if len(buf) - pos < head:
            return None
        plen = buf[pos + 1]
        signed = v2 and bool(buf[pos + 2] & INCOMPAT_SIGNED)
        msgid = int.from_bytes(buf[pos + 7:pos + 10], "little") if v2 else buf[pos + 5]
        total = head + plen + 2 + (SIGNATURE_LEN if signed else 0)
        extra = _CRC_EXTRA.get(msgid)
        if extra is None or (v2 and buf[pos + 2] & ~INCOMPAT_SIGNED):
            self.skipped += 1
            return 1
        if len(buf) - pos < total:
            return None
        end = pos + head + plen
        if crc16_mcrf4xx_bytes(bytes(buf[pos + 1:end]) + bytes([extra])) != buf[end] | buf[end + 1] << 8:
            self.skipped += 1
            return 1
        sysid, compid = (buf[pos + 5], buf[pos + 6]) if v2 else (buf[pos + 3], buf[pos + 4])
        frame = bytes(buf[pos:pos + total])
        out.append((msgid, frame[head:head + plen], sysid, compid, frame if signed else None, v2))
        return total


class _Ahead:
    """Packets encoded at once for samples start to start + n - 1 of one block, handed out one by one by `output`
    (next: the next to hand out), with the sequence number and heartbeat count before the first."""
    __slots__ = ("samples", "start", "next", "end", "packets", "seq", "beat")

    def __init__(self, samples, start: int, n: int, packets: list, seq: int, beat: int):
        self.samples, self.start, self.next, self.end = samples, start, start, start + n
        self.packets, self.seq, self.beat = packets, seq, beat


class MavlinkDevice(Device):
    """The IMU message of `message` at the scene's rate (or as asked), HEARTBEAT at 1 Hz, COMMAND_ACKs.

    Encoding ahead: while `output` would send the main message alone at every sample, it encodes the next `ahead`
    samples of the block in one call and hands their packets out one by one. Anything that could change what is
    due takes the unsent ones back first (_rewind: input from the driver, a sample asked for out of turn, a range
    asked for), so every packet is the one `output` sample by sample gives under the configuration in force."""

    ahead = _AHEAD        # samples encoded at once by `output` (1: one at a time)

    def __init__(self, rate_hz: float, message: str = "mavlink-highres", heartbeat_type: int = MAV_TYPE_IMU,
                 heartbeat_autopilot: int = MAV_AUTOPILOT_INVALID, also="", **encoder_options):
        super().__init__(rate_hz)
        names = [n.strip() for n in also.split(",") if n.strip()] if isinstance(also, str) else list(also)
        unknown = [n for n in names if n not in NAV_MESSAGES or n == message]
        if unknown:
            raise ValueError(f"also: {', '.join(map(repr, unknown))} is not one of {', '.join(NAV_MESSAGES)} "
                             "(or repeats the main message)")
        if message in NAV_MESSAGES:
            self.encoder = MavlinkNavEncoder(message, **encoder_options)
        else:
            self.encoder = MavlinkEncoder(message, **encoder_options)
        self.spec = self.encoder.spec
        self._encodes_ranges = isinstance(self.encoder, MavlinkEncoder)
        for name, value in (("heartbeat_type", heartbeat_type), ("heartbeat_autopilot", heartbeat_autopilot)):
            if not 0 <= int(value) <= 255:
                raise ValueError(f"{name}: must be 0..255, got {value}")
        self.heartbeat_payload = struct.pack("<IBBBBB", 0, int(heartbeat_type), int(heartbeat_autopilot), 0,
                                             MAV_STATE_ACTIVE, MAVLINK_VERSION)
        self.imu = Divider(1)
        self.heartbeat = Periodic.every(1.0, rate_hz)
        self._once: set = set()          # message ids asked for once with REQUEST_MESSAGE
        self._ahead = None               # _Ahead: packets encoded ahead, not yet handed out
        self._plain_until = (None, 0)    # (block, sample): no range encoded ahead from here; one by one up to there
        self._unsent: dict = {}          # message id -> new-reading flags seen on samples its divider skipped
        self._reader = _FrameReader()
        self.sysid, self.compid = self.encoder_ids(self.encoder)
        self.link = self.encoder.signing_link
        shared = {k: encoder_options[k] for k in ("sign_time", "truncate") if k in encoder_options}
        # msgid -> (encoder, divider): the sensor head's other messages on this link
        self.extra = {}
        for name in names:
            options = dict(shared, sysid=self.sysid, compid=self.compid, signing_link=self.link)
            encoder = MavlinkNavEncoder(name, **options)
            self.extra[encoder.spec.msgid] = (encoder, Divider(1))
        self._stream_ts: dict = {}       # (link id, sysid, compid) -> last signing timestamp accepted
        self.bytes_per_sample = self.encoder.bytes_per_sample + sum(e.bytes_per_sample for e, _ in self.extra.values())

    @staticmethod
    def encoder_ids(encoder) -> tuple:
        if isinstance(encoder, MavlinkNavEncoder):
            return encoder.sysid, encoder.compid
        return int(encoder._params[P_SYSID]), int(encoder._params[P_COMPID])

    # one sequence for everything this component sends: the main encoder holds it
    def _next_seq(self) -> int:
        if isinstance(self.encoder, MavlinkNavEncoder):
            return self.encoder.seq
        return int(self.encoder._params[P_SEQ])

    def _set_seq(self, seq: int) -> None:
        if isinstance(self.encoder, MavlinkNavEncoder):
            self.encoder.seq = seq & 0xFF
        else:
            self.encoder._params[P_SEQ] = seq & 0xFF

    def _frame(self, msgid: int, payload: bytes) -> bytes:
        seq = self._next_seq()
        self._set_seq(seq + 1)
        return pack_frame(msgid, payload, seq, self.sysid, self.compid, self.link)

    def encoders(self):
        return [self.encoder] + [encoder for encoder, _ in self.extra.values()]

    # - output -
    def output(self, samples: Samples, i: int) -> bytes:
        ahead = self._ahead
        if ahead is not None and not (ahead.samples is samples and ahead.next == i):
            self._rewind()
            ahead = None
        if ahead is None:
            ahead = self._encode_ahead(samples, i)
        if ahead is not None:
            ahead.next = i + 1
            if ahead.next == ahead.end:
                self._ahead = None
            return ahead.packets[i - ahead.start]
        parts = []
        if self.heartbeat.due() or HEARTBEAT in self._once:
            parts.append(self._frame(HEARTBEAT, self.heartbeat_payload))
        if self.imu.due() or self.spec.msgid in self._once:
            parts.append(self._encode(self.spec.msgid, self.encoder, samples, i, self.spec.msgid in self._once))
        else:
            self._skip(self.spec.msgid, samples, i)
        for msgid, (encoder, divider) in self.extra.items():
            if divider.due() or msgid in self._once:
                encoder.seq = self._next_seq()
                parts.append(self._encode(msgid, encoder, samples, i, msgid in self._once))
                self._set_seq(encoder.seq)
            else:
                self._skip(msgid, samples, i)
        self._once.clear()
        return b"".join(parts)

    def prepare(self, samples: Samples, i: int) -> None:
        """Encode ahead from sample i now, if `output` would (Device.prepare)."""
        if self._ahead is None:
            self._encode_ahead(samples, i)

    def _encode_ahead(self, samples: Samples, i: int) -> _Ahead | None:
        """Samples i on to the block's end, the next heartbeat or `ahead` samples, encoded at once as `output` will
        hand them out (the range `_range` allows); None when they are not (then sample by sample up to there)."""
        heartbeat = self.heartbeat
        n = min(self.ahead, len(samples.time_ns) - i,
                heartbeat.period_samples - heartbeat.count if heartbeat.count else 0)
        if n <= 1 or (samples is self._plain_until[0] and i < self._plain_until[1]):
            return None
        seq, beat = self._next_seq(), heartbeat.count
        packets = self._range(samples, i, i + n, ahead=True)
        if packets is None:
            self._plain_until = (samples, i + n)
            return None
        self._ahead = _Ahead(samples, i, n, packets, seq, beat)
        return self._ahead

    def output_many(self, samples: Samples, i: int, k: int) -> list:
        """The packets encoded ahead for the range's first samples, then one encoder call for the rest when
        `_range` can, else sample by sample (Device.output_many)."""
        ahead, taken = self._ahead, []
        if ahead is not None and ahead.samples is samples and ahead.next == i:
            m = min(k, ahead.end)
            taken = ahead.packets[i - ahead.start:m - ahead.start]
            ahead.next = i = m
            if m == ahead.end:
                self._ahead = None
            if i == k:
                return taken
        if self._ahead is not None:
            self._rewind()
        packets = self._range(samples, i, k, ahead=False)
        return taken + (super().output_many(samples, i, k) if packets is None else packets)

    def _range(self, samples: Samples, i: int, k: int, ahead: bool) -> list | None:
        """Samples i to k - 1 in one encoder call, each one's packet as `output` would give it in turn (numbered
        in turn), when that is all `output` would send: the main message alone at every sample (no other message,
        none asked for once, no reading held back, no heartbeat due in the range); None otherwise, the device
        unchanged. `ahead` (encoding before the samples are due): also None, the device unchanged, on a signed
        link (a signature's timestamp is not taken back by _rewind) and when a value saturated or is not finite:
        the counts must follow what was sent, and the error come at its sample."""
        n, heartbeat = k - i, self.heartbeat
        if (n < _MANY_AT_ONCE or self.extra or self._once or self._unsent or self.imu.divider != 1
                or heartbeat.count == 0 or heartbeat.count + n > heartbeat.period_samples
                or (ahead and self.link is not None)):
            return None
        # the IMU messages' encoder takes the block and the range: no view to make
        args = (samples, i, k) if self._encodes_ranges else (view(samples, i, k),)
        if not ahead:
            encoded = self.encoder.encode(*args)
        else:
            saturated = self.encoder.saturated
            seq, counts = self._next_seq(), dict(saturated.counts)
            try:
                encoded = self.encoder.encode(*args)
            except EncodeError:
                encoded = None
            if encoded is None or saturated.counts != counts:
                saturated.counts = counts
                self._set_seq(seq)
                return None
        heartbeat.count = (heartbeat.count + n) % heartbeat.period_samples
        data, offsets = bytes(encoded.data), encoded.offsets.tolist()
        return [data[offsets[m]:offsets[m + 1]] for m in range(n)]

    def _rewind(self) -> None:
        """Forget the packets encoded ahead and not handed out: the device is as if `output` had been asked for the
        samples handed out so far only (their sequence numbers: one per packet, a GNSS message has none between
        fixes; the heartbeat count)."""
        ahead, self._ahead = self._ahead, None
        sent = ahead.next - ahead.start
        self._set_seq(ahead.seq + sum(1 for packet in ahead.packets[:sent] if packet))
        self.heartbeat.count = (ahead.beat + sent) % self.heartbeat.period_samples

    def _encode(self, msgid: int, encoder, samples: Samples, i: int, requested: bool) -> bytes:
        """Sample i as the message: a reading new at this sample, or at one its divider skipped since it was last
        sent (a rate command thinning it), is new here (the reading held is the newest), so the consumer still sees
        each sensor update at the message's rate; asked for with REQUEST_MESSAGE, the reading held goes out as
        new even between updates."""
        one = single(samples, i)
        carried = self._unsent.pop(msgid, ())
        for flag in _NEW_FLAGS:
            if getattr(one, flag) is not None and (requested or flag in carried):
                setattr(one, flag, np.ones(1))       # a fresh array: `one` holds views of the block
        return encoder.encode(one).data

    def _skip(self, msgid: int, samples: Samples, i: int) -> None:
        """Sample i is not sent as this message: remember which sensors had a new reading at it."""
        for flag in _NEW_FLAGS:
            values = getattr(samples, flag)
            if values is not None and values[i] != 0:
                self._unsent.setdefault(msgid, set()).add(flag)

    # - input -
    def _receive(self, data: bytes, now_ns: int) -> list:
        if self._ahead is not None:     # a command may change what is due from the next sample on
            self._rewind()
        replies = []
        skipped = self._reader.skipped
        for msgid, payload, sysid, compid, signed, v2 in self._reader.feed(data):
            if msgid != COMMAND_LONG:
                continue                               # a ground station's own HEARTBEAT and the like
            values = _COMMAND_LONG.unpack(bytes(payload).ljust(_COMMAND_LONG_LEN, b"\0"))
            params, command, target_sys, target_comp = values[:7], values[7], values[8], values[9]
            if target_sys not in (0, self.sysid) or target_comp not in (0, self.compid):
                self.stats.ignored_bytes += len(payload)
                continue
            if self.link is not None and not self._authentic(signed, sysid, compid):
                self.stats.errors += 1
                continue
            interval = self._interval_request(command, params)
            if interval is not None:
                replies.append(self._frame(MESSAGE_INTERVAL, struct.pack("<iH", *interval)))
                result = MAV_RESULT_ACCEPTED
            else:
                result = self._command(command, params)
            if result == MAV_RESULT_ACCEPTED:
                self.stats.commands += 1
            else:
                self.stats.errors += 1
            ack = struct.pack("<HBBiBB", command, result, 0, 0, sysid, compid)
            replies.append(self._frame(COMMAND_ACK, ack))
        self.stats.ignored_bytes += self._reader.skipped - skipped
        return replies

    def _authentic(self, frame: bytes | None, sysid: int, compid: int) -> bool:
        if frame is None or hashlib.sha256(self.link.secret_key + frame[:-6]).digest()[:6] != frame[-6:]:
            return False
        stream = (frame[-13], sysid, compid)
        stamp = int.from_bytes(frame[-12:-6], "little")
        if stamp <= self._stream_ts.get(stream, -1):
            return False                                # replayed
        self._stream_ts[stream] = stamp
        return True

    def _command(self, command: int, params) -> int:
        if command == MAV_CMD_SET_MESSAGE_INTERVAL:
            msgid, interval_us = _message_id(params[0]), params[1]
            target = {self.spec.msgid: self.imu, HEARTBEAT: None,
                      **{k: divider for k, (_, divider) in self.extra.items()}}.get(msgid, "no")
            # common.xml, MAV_CMD_SET_MESSAGE_INTERVAL param2: "Set to -1 to disable and 0 to request default
            # rate"; any other negative, a non-finite value or one MESSAGE_INTERVAL cannot report back is
            # MAV_RESULT_DENIED: "one or more parameter values are invalid ... Retrying ... will not work".
            if target == "no" or not math.isfinite(interval_us) or (interval_us < 0 and interval_us != -1) \
                    or interval_us > _INT32_MAX:
                return MAV_RESULT_DENIED
            divider = self._divider(interval_us)
            if target is None:
                if divider <= 0:
                    return MAV_RESULT_DENIED             # a component keeps announcing itself
                self.heartbeat = Periodic(divider)
            else:
                target.set(divider)
            return MAV_RESULT_ACCEPTED
        if command == MAV_CMD_REQUEST_MESSAGE:
            msgid = _message_id(params[0])
            if msgid not in (self.spec.msgid, HEARTBEAT, *self.extra):
                return MAV_RESULT_DENIED
            self._once.add(msgid)
            return MAV_RESULT_ACCEPTED
        return MAV_RESULT_UNSUPPORTED

    def _interval_request(self, command: int, params) -> tuple | None:
        """(interval_us, message id) when the command asks for a MESSAGE_INTERVAL, else None."""
        if command == MAV_CMD_GET_MESSAGE_INTERVAL:
            asked = params[0]
        elif command == MAV_CMD_REQUEST_MESSAGE and params[0] == MESSAGE_INTERVAL:
            asked = params[1]
        else:
            return None
        msgid = _message_id(asked)
        msgid = msgid if msgid is not None and msgid <= 0xFFFF else None      # MESSAGE_INTERVAL's field is u16
        if msgid == self.spec.msgid:
            samples = self.imu.divider
        elif msgid in self.extra:
            samples = self.extra[msgid][1].divider
        elif msgid == HEARTBEAT:
            samples = self.heartbeat.period_samples
        else:
            return 0, (0 if msgid is None else msgid)        # interval 0: not available from this component
        return (-1 if samples <= 0 else min(_INT32_MAX, int(round(samples * 1e6 / self.rate_hz)))), msgid

    def _drop_partial(self) -> int:
        return self._reader.drop_partial()

    def _divider(self, interval_us: float) -> int:
        """Interval in us (finite, -1 or >= 0) -> samples between messages; 0 = off, 1 = every sample (interval 0
        = default)."""
        if interval_us < 0:
            return 0
        if interval_us == 0:
            return 1
        return max(1, int(round(interval_us * 1e-6 * self.rate_hz)))


def _message_id(value: float) -> int | None:
    """A COMMAND_LONG float parameter as a MAVLink message id (24 bits), None when it is none (NaN, inf, -3, 1.5)."""
    if not math.isfinite(value) or value != int(value) or not 0 <= value <= 0xFFFFFF:
        return None
    return int(value)


#: Samples' new-reading flags: a message thinned by its divider carries those of the samples it skipped
_NEW_FLAGS = ("gnss_new", "baro_new", "mag_new")

_DEVICE_OPTIONS = {
    "heartbeat_type": f"HEARTBEAT type (MAV_TYPE), default {MAV_TYPE_IMU} (MAV_TYPE_IMU)",
    "heartbeat_autopilot": f"HEARTBEAT autopilot (MAV_AUTOPILOT), default {MAV_AUTOPILOT_INVALID} (not a flight "
                           "controller); 0 (generic) makes MAVSDK's first_autopilot() return this system",
}
_DEVICE_OPTIONS["also"] = ("more messages on the link, comma-separated: " + ", ".join(NAV_MESSAGES)
                           + " (GNSS on new fixes, SCALED_PRESSURE on new barometer readings)")
# A MAVLink device carries GNSS messages only when also= names them: their encoders say `uses_navigation`, and the
# streamer computes the navigation their fix falls back on (live.config.reports_navigation) for those streams alone.
for _name in (*MESSAGES, *NAV_MESSAGES):
    attach_device(_name, lambda rate_hz, _m=_name, **options: MavlinkDevice(rate_hz, _m, **options), _DEVICE_OPTIONS,
                  device_class=MavlinkDevice)
