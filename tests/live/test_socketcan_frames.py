"""The SocketCAN fast path: frames packed as python-can packs them, and sent with one system call.

The packing oracle is python-can's own `build_can_frame` (what the frames went through before). The sender is
checked on a Unix datagram socket pair, which keeps message boundaries as a CAN socket does and exists on a
host without SocketCAN; the UML tests (test_socketcan_uml.py) check the same path on a real vcan0.
"""
from __future__ import annotations

import errno
import socket

import can
import numpy as np
import pytest
from can.interfaces.socketcan.socketcan import build_can_frame

from firmware_protocols.base import empty_frames
from imu_emulator.live.transport.frames import to_messages
from imu_emulator.live.transport.socketcan_frames import CAN_MTU, CANFD_MTU, FrameSender, pack


def _random_rows(rng, count: int, fd: bool) -> np.ndarray:
    rows = empty_frames(count, fd=fd)
    rows["extended"] = rng.random(count) < 0.5
    rows["can_id"] = np.where(rows["extended"], rng.integers(0, 1 << 29, count), rng.integers(0, 1 << 11, count))
    rows["fd"] = fd
    rows["length"] = rng.integers(0, 65 if fd else 9, count)
    rows["data"] = rng.integers(0, 256, rows["data"].shape)   # bytes past `length` must not leak into a frame
    return rows


@pytest.mark.parametrize("fd, brs", [(False, False), (True, False), (True, True)])
def test_pack_matches_python_can(fd, brs):
    rng = np.random.default_rng(7)
    rows = _random_rows(rng, 200, fd)
    packed, size = pack(rows, bitrate_switch=brs)
    assert size == (CANFD_MTU if fd else CAN_MTU)
    expected = b"".join(build_can_frame(m) for m in to_messages(rows, bitrate_switch=brs))
    assert packed == expected


def _pair():
    a, b = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
    return a, b


def test_sender_sends_each_frame_as_one_datagram_in_order():
    a, b = _pair()
    with a, b:
        rows = _random_rows(np.random.default_rng(1), 7, fd=False)
        packed, size = pack(rows)
        assert FrameSender(a).send(packed, size) is None
        got = [b.recv(100) for _ in range(7)]
        assert got == [packed[i * size:(i + 1) * size] for i in range(7)]
        b.setblocking(False)
        with pytest.raises(BlockingIOError):
            b.recv(100)


def test_sender_reports_a_full_socket_and_sends_nothing_after_the_refused_frame():
    a, b = _pair()
    with a, b:
        sender = FrameSender(a)
        rows = _random_rows(np.random.default_rng(2), 7, fd=False)
        packed, size = pack(rows)
        sent = 0
        while (code := sender.send(packed, size)) is None:   # never blocks: fills, then refuses
            sent += 1
            assert sent < 100_000
        assert code == errno.EAGAIN
        b.setblocking(False)
        received = 0
        while True:
            try:
                b.recv(100)
            except BlockingIOError:
                break
            received += 1
        # every whole call arrived; of the refused call, only a prefix of its frames
        assert sent * 7 <= received < (sent + 1) * 7


def test_sender_without_sendmmsg_behaves_the_same(monkeypatch):
    a, b = _pair()
    with a, b:
        sender = FrameSender(a)
        monkeypatch.setattr(sender, "_sendmmsg", None)
        rows = _random_rows(np.random.default_rng(3), 5, fd=True)
        packed, size = pack(rows, bitrate_switch=True)
        assert sender.send(packed, size) is None
        assert [b.recv(200) for _ in range(5)] == [packed[i * size:(i + 1) * size] for i in range(5)]


def test_message_roundtrip_through_python_can_parser():
    """What the kernel would hand a reader parses back (python-can's receive-side parser) to the rows."""
    from can.interfaces.socketcan.socketcan import dissect_can_frame
    rows = _random_rows(np.random.default_rng(4), 50, fd=True)
    packed, size = pack(rows)
    for i, row in enumerate(rows):
        can_id, length, flags, data = dissect_can_frame(packed[i * size:(i + 1) * size])
        assert can_id & 0x1FFFFFFF == row["can_id"]
        assert bool(can_id & 0x80000000) == bool(row["extended"])
        assert data[: row["length"]] == bytes(row["data"][: row["length"]])
        assert can.util.len2dlc(length) == can.util.len2dlc(int(row["length"]))
