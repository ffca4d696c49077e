"""End to end over a pty: the emulator in its own process, pymavlink decoding what a firmware would read."""
import json
import os
import time

import numpy as np
import pytest

from tests.support.stream import (Emulator, check_highres_against_scene, mavlink_parse, open_pty_reader, read_for,
                                 read_until_closed, reference, write_scene)

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]


def _seq_steps(messages):
    return np.diff([m.get_seq() for m in messages]) % 256


def test_highres_over_pty_equals_scene_with_continuous_sequence(tmp_path):
    scene_path = write_scene(tmp_path, rate=200, duration=5.0)
    scene, _, accel, gyro = reference(scene_path)
    with Emulator(scene_path, "--format", "mavlink-highres", "--to", "pty", "--duration", "4") as emu:
        fd = open_pty_reader(emu.targets[0])
        data = read_for(fd, 1.5)
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err
    assert "done:" in err and "Traceback" not in err
    messages, bad = mavlink_parse(data)
    assert not bad
    assert len(messages) > 150
    # One sender, one sequence: the device's HEARTBEATs take their numbers from the same counter.
    assert set(_seq_steps(mavlink_parse(data, types=None)[0])) == {1}
    k = check_highres_against_scene(messages, scene, accel, gyro)
    assert set(np.diff(k)) == {1}


def test_reader_that_pauses_costs_whole_packets_only_and_streaming_resumes(tmp_path):
    scene_path = write_scene(tmp_path, rate=1000, duration=10.0)
    scene, _, accel, gyro = reference(scene_path)
    stats = tmp_path / "stats.json"
    with Emulator(scene_path, "--format", "mavlink-highres", "--to", "pty", "--duration", "8",
                  "--stats-json", stats) as emu:
        fd = open_pty_reader(emu.targets[0])
        before = read_for(fd, 0.3)
        time.sleep(1.0)          # the pty buffer (a few KB) fills within ~0.3 s at 75 kB/s
        after = read_for(fd, 1.0)
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err
    summary = json.loads(stats.read_text())
    assert summary["dropped"] > 0
    first, bad_first = mavlink_parse(before)
    messages, bad = mavlink_parse(before + after)
    assert not bad_first and not bad, "a partial packet reached the reader"
    resumed = [m for m in messages if m.time_usec > first[-1].time_usec + 1_000_000]
    assert len(resumed) > 300, "packets did not arrive again after the reader resumed"
    check_highres_against_scene(messages, scene, accel, gyro)
    assert max(_seq_steps(messages)) > 1   # the gap: whole packets dropped while nobody read


def test_packets_a_slow_reader_leaves_unread_when_it_closes_are_counted(tmp_path):
    """Issue 23 item 9 (xsens-go lost 166 of 553 packets counted as sent): a reader that reads slowly, then closes
    with the pty full, and a second reader that reads to the end. Every packet counted as sent either arrived
    whole or is counted lost: sent = received + lost, exactly."""
    scene_path = write_scene(tmp_path, rate=200, duration=10.0)
    stats = tmp_path / "stats.json"
    with Emulator(scene_path, "--format", "mavlink-highres", "--device", "off", "--to", "pty", "--duration", "4",
                  "--stats-json", stats) as emu:
        first = open_pty_reader(emu.targets[0])
        data = read_for(first, 0.2)
        time.sleep(0.6)                 # 200 Hz x 61 B: the pty's ~20 kB would fill in ~1.7 s; ~120 packets wait
        os.close(first)                 # what it has not read stays behind
        time.sleep(0.3)
        second = open_pty_reader(emu.targets[0])
        later = read_until_closed(second)
        code, err = emu.wait()
    assert code == 0, err
    stream = json.loads(stats.read_text())["streams"][0]
    received = len(mavlink_parse(data)[0]) + len(mavlink_parse(later)[0])
    lost = stream["link"]["unread_lost"]["packets"]
    assert lost > 20 and stream["sent"] == received + lost
    assert f"({lost} of them never read: lost)" in err


def test_pacing_median_lateness_and_arrival_rate(tmp_path):
    scene_path = write_scene(tmp_path, rate=200, duration=5.0)
    stats = tmp_path / "stats.json"
    with Emulator(scene_path, "--format", "mavlink-highres", "--to", "pty", "--duration", "2.5", "--quiet",
                  "--stats-json", stats) as emu:
        fd = open_pty_reader(emu.targets[0])
        arrivals = []
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            chunk = read_for(fd, 0.05, stop_after=1)
            if chunk:
                arrivals.append((time.monotonic(), len(chunk)))
        os.close(fd)
        code, err = emu.wait()
    assert code == 0, err
    summary = json.loads(stats.read_text())
    assert summary["lateness"]["p50_us"] < 2000
    assert summary["lateness"]["missed_ratio"] < 0.05
    assert abs(summary["achieved_hz"] - 200) < 10
    gaps = np.diff([t for t, _ in arrivals])
    assert 0.004 < np.median(gaps) < 0.006


