"""Target specs, whole-packet writes under backpressure, UART pacing, SLCAN lines, catching up in one write."""
import os
import time
import tty
from types import SimpleNamespace

import numpy as np
import pytest

from firmware_protocols import CAN_FRAME_DTYPE
from imu_emulator.errors import TargetError
from imu_emulator.live.config import StreamConfig
from imu_emulator.live.stream import Stream
from imu_emulator.live.transport import TargetOptions, link_capacity, parse_target
from imu_emulator.live.transport.base import Transport
from imu_emulator.live.transport.fdwriter import FdPacketWriter
from imu_emulator.live.transport.pty import PtyTransport
from imu_emulator.live.transport.slcan_pty import slcan_lines


@pytest.mark.parametrize("text, fields", [
    ("pty", dict(kind="pty")),
    ("serial:/dev/ttyUSB0@921600", dict(kind="serial", path="/dev/ttyUSB0", rate=921600)),
    ("serial:/dev/ttyUSB0", dict(kind="serial", rate=115200)),
    ("can:socketcan:vcan0", dict(kind="can", interface="socketcan", path="vcan0", rate=None)),
    ("can:slcan:/dev/ttyACM0@500000", dict(interface="slcan", path="/dev/ttyACM0", rate=500000)),
    ("can:udp_multicast:239.74.163.2", dict(interface="udp_multicast", path="239.74.163.2", port=0)),
    ("can:udp_multicast:239.74.163.2:43200", dict(interface="udp_multicast", path="239.74.163.2", port=43200)),
    ("can:udp_multicast:[ff15::1]:43201", dict(interface="udp_multicast", path="ff15::1", port=43201)),
    ("can:udp_multicast:ff15::1", dict(interface="udp_multicast", path="ff15::1", port=0)),
    ("udp:[::1]:14550", dict(kind="udp", path="::1", port=14550)),
    ("file:out/imu.blf", dict(kind="file", path="out/imu.blf")),
    ("px4", dict(kind="px4", path="127.0.0.1", port=4560)),
    ("px4:0.0.0.0:4561,timeout=2.5", dict(kind="px4", path="0.0.0.0", port=4561, params=(("timeout", "2.5"),))),
    ("ardupilot:9003,record=servos.csv", dict(kind="ardupilot", path="127.0.0.1", port=9003,
                                              params=(("record", "servos.csv"),))),
])
def test_parse_target(text, fields):
    spec = parse_target(text)
    for key, value in fields.items():
        assert getattr(spec, key) == value


@pytest.mark.parametrize("text", ["", "pty:x", "serial:", "serial:/dev/x@0", "can:virtual", "can::x", "udp:h:0",
                                  "tcp:h:1", "can:udp_multicast:239.1.2.3:0",
                                  "can:udp_multicast:239.1.2.3:x", "can:udp_multicast:[ff15::1]",
                                  "px4:h:x", "px4:4560,timeout=0", "px4:4560,record=", "ardupilot:70000",
                                  "ardupilot:9002,lockstep=1"])
def test_malformed_target_raises_target_error(text):
    with pytest.raises(TargetError):
        parse_target(text)


def test_link_capacity():
    assert link_capacity(parse_target("serial:/dev/x@921600"), "serial").bytes_per_s == 92160
    assert link_capacity(parse_target("pty"), "serial").bytes_per_s is None
    assert link_capacity(parse_target("pty"), "serial", TargetOptions(pace_baud=115200)).bytes_per_s == 11520
    assert link_capacity(parse_target("can:virtual:x"), "can").bits_per_s == 1e6
    assert link_capacity(parse_target("can:virtual:x@500000"), "can").bits_per_s == 5e5


def _pty():
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    os.set_blocking(slave, False)
    return master, slave


def _packets(count, size=75):
    return [bytes([i % 251]) * size for i in range(count)]


def test_full_pty_drops_whole_packets_and_resumes():
    master, slave = _pty()
    writer = FdPacketWriter(master)
    try:
        accepted = [p for p in _packets(2000) if writer.send(p)]
        assert 0 < len(accepted) < 2000
        received = b""
        while True:
            try:
                received += os.read(slave, 65536)
            except BlockingIOError:
                break
        assert writer.send(b"\xAA" * 75)      # room again: the unfinished tail goes first, then this one
        time.sleep(0.01)
        received += os.read(slave, 65536)
    finally:
        os.close(master)
        os.close(slave)
    assert received == b"".join(accepted) + b"\xAA" * 75


