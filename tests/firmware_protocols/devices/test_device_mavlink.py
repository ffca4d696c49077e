"""The MAVLink device end to end: the emulator in its own process on a pty or UDP port, pymavlink and MAVSDK
(its C++ core through the `mavsdk` wheel) on the other end, as a ground station would be."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.support.stream import Emulator, read_for, write_scene
from tests.support.paths import CLIENTS
from tests.support.timing import scaled

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

mavlink2 = pytest.importorskip("pymavlink.dialects.v20.common")

KEY = bytes(range(32))


def _gcs(signing: bool = False):
    mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    mav.robust_parsing = True
    if signing:
        mav.signing.secret_key = KEY
        mav.signing.link_id = 3
        mav.signing.sign_outgoing = True
        mav.signing.allow_unsigned_callback = lambda *_: False
    return mav


def _messages(mav, data, kind=None):
    out = [m for m in (mav.parse_buffer(data) or []) if m.get_type() != "BAD_DATA"]
    return out if kind is None else [m for m in out if m.get_type() == kind]


def _open(path: str) -> int:
    """The pty opened as a driver opens it, once the stream runs (a command sent during start-up would only
    be read later)."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    assert read_for(fd, 30, stop_after=1), "the emulator sent nothing"
    return fd


def _converse(fd, mav, message, seconds=0.6):
    os.write(fd, message.pack(mav))
    return read_for(fd, seconds)


