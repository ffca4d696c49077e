"""Packets from issue 23 that stopped a device or its stream, each answered now as the protocol says: MAVLink's
MAV_RESULT for SET_MESSAGE_INTERVAL values common.xml does not allow, MIP's NACK codes (mip_sdk mip_result.h) for
a reply that cannot fit and a field listed twice, one $VNERR per malformed VectorNav line; floods of a sync byte
cost time linear in their size; replies wait for room ahead of samples instead of being dropped."""
import math

import numpy as np
import pytest

import firmware_protocols
from firmware_protocols import Samples
from imu_emulator.live.config import StreamConfig
from imu_emulator.live.stream import Stream

mavlink2 = pytest.importorskip("pymavlink.dialects.v20.common")
from tests.support.devices import command_long, gcs  # noqa: E402


def _samples(n=8):
    t = (np.arange(n) * 1e7).astype(np.int64)
    return Samples(t, np.tile([0.1, -0.2, 9.8], (n, 1)), np.tile([0.01, 0.02, 0.03], (n, 1)),
                   quat=np.tile([1.0, 0, 0, 0], (n, 1)), euler=np.zeros((n, 3)))


# - MAVLink -

def _acks(replies):
    mav = gcs()
    return [(m.command, m.result) for r in replies for m in mav.parse_buffer(r) or [] if m.get_type() == "COMMAND_ACK"]


def _imu_messages(device, samples, n=4):
    mav = gcs()
    return sum(m.get_type() == "HIGHRES_IMU"
               for i in range(n) for m in mav.parse_buffer(device.output(samples, i)) or [])


@pytest.mark.parametrize("msgid, interval", [
    (105, math.inf), (105, -math.inf), (105, math.nan), (math.inf, 1000), (-math.inf, 0), (math.nan, 0), (1.5, 0),
    (105, -5), (105, -0.5), (105, -2), (105, 1e30), (105, 2.0 ** 31), (0, 1e30), (0, -5)])
def test_set_message_interval_values_common_xml_does_not_allow_are_denied(msgid, interval):
    """common.xml, MAV_CMD_SET_MESSAGE_INTERVAL param2: "Set to -1 to disable and 0 to request default rate";
    MAV_RESULT_DENIED: "one or more parameter values are invalid". On 168021a ±inf raised OverflowError, -5
    turned the stream off, 1e30 broke the packing of MESSAGE_INTERVAL."""
    device = firmware_protocols.create_device("mavlink-highres", 100.0)
    samples = _samples()
    assert _acks(device.receive(command_long(msgid, interval))) == [(511, mavlink2.MAV_RESULT_DENIED)]
    assert _imu_messages(device, samples) == 4          # the stream goes on unchanged
    interval_reply = device.receive(command_long(105, command=510)) + device.receive(command_long(0, command=510))
    got = [(m.message_id, m.interval_us) for r in interval_reply for m in gcs().parse_buffer(r) or []
           if m.get_type() == "MESSAGE_INTERVAL"]
    assert got == [(105, 10_000), (0, 1_000_000)]


def test_minus_one_disables_and_zero_restores_the_default_rate():
    device = firmware_protocols.create_device("mavlink-highres", 100.0)
    samples = _samples()
    assert _acks(device.receive(command_long(105, -1))) == [(511, mavlink2.MAV_RESULT_ACCEPTED)]
    assert _imu_messages(device, samples) == 0
    assert _acks(device.receive(command_long(105, 0))) == [(511, mavlink2.MAV_RESULT_ACCEPTED)]
    assert _imu_messages(device, samples) == 4


def test_a_datagram_left_unfinished_does_not_swallow_the_next_datagrams_commands():
    """Over UDP each datagram holds whole frames: a header claiming 255 payload bytes in one datagram must not
    wait for the next datagrams (on 168021a the next three commands got no ACK)."""
    device = firmware_protocols.create_device("mavlink-highres", 100.0)
    garbage = bytes([0xFD, 0xFF, 0, 0, 0, 255, 190, 76, 0, 0]) + b"\x55" * 20
    assert device.receive(garbage, whole=True) == []
    for interval in (20_000, 30_000, 40_000):
        assert _acks(device.receive(command_long(105, interval), whole=True)) == [(511, mavlink2.MAV_RESULT_ACCEPTED)]
    assert device.imu.divider == 4
    assert device.stats.ignored_bytes == len(garbage)


@pytest.mark.parametrize("unit", [b"\xfd", b"\xfe"])
def test_a_command_behind_a_flood_of_mavlink_start_bytes_is_answered(unit):
    """The flood's tail may look like the start of a long frame: a command hidden behind it is found once that
    false frame's claimed length has arrived (the driver resending), as any MAVLink parser does. (What such a
    flood costs: test_devices_fuzz.py::test_sync_byte_floods_are_not_quadratic.)"""
    device = firmware_protocols.create_device("mavlink-highres", 100.0)
    assert device.receive(unit * 65_536) == []
    assert (511, 0) in _acks(device.receive(command_long(105, 20_000) * 8))


# - MIP -

def _fletcher16(data: bytes) -> bytes:
    a = b = 0
    for byte in data:
        a = (a + byte) & 0xFF
        b = (b + a) & 0xFF
    return bytes([a, b])


def _mip_fields(reply: bytes) -> list:
    """(descriptor, data) fields of one MIP packet, checked against its closed-form checksum."""
    assert reply[:2] == b"ue" and len(reply) == 6 + reply[3]
    assert _fletcher16(reply[:-2]) == reply[-2:]
    out, k, payload = [], 0, reply[4:-2]
    while k < len(payload):
        out.append((payload[k + 1], payload[k + 2:k + payload[k]]))
        k += payload[k]
    return out


