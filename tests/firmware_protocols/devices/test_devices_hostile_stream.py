"""Issue 23's packets end to end: the emulator in its own process on a pty or a UDP port, the hostile packets
sent as a driver (or an attacker) would, then the stream still streams and still answers; exit status 0."""
import math
import os
import re
import select
import socket
import time

import pytest

from tests.support.stream import Emulator, read_for, write_scene

mavlink2 = pytest.importorskip("pymavlink.dialects.v20.common")
from tests.support.devices import command_long, gcs  # noqa: E402

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]


def _kinds(data):
    return [m for m in gcs().parse_buffer(data) or [] if m.get_type() != "BAD_DATA"]


def _acks(data):
    return [(m.command, m.result) for m in _kinds(data) if m.get_type() == "COMMAND_ACK"]


def _write_all(fd, data: bytes) -> None:
    """All of data into the non-blocking pty, waiting for room (a flood fills the pty's buffer)."""
    while data:
        select.select([], [fd], [], 1.0)
        try:
            data = data[os.write(fd, data):]
        except BlockingIOError:
            read_for(fd, 0.01)      # let the emulator's output through too


HOSTILE_511 = [(105, math.inf), (math.inf, 1000), (-math.inf, 0), (105, -5), (105, 1e30), (105, math.nan)]


def test_mavlink_over_a_pty_denies_hostile_intervals_survives_a_flood_and_keeps_streaming(tmp_path):
    scene_path = write_scene(tmp_path, rate=100, duration=60.0)
    with Emulator(scene_path, "--format", "mavlink-highres", "--to", "pty", "--duration", "30") as emu:
        fd = os.open(emu.targets[0], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        assert read_for(fd, 30, stop_after=1)
        hostile = b""
        for msgid, interval in HOSTILE_511:
            _write_all(fd, command_long(msgid, interval))
            hostile += read_for(fd, 0.3)
        for _ in range(32):                                   # 2 MB took 411 s on 168021a; 256 KiB here
            _write_all(fd, b"\xfd" * 8192)
            read_for(fd, 0.01)
        answered = b""
        for attempt in range(20):                             # a driver resends until it hears an answer
            _write_all(fd, command_long(105, 20_000))
            answered += read_for(fd, 0.3)
            if (511, 0) in _acks(answered):
                break
        after = read_for(fd, 1.0)
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err
    assert _acks(hostile) == [(511, mavlink2.MAV_RESULT_DENIED)] * len(HOSTILE_511)
    assert (511, 0) in _acks(answered)
    assert sum(m.get_type() == "HIGHRES_IMU" for m in _kinds(after)) >= 20   # 50 Hz after the command
    assert "Traceback" not in err


def test_mavlink_over_udp_answers_the_commands_after_a_garbage_datagram(tmp_path):
    scene_path = write_scene(tmp_path, rate=100, duration=60.0)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as gcs:
        gcs.bind(("127.0.0.1", 0))
        gcs.settimeout(0.2)
        with Emulator(scene_path, "--format", "mavlink-highres", "--to", f"udp:127.0.0.1:{gcs.getsockname()[1]}",
                      "--duration", "30") as emu:
            _, address = gcs.recvfrom(65536)

            def converse(datagram, seconds=0.5):
                gcs.sendto(datagram, address)
                got, end = b"", time.monotonic() + seconds
                while time.monotonic() < end:
                    try:
                        got += gcs.recv(65536)
                    except socket.timeout:
                        pass
                return got

            garbage = converse(bytes([0xFD, 0xFF, 0, 0, 0, 255, 190, 76, 0, 0]) + b"\x55" * 20)
            valid = [converse(command_long(105, interval)) for interval in (20_000, 30_000, 40_000)]
            hostile = converse(command_long(math.inf, 1000))
            code, err = emu.interrupt()
    assert code == 0, err
    assert not _acks(garbage)
    assert [_acks(reply) for reply in valid] == [[(511, 0)]] * 3     # none answered on 168021a
    assert _acks(hostile) == [(511, mavlink2.MAV_RESULT_DENIED)]
    assert "Traceback" not in err


def test_mip_over_a_pty_nacks_what_cannot_be_done_and_keeps_streaming(tmp_path):
    from firmware_protocols.devices.microstrain import packet
    from firmware_protocols.wire_formats.microstrain import MipDecoder
    scene_path = write_scene(tmp_path, rate=100, duration=60.0)
    with Emulator(scene_path, "--format", "microstrain-mip", "--to", "pty", "--duration", "30") as emu:
        fd = os.open(emu.targets[0], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        assert read_for(fd, 30, stop_after=1)
        _write_all(fd, packet(0x01, [(0x01, b"")] * 127))
        _write_all(fd, packet(0x01, [(0x03, b"")] * 3))
        _write_all(fd, packet(0x0C, [(0x0F, bytes([1, 0x80, 2, 0x04, 0, 1, 0x04, 0, 2]))]))
        read_for(fd, 0.5)
        after = read_for(fd, 1.0)
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err
    assert len(MipDecoder().feed(after)) >= 50          # still 100 Hz of sensor packets
    assert "Traceback" not in err
    assert "device: 64 commands answered, 67 error replies" in err     # 62 + 2 + 0 / 65 + 1 + 1


def test_vectornav_over_a_pty_answers_a_dollar_flood_once_and_keeps_answering(tmp_path):
    scene_path = write_scene(tmp_path, rate=100, duration=60.0)
    with Emulator(scene_path, "--format", "vectornav-binary", "--to", "pty", "--duration", "30") as emu:
        fd = os.open(emu.targets[0], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        assert read_for(fd, 30, stop_after=1)
        for _ in range(16):
            _write_all(fd, b"$VNRRG," * 1024)
            read_for(fd, 0.01)
        _write_all(fd, b"\r\n$VNRRG,01*XX\r\n")
        got = read_for(fd, 1.5)
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err
    assert got.count(b"$VNERR") <= 2 and b"$VNRRG,01,VN-100T-CR" in got
    assert "Traceback" not in err


def test_replies_on_a_full_link_wait_for_room_and_all_arrive(tmp_path):
    """A UART at 9600 baud carries a sixth of 100 Hz HIGHRES_IMU: samples are dropped for lack of room (counted).
    Every COMMAND_ACK still arrives, ahead of the samples (on 168021a the refused ones were dropped)."""
    scene_path = write_scene(tmp_path, rate=100, duration=60.0)
    with Emulator(scene_path, "--format", "mavlink-highres", "--to", "pty", "--pace-baud", "9600",
                  "--allow-overload", "--duration", "30") as emu:
        fd = os.open(emu.targets[0], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        assert read_for(fd, 30, stop_after=1)
        read_for(fd, 1.0)
        answers = b""
        for k in range(10):
            _write_all(fd, command_long(105, 10_000 * (1 + k % 2)))
            answers += read_for(fd, 0.3)
        answers += read_for(fd, 1.0)
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err
    assert len(_acks(answers)) == 10
    waited, replies_dropped = map(int, re.search(r"replies sent \((\d+) after waiting for room\), (\d+) dropped",
                                                 err).groups())
    assert waited >= 1 and replies_dropped == 0
    assert int(re.search(r"sent \d+(?: \(\d+ of them never read: lost\))?, dropped (\d+)", err).group(1)) > 0     # samples were: the link is full