def test_heartbeat_every_second_of_samples_and_acks_that_change_the_rate(tmp_path):
    rate = 200
    scene_path = write_scene(tmp_path, rate=rate, duration=30.0)
    with Emulator(scene_path, "--format", "mavlink-highres", "--to", "pty", "--duration", "20",
                  "--option", "sysid=7", "--option", "compid=200") as emu:
        fd = _open(emu.targets[0])
        mav = _gcs()
        data = read_for(fd, 3.5)
        wrong_target = _converse(fd, mav, mav.command_long_encode(8, 200, 511, 0, 105, 20_000, 0, 0, 0, 0, 0))
        set_interval = _converse(fd, mav, mav.command_long_encode(7, 200, 511, 0, 105, 20_000, 0, 0, 0, 0, 0), 1.5)
        unsupported = _converse(fd, mav, mav.command_long_encode(7, 0, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        off = _converse(fd, mav, mav.command_long_encode(0, 0, 511, 0, 105, -1, 0, 0, 0, 0, 0), 1.2)
        request = _converse(fd, mav, mav.command_long_encode(7, 200, 512, 0, 105, 0, 0, 0, 0, 0, 0))
        bad_msgid = _converse(fd, mav, mav.command_long_encode(7, 200, 511, 0, 33, 1000, 0, 0, 0, 0, 0))
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err

    every = _messages(_gcs(), data)
    beats = [m for m in every if m.get_type() == "HEARTBEAT"]
    assert len(beats) >= 2
    for beat in beats:
        assert (beat.get_srcSystem(), beat.get_srcComponent()) == (7, 200)
        assert (beat.type, beat.autopilot) == (mavlink2.MAV_TYPE_IMU, mavlink2.MAV_AUTOPILOT_INVALID)
    # 1 Hz in sample time: exactly `rate` IMU messages between two heartbeats.
    kinds = [m.get_type() for m in every]
    at = [i for i, kind in enumerate(kinds) if kind == "HEARTBEAT"]
    assert {b - a - 1 for a, b in zip(at, at[1:])} == {rate}
    assert set(np.diff([m.get_seq() for m in every]) % 256) == {1}

    assert not _messages(_gcs(), wrong_target, "COMMAND_ACK"), "a command for another system was answered"
    acks = _messages(_gcs(), set_interval, "COMMAND_ACK")
    assert [(a.command, a.result, a.target_system, a.target_component) for a in acks] == [(511, 0, 255, 190)]
    # After the ack every HIGHRES_IMU is 20 ms after the previous one (200 Hz / 4).
    imu = _messages(_gcs(), set_interval, "HIGHRES_IMU")
    steps = np.diff([m.time_usec for m in imu])
    assert len(steps) > 20 and np.all(steps[-20:] == 20_000)
    assert [(a.command, a.result) for a in _messages(_gcs(), unsupported, "COMMAND_ACK")] == [(400, 3)]
    assert [(a.command, a.result) for a in _messages(_gcs(), off, "COMMAND_ACK")] == [(511, 0)]
    tail = _messages(_gcs(), off)
    assert [m.get_type() for m in tail[-100:]].count("HIGHRES_IMU") <= 1
    assert {m.get_type() for m in _messages(_gcs(), off)[-100:]} <= {"HEARTBEAT", "HIGHRES_IMU", "COMMAND_ACK"}
    # REQUEST_MESSAGE while the message is off: accepted, and exactly one HIGHRES_IMU follows.
    assert [(a.command, a.result) for a in _messages(_gcs(), request, "COMMAND_ACK")] == [(512, 0)]
    assert len(_messages(_gcs(), request, "HIGHRES_IMU")) == 1
    assert [(a.command, a.result) for a in _messages(_gcs(), bad_msgid, "COMMAND_ACK")] == [(511, 2)]
    assert "device: 3 commands answered, 2 error replies" in err


def test_get_message_interval_answers_message_interval_then_ack(tmp_path):
    """MAV_CMD_GET_MESSAGE_INTERVAL (510) and REQUEST_MESSAGE for MESSAGE_INTERVAL (512, param1 244): pymavlink
    decodes a MESSAGE_INTERVAL with common.xml's meanings (> 0 the interval, -1 disabled, 0 not available),
    then the COMMAND_ACK."""
    rate = 200
    scene_path = write_scene(tmp_path, rate=rate, duration=30.0)
    with Emulator(scene_path, "--format", "mavlink-highres", "--to", "pty", "--duration", "20") as emu:
        fd = _open(emu.targets[0])
        mav = _gcs()
        default = _converse(fd, mav, mav.command_long_encode(1, 1, 510, 0, 105, 0, 0, 0, 0, 0, 0))
        _converse(fd, mav, mav.command_long_encode(1, 1, 511, 0, 105, 25_000, 0, 0, 0, 0, 0))
        changed = _converse(fd, mav, mav.command_long_encode(1, 1, 510, 0, 105, 0, 0, 0, 0, 0, 0))
        heartbeat = _converse(fd, mav, mav.command_long_encode(1, 1, 512, 0, 244, 0, 0, 0, 0, 0, 0))
        other = _converse(fd, mav, mav.command_long_encode(1, 1, 510, 0, 30, 0, 0, 0, 0, 0, 0))
        _converse(fd, mav, mav.command_long_encode(1, 1, 511, 0, 105, -1, 0, 0, 0, 0, 0))
        off = _converse(fd, mav, mav.command_long_encode(1, 1, 512, 0, 244, 105, 0, 0, 0, 0, 0))
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err

    def answer(data):
        replies = [m for m in _messages(_gcs(), data) if m.get_type() in ("MESSAGE_INTERVAL", "COMMAND_ACK")]
        return [(m.get_type(), m.message_id, m.interval_us) if m.get_type() == "MESSAGE_INTERVAL"
                else (m.get_type(), m.command, m.result) for m in replies]

    assert answer(default) == [("MESSAGE_INTERVAL", 105, 1_000_000 // rate), ("COMMAND_ACK", 510, 0)]
    assert answer(changed) == [("MESSAGE_INTERVAL", 105, 25_000), ("COMMAND_ACK", 510, 0)]
    assert answer(heartbeat) == [("MESSAGE_INTERVAL", 0, 1_000_000), ("COMMAND_ACK", 512, 0)]
    assert answer(other) == [("MESSAGE_INTERVAL", 30, 0), ("COMMAND_ACK", 510, 0)]
    assert answer(off) == [("MESSAGE_INTERVAL", 105, -1), ("COMMAND_ACK", 512, 0)]


def test_signed_link_answers_only_signed_commands_and_signs_everything(tmp_path):
    scene_path = write_scene(tmp_path, rate=100, duration=30.0)
    with Emulator(scene_path, "--format", "mavlink-scaled-imu", "--to", "pty", "--duration", "20",
                  "--option", f"signing_key={KEY.hex()}") as emu:
        fd = _open(emu.targets[0])
        unsigned = _converse(fd, _gcs(), _gcs().command_long_encode(1, 1, 511, 0, 26, 50_000, 0, 0, 0, 0, 0))
        signer = _gcs(signing=True)
        signed = _converse(fd, signer, signer.command_long_encode(1, 1, 511, 0, 26, 50_000, 0, 0, 0, 0, 0), 1.5)
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err
    assert not _messages(_gcs(signing=True), unsigned, "COMMAND_ACK")
    checker = _gcs(signing=True)
    every = _messages(checker, signed)
    assert {"HEARTBEAT", "SCALED_IMU", "COMMAND_ACK"} <= {m.get_type() for m in every}
    # pymavlink (with allow_unsigned refusing) only returns frames whose signature verified
    assert all(m._signed for m in every)
    assert [(a.command, a.result) for a in every if a.get_type() == "COMMAND_ACK"] == [(511, 0)]
    steps = np.diff([m.time_boot_ms for m in every if m.get_type() == "SCALED_IMU"])
    assert np.all(steps[-10:] == 50)


def test_mavsdk_discovers_connects_receives_imu_and_sets_its_rate(tmp_path):
    pytest.importorskip("mavsdk")
    rate, new_rate, window = 200, 50, 1.5
    scene_path = write_scene(tmp_path, rate=rate, duration=60.0)
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    client = subprocess.Popen([sys.executable, str(CLIENTS / "mavsdk_client.py"),
                               str(port), str(new_rate), str(window)], stdout=subprocess.PIPE, text=True)
    try:
        assert client.stdout.readline().strip() == "listening"
        with Emulator(scene_path, "--format", "mavlink-highres", "--to", f"udp:127.0.0.1:{port}",
                      "--duration", "40") as emu:
            out, _ = client.communicate(timeout=scaled(60))
            code, err = emu.interrupt()
    finally:
        if client.poll() is None:
            client.kill()
    assert code == 0, err
    result = json.loads(out.strip().splitlines()[-1])
    assert result["discovered"] and result["connected"] and result["sysid"] == 1
    assert result["set_rate"] == "ok"
    before, after = np.array(result["before"]), np.array(result["after"])
    # Rates from the messages' own time stamps (arrival times would measure the loaded machine).
    assert set(np.diff(before[:, 0])) == {1_000_000 // rate}
    assert set(np.diff(after[-10:, 0])) == {1_000_000 // new_rate}
    # MAVSDK reports FRD axes as sent (the scene's body axes here); values survive as float32.
    assert np.all(np.isfinite(before[:, 1:]))