def test_mip_replies_that_cannot_fit_one_packet_end_with_nack_command_failed():
    """127 pings in one packet: 127 acknowledgements need 508 bytes, a MIP payload holds 255. The ones that fit
    are answered, the next is NACKed 0x04 (MIP_NACK_COMMAND_FAILED, "the device could not complete the
    command"); on 168021a packet() raised ValueError."""
    from firmware_protocols.devices.microstrain import packet
    device = firmware_protocols.create_device("microstrain-mip", 100.0)
    [reply] = device.receive(packet(0x01, [(0x01, b"")] * 127))
    fields = _mip_fields(reply)
    assert fields[:-1] == [(0xF1, bytes([0x01, 0x00]))] * 62 and fields[-1] == (0xF1, bytes([0x01, 0x04]))
    assert (device.stats.commands, device.stats.errors) == (62, 65)
    assert device.output(_samples(), 0)


def test_mip_device_information_three_times_gets_two_answers_and_one_nack():
    from firmware_protocols.devices.microstrain import packet
    device = firmware_protocols.create_device("microstrain-mip", 100.0)
    [reply] = device.receive(packet(0x01, [(0x03, b"")] * 3))
    kinds = [(d, data[:2]) for d, data in _mip_fields(reply)]
    assert kinds == [(0xF1, b"\x03\x00"), (0x81, device.info[:2]), (0xF1, b"\x03\x00"), (0x81, device.info[:2]),
                     (0xF1, b"\x03\x04")]


def test_mip_message_format_listing_a_field_twice_is_nacked_invalid_parameter():
    """On 168021a it was acknowledged, then the next output raised "item listed twice"."""
    from firmware_protocols.devices.microstrain import packet
    device = firmware_protocols.create_device("microstrain-mip", 100.0)
    before = {k: list(v) for k, v in device.formats.items()}
    [reply] = device.receive(packet(0x0C, [(0x0F, bytes([1, 0x80, 2, 0x04, 0, 1, 0x04, 0, 2]))]))
    assert _mip_fields(reply) == [(0xF1, bytes([0x0F, 0x03]))]
    assert device.formats == before
    assert device.output(_samples(), 0)


# - VectorNav -

def test_a_flood_of_dollars_gets_one_error_reply_not_one_per_byte():
    """On 168021a every `$` was a line cut by the next and answered with $VNERR,03 (12x amplification)."""
    device = firmware_protocols.create_device("vectornav-binary", 100.0)
    replies = device.receive(b"$" * 10_000 + b"\r\n" + b"$VNRRG,01*XX\r\n")
    assert [r.split(b"*")[0] for r in replies] == [b"$VNERR,03", b"$VNRRG,01,VN-100T-CR"]
    assert device.stats.ignored_bytes >= 9_999


def test_a_command_cut_by_a_new_one_is_still_answered_as_before():
    device = firmware_protocols.create_device("vectornav-binary", 100.0)
    replies = device.receive(b"$VNR$VNRRG,01*XX\r\n")
    assert [r.split(b",")[0] for r in replies] == [b"$VNERR", b"$VNRRG"]


# - the reply path -

class _FullLink:
    """A transport that refuses everything while `full`, and keeps what it took in order."""

    datagrams = False

    def __init__(self):
        self.full, self.sent = False, []

    def send(self, item) -> bool:
        if self.full:
            return False
        self.sent.append(item)
        return True

    def finish(self):
        pass

    def sample_queue(self):
        pass

    def queued(self):
        return None

    def link_report(self):
        return {}

    def close(self):
        pass


def _stream():
    info = firmware_protocols.get("mavlink-highres")
    stream = Stream(StreamConfig("imu0", "mavlink-highres", "pty"), 0, info, 100.0)
    stream.transport = _FullLink()
    return stream


def test_a_reply_the_full_link_refused_goes_before_any_later_sample():
    stream = _stream()
    link = stream.transport
    link.full = True
    stream.send_reply(b"reply")
    stream.send_sample(b"sample 1")           # the reply still waits: this sample is dropped, and counted
    link.full = False
    stream.send_sample(b"sample 2")
    assert link.sent == [b"reply", b"sample 2"]
    assert (stream.sent, stream.dropped, stream.replies_sent, stream.replies_delayed) == (1, 1, 1, 1)
    summary = stream.summary()["device"]
    assert (summary["replies_sent"], summary["replies_delayed"], summary["replies_dropped"]) == (1, 1, 0)


def test_replies_that_never_find_room_are_counted_as_dropped():
    stream = _stream()
    stream.transport.full = True
    for k in range(100):
        stream.send_reply(b"reply %d" % k)
    stream.close()
    assert (stream.replies_sent, stream.replies_dropped) == (0, 100)


@pytest.mark.parametrize("name, flood", [("microstrain-mip", b"ue"), ("xsens-mtdata2", b"\xfa\xff\x30\x00")])
def test_a_flood_of_false_syncs_gets_one_error_reply_per_claimed_frame_not_per_sync(name, flood):
    """On 168021a every `ue` of a flood was a damaged packet overlapping the previous one, each NACKed: 10
    bytes out for 2 in. A damaged frame is answered once; false syncs inside it are not."""
    device = firmware_protocols.create_device(name, 100.0)
    data = flood * 5000
    replies = device.receive(data)
    assert sum(map(len, replies)) <= len(data)
    assert device.stats.errors == len(replies) > 0
