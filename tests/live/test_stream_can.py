"""CAN targets on a host without SocketCAN: a virtual SLCAN adapter on a pty, python-can udp_multicast,
and capture logs. Readers are python-can in this (separate) process; dronecan decodes the transfers."""
import calendar
import json
import socket
import subprocess

import can
import numpy as np
import pytest

from tests.support.stream import Emulator, dronecan_rawimu, reference, run_emulator, write_scene

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]


def _check_rawimu(frames, scene_path, imu=0, minimum=100, dropped=0):
    """The transfers decode to the scene's samples, in order, none twice. `dropped`: whole transfers the emulator
    counted as dropped (the pty full while the reader was starved); at most that many may be missing between
    the first and the last received, each having used its transfer ID as it would on a bus."""
    scene, _, accel, gyro = reference(scene_path, imu)
    transfers = dronecan_rawimu(frames)
    assert len(transfers) >= minimum
    k = np.array([round(t.payload.timestamp.usec * 1e-6 * scene.rate_hz) for t in transfers])
    steps = np.diff(k)
    assert steps.min() >= 1 and int((steps - 1).sum()) <= dropped, f"samples missing beyond the {dropped} dropped"
    assert set((np.diff([t.transfer_id for t in transfers]) - steps) % 32) == {0}
    np.testing.assert_array_equal([list(t.payload.rate_gyro_latest) for t in transfers], gyro[k].astype(np.float16))
    np.testing.assert_array_equal([list(t.payload.accelerometer_latest) for t in transfers], accel[k].astype(np.float16))


def _receive(bus, seconds_without_frames=1.0, limit=5000):
    """Frames until the stream falls silent; the first may take a while (the emulator's start-up)."""
    frames = []
    while len(frames) < limit:
        try:
            message = bus.recv(timeout=seconds_without_frames if frames else 20.0)
        except can.CanOperationError:   # the emulator finished and closed its pty
            break
        if message is None:
            break
        frames.append((message.arbitration_id, bytes(message.data)))
    return frames


def test_slcan_pty_read_by_python_can_slcan(tmp_path):
    scene_path = write_scene(tmp_path, rate=200, duration=5.0)
    stats = tmp_path / "stats.json"
    with Emulator(scene_path, "--format", "dronecan-rawimu", "--to", "can:slcan:pty", "--count", "300",
                  "--stats-json", stats) as emu:
        bus = can.Bus(interface="slcan", channel=emu.targets[0], sleep_after_open=0)
        frames = _receive(bus)
        code, err = emu.wait()
        try:
            bus.shutdown()
        except can.CanOperationError:   # python-can writes a close command to a pty already gone
            pass
    assert code == 0, err
    summary = json.loads(stats.read_text())
    stream = summary["streams"][0]
    # Each of the 300 samples is sent or counted as dropped (before the reader opened the pty, or while it was
    # too starved to keep it from filling, as on a loaded host); what was sent is read, or counted as left unread.
    assert stream["sent"] + summary["dropped"] == 300
    unread = stream["link"].get("unread_lost", {}).get("packets", 0)
    assert len(dronecan_rawimu(frames)) == stream["sent"] - unread >= 100
    _check_rawimu(frames, scene_path, dropped=summary["dropped"])


def _multicast_route_or_skip():
    route = subprocess.run(["ip", "route", "get", "239.74.163.2"], capture_output=True, text=True)
    if route.returncode == 0 and " dev lo" in route.stdout:
        return
    for command in (["ip", "link", "set", "lo", "multicast", "on"], ["ip", "route", "add", "239.0.0.0/8", "dev", "lo"]):
        done = subprocess.run(command, capture_output=True, text=True)
        if done.returncode != 0 and "File exists" not in done.stderr:
            pytest.skip(f"no multicast route on lo and cannot add one ({' '.join(command)}: {done.stderr.strip()})")


def free_udp_port() -> int:
    """A UDP port nobody holds now. udp_multicast's fixed default port (43113) let two test runs on one host
    hear each other's frames: a socket bound to the port receives every group joined on it."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("", 0))
        return probe.getsockname()[1]


def test_udp_multicast_to_reader_in_another_process(tmp_path):
    _multicast_route_or_skip()
    group, port = "239.74.163.2", free_udp_port()
    bus = can.Bus(interface="udp_multicast", channel=group, port=port)
    try:
        scene_path = write_scene(tmp_path, rate=200, duration=5.0)
        with Emulator(scene_path, "--format", "dronecan-rawimu", "--to", f"can:udp_multicast:{group}:{port}",
                      "--count", "200") as emu:
            frames = _receive(bus, limit=1400)
            code, err = emu.wait()
    finally:
        bus.shutdown()
    assert code == 0, err
    _check_rawimu(frames, scene_path, minimum=190)


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_can_capture_log_read_back_by_python_can(tmp_path, suffix):
    scene_path = write_scene(tmp_path, rate=200, duration=1.0)
    log = tmp_path / f"capture{suffix}"
    result = run_emulator(scene_path, "--format", "dronecan-rawimu", "--to", f"file:{log}", "--speed", "0", "--quiet")
    assert result.returncode == 0, result.stderr
    messages = list(can.LogReader(str(log)))
    assert len(messages) == 200 * 7
    # Log time stamps are the samples' times on the run's time base: UTC from --start-time (default
    # 2024-01-01T00:00:00Z, README conventions) plus the scene time, not the wall clock.
    # A candump log keeps them absolute; python-can's BLF round trip keeps their spacing (its reader measures from
    # the file's start record), so the first stamp is checked in the log and the spacing in both.
    if suffix == ".log":
        assert messages[0].timestamp == pytest.approx(calendar.timegm((2024, 1, 1, 0, 0, 0)), abs=1e-6)
    assert messages[-1].timestamp - messages[0].timestamp == pytest.approx(0.995, abs=1e-3)
    _check_rawimu([(m.arbitration_id, bytes(m.data)) for m in messages], scene_path, minimum=200)