def test_scene_stream_tables_drive_two_imus_to_two_targets(tmp_path):
    import can
    from tests.support.stream import dronecan_rawimu
    link = tmp_path / "imu0"
    log = tmp_path / "imu1.log"
    extra = f'''
[[stream]]
imu = "imu0"
format = "mavlink-highres"
to = "pty"
link = "{link}"

[[stream]]
imu = "imu1"
format = "dronecan-rawimu"
to = "file:{log}"
options = {{ node_id = 7 }}
'''
    scene_path = write_scene(tmp_path, rate=200, duration=5.0, extra=extra)
    scene, _, accel0, gyro0 = reference(scene_path, imu=0)
    _, _, accel1, gyro1 = reference(scene_path, imu=1)
    with Emulator(scene_path, "--duration", "2", streams=2) as emu:
        assert os.path.realpath(link) == emu.targets[0]
        fd = open_pty_reader(str(link))
        data = read_for(fd, 1.0)
        os.close(fd)
        code, err = emu.wait()
    assert code == 0, err
    assert not os.path.lexists(link), "the symlink outlives the stream"
    messages, bad = mavlink_parse(data)
    assert len(messages) > 100 and not bad
    check_highres_against_scene(messages, scene, accel0, gyro0)
    frames = [(m.arbitration_id, bytes(m.data)) for m in can.LogReader(str(log))]
    assert all(can_id & 0x7F == 7 for can_id, _ in frames)
    transfers = dronecan_rawimu(frames)
    assert len(transfers) == 400
    k = np.array([round(t.payload.timestamp.usec * 1e-6 * scene.rate_hz) for t in transfers])
    np.testing.assert_array_equal(k, np.arange(400))
    got_gyro = np.array([list(t.payload.rate_gyro_latest) for t in transfers])
    got_acc = np.array([list(t.payload.accelerometer_latest) for t in transfers])
    np.testing.assert_array_equal(got_gyro, gyro1[k].astype(np.float16))
    np.testing.assert_array_equal(got_acc, accel1[k].astype(np.float16))


def test_serial_target_through_pyserial(tmp_path):
    import tty
    scene_path = write_scene(tmp_path, rate=200, duration=5.0)
    scene, _, accel, gyro = reference(scene_path)
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    try:
        with Emulator(scene_path, "--format", "mavlink-highres", "--to", f"serial:{path}@921600", "--count", "150") as emu:
            assert emu.targets[0] == path
            data = read_for(master, 1.2)
            code, err = emu.wait()
    finally:
        os.close(master)
        os.close(slave)
    assert code == 0, err
    messages, bad = mavlink_parse(data)
    assert not bad and len(messages) >= 140
    check_highres_against_scene(messages, scene, accel, gyro)


def test_udp_one_datagram_per_sample(tmp_path):
    import socket
    scene_path = write_scene(tmp_path, rate=200, duration=5.0)
    scene, _, accel, gyro = reference(scene_path)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(5)
    port = sock.getsockname()[1]
    with Emulator(scene_path, "--format", "mavlink-highres", "--to", f"udp:127.0.0.1:{port}", "--count", "50") as emu:
        datagrams = [sock.recv(4096) for _ in range(50)]
        code, err = emu.wait()
    sock.close()
    assert code == 0, err
    assert all(len(mavlink_parse(d)[0]) == 1 for d in datagrams)
    messages, _ = mavlink_parse(b"".join(datagrams))
    np.testing.assert_array_equal(check_highres_against_scene(messages, scene, accel, gyro), np.arange(50))


@pytest.mark.parametrize("start", [[], ["--start-time", "2026-11-27T12:00:00Z"], ["--start-time", "now"],
                                   ["--epoch-time"]])
def test_loop_keeps_time_increasing_on_the_declared_base(tmp_path, start):
    """HIGHRES_IMU's time_usec counts since the run's start (mavlink.py's declared base) whatever --start-time
    says (that moves the UTC fields only); the deprecated --epoch-time still runs, as --start-time now, and says so
    in one line."""
    scene_path = write_scene(tmp_path, rate=200, duration=0.5)
    scene, _, accel, gyro = reference(scene_path)
    out = tmp_path / "out.bin"
    args = [scene_path, "--format", "mavlink-highres", "--to", f"file:{out}", "--loop", "--count", "250",
            "--speed", "0", "--quiet"] + start
    from tests.support.stream import run_emulator
    result = run_emulator(*args)
    assert result.returncode == 0, result.stderr
    deprecation = [line for line in result.stderr.splitlines() if "deprecated" in line]
    assert deprecation == (["warning: --epoch-time is deprecated: use --start-time now"] if "--epoch-time" in start
                           else [])
    messages, bad = mavlink_parse(out.read_bytes())
    assert len(messages) == 250 and not bad
    times = np.array([m.time_usec for m in messages])
    assert set(np.diff(times)) == {5000}   # seamless across the two loop boundaries
    assert times[0] == 0
    k = np.arange(250) % 100
    np.testing.assert_array_equal(check_highres_against_scene(messages, scene, accel, gyro, k), k)
