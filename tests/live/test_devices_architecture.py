"""The two-way plumbing under the devices: transports' recv/fileno, the pacer answering input between
deadlines, and a configuration change taking effect at the next sample."""
import os
import socket
import threading
import time

import numpy as np
import pytest

import firmware_protocols
from firmware_protocols import Samples
from imu_emulator.live.realtime import Pacer
from imu_emulator.live.transport import TargetOptions
from imu_emulator.live.transport.pty import PtyTransport
from imu_emulator.live.transport.slcan_pty import parse_slcan_line
from imu_emulator.live.transport.udp import UdpTransport

pytestmark = pytest.mark.realtime


def test_pty_transport_returns_what_the_reader_writes():
    transport = PtyTransport(TargetOptions())
    try:
        fd = os.open(transport.pty.path, os.O_RDWR | os.O_NOCTTY)
        assert transport.recv() == b""
        os.write(fd, b"$VNRRG,01*XX\r\n")
        deadline = time.monotonic() + 2
        got = b""
        while len(got) < 14 and time.monotonic() < deadline:
            got += transport.recv()
        assert got == b"$VNRRG,01*XX\r\n"
        assert transport.fileno() == transport.pty.master
        os.close(fd)
    finally:
        transport.close()


def test_udp_transport_receives_the_peers_datagrams():
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    transport = UdpTransport("127.0.0.1", peer.getsockname()[1], TargetOptions())
    try:
        transport.send(b"x")
        data, address = peer.recvfrom(10)
        peer.sendto(b"hello", address)
        peer.sendto(b"world", address)
        time.sleep(0.05)
        assert transport.recv() == b"helloworld"
        assert transport.recv() == b""
    finally:
        transport.close()
        peer.close()


def test_slcan_transmit_lines_become_frames_and_setup_commands_do_not():
    frame = parse_slcan_line(b"T1E03EB2A11B")
    assert (frame.arbitration_id, frame.is_extended_id, bytes(frame.data)) == (0x1E03EB2A, True, b"\x1b")
    assert parse_slcan_line(b"t1230").dlc == 0
    for line in (b"O", b"S8", b"T12", b"t123G", b"t1239" + b"00" * 9, b"\xff"):
        assert parse_slcan_line(line) is None


def test_pacer_hands_input_over_while_waiting_and_still_meets_the_deadline():
    r, w = os.pipe()
    seen = []

    def on_ready(fds):
        seen.append((time.monotonic_ns(), os.read(r, 100)))

    pacer = Pacer(fifo=False)
    start = time.monotonic_ns()
    deadline = start + 200_000_000
    threading.Timer(0.05, os.write, (w, b"cmd")).start()
    woke = pacer.wait_until(deadline, [r], on_ready)
    os.close(r)
    os.close(w)
    assert woke >= deadline
    assert [data for _, data in seen] == [b"cmd"]
    # The input was handled long before the deadline, not held until it (generous bound: loaded machine).
    assert seen[0][0] - start < 150_000_000


def _samples(n=10, rate=100.0):
    t = (np.arange(n) * 1e9 / rate).astype(np.int64)
    return Samples(t, np.tile([0.1, -0.2, 9.8], (n, 1)), np.tile([0.01, 0.02, 0.03], (n, 1)))


def test_mavlink_rate_change_takes_effect_at_the_next_sample():
    from pymavlink.dialects.v20 import common as mavlink2
    device = firmware_protocols.create_device("mavlink-highres", 100.0)
    samples = _samples(10)
    mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    first = mav.parse_buffer(device.output(samples, 0))
    assert [m.get_type() for m in first] == ["HEARTBEAT", "HIGHRES_IMU"]
    # SET_MESSAGE_INTERVAL HIGHRES_IMU every 30 ms = every 3rd sample at 100 Hz
    command = mav.command_long_encode(1, 1, 511, 0, 105, 30_000, 0, 0, 0, 0, 0).pack(mav)
    replies = device.receive(command)
    ack = mav.parse_buffer(b"".join(replies))
    assert [(m.get_type(), m.command, m.result) for m in ack] == [("COMMAND_ACK", 511, 0)]
    sent = [bool(mav.parse_buffer(device.output(samples, i))) for i in range(1, 10)]
    assert sent == [True, False, False, True, False, False, True, False, False]


def test_device_off_streams_blindly(tmp_path):
    from tests.support.stream import Emulator, mavlink_parse, open_pty_reader, read_for, write_scene
    scene_path = write_scene(tmp_path, rate=200, duration=5.0)
    with Emulator(scene_path, "--format", "mavlink-highres", "--to", "pty", "--duration", "3",
                  "--device", "off") as emu:
        fd = os.open(emu.targets[0], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        os.write(fd, b"\x00" * 100)           # read and ignored: the writer never blocks
        data = read_for(fd, 1.5)
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err
    every, bad = mavlink_parse(data, types=None)
    assert every and not bad
    assert {m.get_type() for m in every} == {"HIGHRES_IMU"}
    assert "input ignored (no device): 100" in err


def test_stream_table_device_key():
    from imu_emulator.errors import SceneError
    from imu_emulator.live.config import streams_from_tables
    tables = [{"format": "mavlink-highres", "to": "pty", "device": False}, {"format": "j1939", "to": "file:x.log"}]
    configs = streams_from_tables(tables, ("imu0",))
    assert [c.device for c in configs] == [False, True]
    with pytest.raises(SceneError, match=r"stream\[0\]\.device: expected true or false"):
        streams_from_tables([{"format": "mavlink-highres", "to": "pty", "device": "yes"}], ("imu0",))


def test_single_row_equals_samples_slice():
    from firmware_protocols.devices.base import single
    n = 5
    samples = Samples(np.arange(n), np.random.default_rng(0).normal(size=(n, 3)), np.zeros((n, 3)),
                      temperature_c=np.arange(n) * 1.5, quat=np.tile([1.0, 0, 0, 0], (n, 1)))
    for i in range(n):
        one, ref = single(samples, i), samples.slice(i, i + 1)
        for name in ("time_ns", "accel", "gyro", "mag", "quat", "temperature_c", "position_llh"):
            a, b = getattr(one, name), getattr(ref, name)
            assert (a is None and b is None) or (np.array_equal(a, b) and a.flags.c_contiguous and a.shape == b.shape)