def test_pace_baud_delivers_no_faster_than_the_uart(monkeypatch):
    """9600 baud is 960 B/s (10 bits a byte): a 75-byte packet holds the line 78.125 ms, and the 150-byte FIFO
    lets a packet in while at most 156.25 ms of line time wait before it. On the writer's clock (driven here, so
    the count depends on no machine) the k-th packet (from 0) goes on the line at k x 78.125 ms and is accepted
    at the first offer (one a ms) no more than 156.25 ms before that: by T ms, floor((T + 156.25) / 78.125) + 1."""
    from imu_emulator.live.transport import fdwriter
    now_ns = [1_000_000_000]
    monkeypatch.setattr(fdwriter, "time", SimpleNamespace(monotonic_ns=lambda: now_ns[0], sleep=time.sleep))
    master, slave = _pty()
    writer = FdPacketWriter(master, pace_baud=9600, fifo_bytes=150)
    accepted, received = [], b""
    try:
        for ms in range(501):                   # one offer a millisecond for half a second
            now_ns[0] = 1_000_000_000 + ms * 1_000_000
            if writer.send(b"x" * 75):
                accepted.append(ms)
            received += os.read(slave, 65536) if _readable(slave) else b""
    finally:
        os.close(master)
        os.close(slave)
    # k = 0, 1, 2 fit (line + FIFO) at their first offers; then k at the first whole ms >= k x 78.125 - 156.25
    assert accepted == [0, 1, 2, 79, 157, 235, 313, 391, 469]
    assert len(accepted) == (500 + 156.25) // 78.125 + 1
    assert writer.refusals["uart-fifo-full"] == 501 - len(accepted)
    assert received == b"x" * 75 * len(accepted)


def _readable(fd) -> bool:
    import select
    return bool(select.select([fd], [], [], 0)[0])


def test_slcan_lines():
    rows = np.zeros(2, dtype=CAN_FRAME_DTYPE)
    rows[0]["can_id"], rows[0]["extended"], rows[0]["length"] = 0x1F03EB2A, True, 3
    rows[0]["data"][:3] = [0xEE, 0xC0, 0x87]
    rows[1]["can_id"], rows[1]["length"], rows[1]["fd"] = 0x123, 12, True
    assert slcan_lines(rows) == b"T1F03EB2A3EEC087\r" + b"d1239" + b"00" * 12 + b"\r"


# - catching up: several samples' packets at once (Transport.send_many, Stream.send_samples) -

def test_a_pty_takes_a_catch_up_in_one_write_and_counts_its_packets_when_left_unread():
    """The joined write reaches the reader as the packets one after the other; when the reader leaves them unread,
    they are lost as three packets (the sizes of the packets, not of the write)."""
    transport = PtyTransport(TargetOptions())
    reader = os.open(transport.pty.path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        assert transport.joins_writes
        assert transport.send_many([b"a" * 10, b"b" * 20, b"c" * 30]) == 3
        time.sleep(0.02)
        assert os.read(reader, 100) == b"a" * 10 + b"b" * 20 + b"c" * 30
        assert transport.send_many(_packets(3)) == 3
    finally:
        os.close(reader)
    transport.finish()
    assert transport.link_report()["unread_lost"] == {"packets": 3, "bytes": 225, "readers": 1}
    transport.close()


def test_a_modelled_uart_takes_a_catch_up_packet_by_packet():
    """Its FIFO takes packets while what waits on the line fits, and drops the others one by one; a joined write
    would be one packet, taken whole beyond the FIFO (or dropped whole, fitting ones too, behind a backlog)."""
    transport = PtyTransport(TargetOptions(pace_baud=9600))
    reader = os.open(transport.pty.path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        assert not transport.joins_writes
        # 4096 bytes of FIFO: 54 packets of 75 bytes fit (and the one on the line), the rest of 80 are dropped
        assert 50 <= transport.send_many(_packets(80)) < 80
    finally:
        os.close(reader)
        transport.close()


class _Link(Transport):
    """A byte stream that refuses while `full`, keeping what it took."""
    joins_writes = True

    def __init__(self):
        self.full, self.taken = False, []

    def send(self, item) -> bool:
        if not self.full:
            self.taken.append(item)
        return not self.full


def test_a_stream_sends_waiting_replies_before_a_catch_up_and_drops_it_whole_while_they_wait():
    import firmware_protocols
    stream = Stream(StreamConfig("imu0", "mavlink-highres", "pty"), 0, firmware_protocols.get("mavlink-highres"),
                    100.0)
    stream.transport = link = _Link()
    link.full = True
    stream.send_reply(b"R")                     # refused: it waits, ahead of every sample
    stream.send_samples([b"a", None, b"b"])
    assert (stream.sent, stream.dropped, stream.idle, link.taken) == (0, 2, 1, [])
    link.full = False
    stream.send_samples([b"c", b"d", None])
    assert link.taken == [b"R", b"cd"]
    assert (stream.sent, stream.dropped, stream.idle, stream.replies_delayed) == (2, 2, 2, 1)
