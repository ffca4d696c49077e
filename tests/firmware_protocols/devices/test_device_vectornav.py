"""The VectorNav device end to end: the emulator in its own process on a pty; this process replays the drivers'
start-up sequences byte for byte, as ArduPilot's AP_ExternalAHRS_VectorNav and PX4's vnproglib-based driver
send them (../shared/specs/devices.md), and parses what follows the way those drivers do: by exact binary
header, CRC-16/XMODEM (here Python's own binascii.crc_hqx) and the drivers' packed structs."""
import binascii
import os
import random
import re
import struct
import time
from functools import reduce

import numpy as np
import pytest

from tests.support.stream import Emulator, read_for, reference, wire_attitude, write_scene

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

_LINE = re.compile(rb"\$VN[A-Z]{3}[^$\r\n]*\*[0-9A-F]{2,4}\r\n")


def xor(body: bytes) -> int:
    return reduce(lambda a, b: a ^ b, body, 0)


def command(body: str, kind: str = "xor") -> bytes:
    """What nmea_printf (ArduPilot) and vnproglib's finalizeCommand put on the wire."""
    raw = body.encode()
    if kind == "crc":
        return b"$" + raw + b"*%04X\r\n" % binascii.crc_hqx(raw, 0)
    return b"$" + raw + b"*%02X\r\n" % xor(raw)


class Driver:
    """A driver's view of the pty: send a command, resend every 500 ms (as ArduPilot does) until a reply
    line whose command name and first argument match arrives; keep every byte read."""

    def __init__(self, path: str):
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self.data = bytearray()
        assert read_for(self.fd, 30, stop_after=1), "the emulator sent nothing"

    def transact(self, sent: bytes, timeout: float = 5.0) -> bytes:
        head = sent[1:].split(b"*")[0].split(b",")[:2]
        start = len(self.data)
        end = time.monotonic() + timeout
        next_send = 0.0
        while time.monotonic() < end:
            if time.monotonic() >= next_send:
                os.write(self.fd, sent)
                next_send = time.monotonic() + 0.5
            self.data += read_for(self.fd, 0.05)
            for match in _LINE.finditer(bytes(self.data[start:])):
                line = match.group(0)
                terms = line[1:].split(b"*")[0].split(b",")
                if terms[:len(head)] == head or terms[0] == b"VNERR":
                    self.reply_end = start + match.end()
                    return line
        raise AssertionError(f"no reply to {sent!r}")

    def replay(self, exchange, then_read: float) -> bytes:
        """Each (command body, expected reply body) in turn, as the driver sends it; then what follows the
        last reply for `then_read` seconds."""
        for sent, expected in exchange:
            assert self.transact(command(sent)) == reply(expected), sent
        return self.read(then_read)[self.reply_end:]

    def send_all(self, data: bytes) -> None:
        """Write everything, reading meanwhile (a pty's buffer holds a few KB; a driver waits for room)."""
        view = memoryview(data)
        while view:
            try:
                view = view[os.write(self.fd, view[:1024]):]
            except BlockingIOError:
                self.data += read_for(self.fd, 0.01)

    def read(self, seconds: float) -> bytes:
        self.data += read_for(self.fd, seconds)
        return bytes(self.data)

    def close(self):
        os.close(self.fd)


def reply(body: str, kind: str = "xor") -> bytes:
    return command(body, kind)


def packets(data: bytes, layouts: dict) -> tuple[dict, int]:
    """Split a byte stream into packets of the given {header: total length} by exact header and CRC, as
    ArduPilot's check_uart does; returns {header: [packets]} and the count of bytes that fitted none."""
    found = {h: [] for h in layouts}
    pos, stray = 0, 0
    while pos < len(data):
        for header, size in layouts.items():
            packet = data[pos:pos + size]
            if packet.startswith(b"\xfa" + header) and len(packet) == size and binascii.crc_hqx(packet[1:], 0) == 0:
                found[header].append(packet)
                pos += size
                break
        else:
            stray += 1
            pos += 1
    return found, stray


def echoed(*bodies) -> list:
    """Commands whose reply is their echo."""
    return [(body, body) for body in bodies]


def ardupilot_start(model: str) -> list:
    """AP_ExternalAHRS_VectorNav::initialize() up to the model read: async off, ASCII off on both ports."""
    return echoed("VNASY,0", "VNWRG,06,0,1", "VNWRG,06,0,2") + [("VNRRG,01", f"VNRRG,01,{model}")]


ARDUPILOT_IMU = bytes.fromhex("012107")        # TimeStartup, AngularRate, Accel, Imu, MagPres: 82 bytes
ARDUPILOT_AHRS = bytes.fromhex("1101000601")   # TimeStartup; YawPitchRoll, Quaternion, YprU: 56 bytes


def healthy_throughout(imu_ns, ekf_ns, gnss_ns=None) -> bool:
    """ArduPilot's AP_ExternalAHRS_VectorNav::healthy() (ArduPilot master, the run_command() version of
    AP_ExternalAHRS_VectorNav.cpp): `now - last_pkt1_ms < 40 && now - last_pkt2_ms < 500` and, for an INS,
    `now - last_pkt3_ms < 1000`. It holds at every instant after the first packets exactly when no two successive
    packets of a kind are that far apart; judged here on the packets' own TimeStartup (sensor time), since wall
    time on a loaded test machine says nothing about the emulator."""
    limits = [(imu_ns, 40e6), (ekf_ns, 500e6)] + ([(gnss_ns, 1000e6)] if gnss_ns is not None else [])
    return all(len(t) > 1 and np.max(np.diff(np.sort(t))) < limit for t, limit in limits)


def scene_attitude(scene_path, k):
    """The scene's attitude at samples k, the upright part's FRD axes -> NED (scipy Rotation), as the wire must
    carry it."""
    from imu_emulator.runtime.simulation import Simulation
    from imu_emulator.scene.load import load_scene
    scene = load_scene(scene_path)
    block = Simulation(scene).block(0, int(np.max(k)) + 1)
    return wire_attitude(scene, block.quat[0][k])


def test_ardupilot_vn100_start_up_sequence_and_the_packets_it_then_parses(tmp_path):
    """No option at all: a VN-100's divisors divide its 800 Hz IMU rate, as ArduPilot assumes."""
    rate = 400
    scene_path = write_scene(tmp_path, rate=rate, duration=60.0)
    scene, _, accel, gyro = reference(scene_path)
    with Emulator(scene_path, "--format", "vectornav-binary", "--to", "pty", "--duration", "40") as emu:
        driver = Driver(emu.targets[0])
        ardupilot_rate = 200            # AP's EAHRS_RATE: it writes 800 / rate as the divisor
        exchange = ardupilot_start("VN-100T-CR") + echoed(f"VNWRG,75,3,{800 // ardupilot_rate},01,0721",
                                                           "VNWRG,76,3,16,11,0001,0106")
        paused = driver.replay(exchange, then_read=0.3)
        assert driver.transact(command("VNASY,1")) == reply("VNASY,1")
        after = driver.read(1.5)[driver.reply_end:]
        driver.close()
        code, err = emu.interrupt()
    assert code == 0, err
    assert b"\xfa" not in paused, "binary output while paused"
    found, stray = packets(after, {ARDUPILOT_IMU: 82, ARDUPILOT_AHRS: 56})
    imu, ahrs = found[ARDUPILOT_IMU], found[ARDUPILOT_AHRS]
    assert stray == 0 and len(imu) > 100
    # 800/4 = 200 Hz and 800/16 = 50 Hz of an 800 Hz unit, from a 400 Hz scene: every 2nd and 8th sample
    t_imu = np.array([struct.unpack_from("<Q", p, 4)[0] for p in imu])
    t_ahrs = np.array([struct.unpack_from("<Q", p, 6)[0] for p in ahrs])
    assert set(np.diff(t_imu)) == {5_000_000} and set(np.diff(t_ahrs)) == {20_000_000}
    assert set(t_ahrs) <= set(t_imu)        # one sample counter: the slower output falls on IMU samples
    # ArduPilot's VN_IMU_packet: uint64 timeStartup, float gyro[3], accel[3], uncompAccel[3], uncompAngRate[3],
    # mag[3], temp, pressure
    k = np.rint(t_imu * 1e-9 * rate).astype(int)
    fields = np.array([struct.unpack_from("<17f", p, 12) for p in imu])
    np.testing.assert_array_equal(fields[:, 0:3], gyro[k].astype(np.float32))
    np.testing.assert_array_equal(fields[:, 3:6], accel[k].astype(np.float32))
    np.testing.assert_array_equal(fields[:, 6:9], accel[k].astype(np.float32))
    np.testing.assert_array_equal(fields[:, 9:12], gyro[k].astype(np.float32))
    # AHRS packet: ypr[3] deg, quaternion[4] x, y, z, w, yprU[3]; unit quaternion, YPR consistent with it
    att = np.array([struct.unpack_from("<10f", p, 14) for p in ahrs])
    np.testing.assert_allclose(np.linalg.norm(att[:, 3:7], axis=1), 1.0, atol=1e-6)
    x, y, z, w = att[:, 3:7].T
    yaw = np.degrees(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    np.testing.assert_allclose(att[:, 0], yaw, atol=1e-3)
    # the attitude ArduPilot takes (state.quat = w, x, y, z from the packet's x, y, z, w) is the scene's
    from scipy.spatial.transform import Rotation
    wire = Rotation.from_quat(att[:, 3:7])
    assert np.all((scene_attitude(scene_path, np.rint(t_ahrs * 1e-9 * rate).astype(int)).inv() * wire).magnitude()
                  < 1e-6)
    # healthy() throughout, so pre_arm_check() (setup complete, healthy; no GNSS check for a VN-1xx) passes
    assert healthy_throughout(t_imu, t_ahrs)
    assert "device: 7 commands answered, 0 error replies" in err


# ArduPilot's VN-300 packets (AP_ExternalAHRS_VectorNav.cpp, VN_INS_ekf_packet and VN_INS_gnss_packet headers)
ARDUPILOT_INS_EKF = bytes([0x31, 0x01, 0x00, 0x06, 0x01, 0x13, 0x06])
ARDUPILOT_GNSS = bytes([0x49, 0x03, 0x00, 0xB8, 0x26, 0x18, 0x00])
# VN_INS_gnss_packet: uint64 timeStartup, timeGps; uint8 numSats1, fix1; double posLla1[3]; float velNed1[3],
# posU1[3], velU1, dop1[7]; uint8 numSats2, fix2 (PACKED, little-endian): 100 bytes + sync, header, CRC = 110
GNSS_STRUCT = struct.Struct("<QQBB3d3f3ff7fBB")


def test_ardupilot_vn300_start_up_sequence_and_its_gnss_packet(tmp_path):
    """ArduPilot's INS path (model VN-3xx) writes the three binary outputs, the third being the GNSS packet its
    pre-arm check needs (fix >= 3 on both receivers); each packet is decoded with ArduPilot's own struct layout
    and its position checked against pymap3d from the scene's truth."""
    import pymap3d

    from imu_emulator.geo.geodesy import DEFAULT_ORIGIN
    from imu_emulator.scene.load import load_scene
    from imu_emulator.runtime.simulation import Simulation
    from tests.firmware_protocols.devices.test_vectornav_drivers import WEEK_START
    rate, week = 200, 2345          # a scene slower than the unit: divisors still count its 400 Hz IMU
    scene_path = write_scene(tmp_path, rate=rate, duration=60.0)
    with Emulator(scene_path, "--format", "vectornav-binary", "--to", "pty", "--duration", "40",
                  "--option", "model=VN-300-CR", "--start-time", WEEK_START) as emu:
        driver = Driver(emu.targets[0])
        ardupilot_rate = 200            # EAHRS_RATE; a VN-300's IMU runs at 400 Hz: divisor 400 / rate
        exchange = ardupilot_start("VN-300-CR") + echoed(f"VNWRG,75,3,{400 // ardupilot_rate},01,0721",
                                                          f"VNWRG,76,3,{400 // 50},31,0001,0106,0613",
                                                          f"VNWRG,77,3,{400 // 5},49,0003,26B8,0018", "VNASY,1")
        after = driver.replay(exchange, then_read=2.5)
        driver.close()
        code, err = emu.interrupt()
    assert code == 0, err
    ekf_size = 1 + 7 + 8 + 12 + 16 + 12 + 2 + 24 + 12 + 4 + 4 + 2
    found, stray = packets(after, {ARDUPILOT_IMU: 82, ARDUPILOT_INS_EKF: ekf_size, ARDUPILOT_GNSS: 110})
    assert stray == 0 and len(found[ARDUPILOT_INS_EKF]) >= 50
    # a VN-300 divides its 400 Hz IMU rate without being told: IMU at 200 Hz, EKF 50 Hz, GNSS 5 Hz; healthy()
    t_imu = np.array([struct.unpack_from("<Q", p, 4)[0] for p in found[ARDUPILOT_IMU]])
    t_ekf = np.array([struct.unpack_from("<Q", p, 8)[0] for p in found[ARDUPILOT_INS_EKF]])
    assert set(np.diff(t_imu)) == {5_000_000} and set(np.diff(t_ekf)) == {20_000_000}
    gnss = [GNSS_STRUCT.unpack_from(p, 8) for p in found[ARDUPILOT_GNSS]]
    assert healthy_throughout(t_imu, t_ekf, np.array([g[0] for g in gnss]))
    assert len(gnss) >= 8               # 400 / 80 = 5 Hz for 2.5 s
    t_startup = np.array([g[0] for g in gnss])
    assert set(np.diff(t_startup)) == {200_000_000}
    # ArduPilot: gps_week = timeGps / (ms per week * 1e6), ms_tow = timeGps / 1e6 % ms per week
    week_ns = 7 * 86400 * 10**9
    for g in gnss:
        # --start-time is the start of GPS week 2345 and TimeStartup counts from it: TOW = TimeStartup
        assert g[1] // week_ns == week and g[1] % week_ns == g[0]
        assert g[3] >= 3 and g[-1] >= 3 and g[2] > 0 and g[-2] > 0         # ArduPilot's pre-arm: fix >= 3
        assert np.all(np.array(g[10:13]) > 0) and g[13] > 0                 # posU N, E, D and velU
        dop = np.array(g[14:21], dtype=np.float64)                          # g, p, t, v, h, n, e
        np.testing.assert_allclose(dop[0] ** 2, dop[1] ** 2 + dop[2] ** 2, rtol=1e-5)
        np.testing.assert_allclose(dop[1] ** 2, dop[4] ** 2 + dop[3] ** 2, rtol=1e-5)
    scene = load_scene(scene_path)
    k = np.rint(t_startup * 1e-9 * rate).astype(int)
    truth = Simulation(scene, truth=True).block(0, int(k.max()) + 1).truth
    east, north, up = truth["position"][k].T           # the test scene is ENU
    lat, lon, h = pymap3d.enu2geodetic(east, north, up, *DEFAULT_ORIGIN)
    lla = np.array([g[4:7] for g in gnss])
    np.testing.assert_allclose(lla[:, 0], lat, atol=1e-10)      # deg: ~1e-5 m
    np.testing.assert_allclose(lla[:, 1], lon, atol=1e-10)
    np.testing.assert_allclose(lla[:, 2], h, atol=1e-6)
    ve, vn, vu = truth["velocity"][k].T
    vel = np.array([g[7:10] for g in gnss])
    np.testing.assert_allclose(vel, np.stack([vn, ve, -vu], axis=1).astype(np.float32), rtol=1e-6, atol=1e-6)
    assert np.all(np.abs(np.hypot(vel[:, 0], vel[:, 1]) - 2 * np.pi * 0.5 * 5.0) < 1e-3)   # circle: 2 pi f r
    assert "device: 8 commands answered, 0 error replies" in err


PX4_OUTPUT1 = bytes.fromhex("06") + struct.pack("<2H", 0x0001, 0x0600)
PX4_OUTPUT2 = bytes.fromhex("36") + struct.pack("<4H", 0x0001, 0x0130, 0x0084, 0x0613)


def test_px4_start_up_sequence_registers_baud_echo_and_binary_outputs(tmp_path):
    rate = 400
    scene_path = write_scene(tmp_path, rate=rate, duration=60.0)
    with Emulator(scene_path, "--format", "vectornav-binary", "--to", "pty", "--duration", "40",
                  "--option", "model=VN-300-CR", "--option", "serial_number=100099887") as emu:
        driver = Driver(emu.targets[0])
        # vnproglib's command texts (sprintf "$VNRRG,%02u", "$VNWRG,%u,%u,%u,%X" + ",%X" per field)
        exchange = [
            ("VNRRG,01", "VNRRG,01,VN-300-CR"),
            ("VNWRG,05,921600", "VNWRG,05,921600"),
            ("VNRRG,01", "VNRRG,01,VN-300-CR"),
            ("VNRRG,02", "VNRRG,02,2"),
            ("VNRRG,03", "VNRRG,03,100099887"),
            ("VNRRG,04", "VNRRG,04,2.1.0.0"),
            ("VNRRG,05", "VNRRG,05,921600"),
            ("VNWRG,06,0", "VNWRG,06,0"),
            ("VNRRG,35", "VNRRG,35,1,1,1,1"),
            ("VNWRG,35,1,0,1,1", "VNWRG,35,1,0,1,1"),
            ("VNRRG,35", "VNRRG,35,1,0,1,1"),
            ("VNWRG,75,1,1,6,1,600", "VNWRG,75,1,1,6,1,600"),
            ("VNWRG,76,1,8,36,1,130,84,613", "VNWRG,76,1,8,36,1,130,84,613"),
            ("VNRRG,76", "VNRRG,76,1,8,36,0001,0130,0084,0613"),
        ]
        after = driver.replay(exchange, then_read=1.0)
        driver.close()
        code, err = emu.interrupt()
    assert code == 0, err
    assert "baud rate 921600 acknowledged" in err
    out1, out2 = 1 + len(PX4_OUTPUT1) + 8 + 24 + 2, 1 + len(PX4_OUTPUT2) + 8 + 12 + 4 + 4 + 16 + 12 + 2 + 24 + 12 + 8 + 2
    found, stray = packets(after, {PX4_OUTPUT1: out1, PX4_OUTPUT2: out2})
    assert stray == 0
    t1 = [struct.unpack_from("<Q", p, 6)[0] for p in found[PX4_OUTPUT1]]
    t2 = [struct.unpack_from("<Q", p, 10)[0] for p in found[PX4_OUTPUT2]]
    assert set(np.diff(t1)) == {2_500_000} and set(np.diff(t2)) == {20_000_000}
    # INS PosLla: the documented default origin (the scene's circle is 5 m around it), height 488 m
    lla = np.array([struct.unpack_from("<3d", p, 10 + 8 + 12 + 4 + 4 + 16 + 12 + 2) for p in found[PX4_OUTPUT2]])
    assert np.all(np.abs(lla[:, 0] - 47.397742) < 1e-4) and np.all(np.abs(lla[:, 1] - 8.545594) < 1e-4)
    assert np.all(np.abs(lla[:, 2] - 488.0) < 1e-3)


def test_ascii_output_follows_registers_6_7_and_30_and_crc_commands_get_crc_replies(tmp_path):
    scene_path = write_scene(tmp_path, rate=200, duration=60.0)
    with Emulator(scene_path, "--format", "vectornav-binary", "--to", "pty", "--duration", "40",
                  "--pace-baud", "115200") as emu:
        driver = Driver(emu.targets[0])
        assert driver.transact(command("VNWRG,75,0,1,01,0001", "crc")) == reply("VNWRG,75,0,1,01,0001", "crc")
        assert driver.transact(command("VNWRG,06,14", "crc")) == reply("VNWRG,06,14", "crc")
        assert driver.transact(command("VNWRG,07,50")) == reply("VNWRG,07,50")
        # Communication protocol control: SerialChecksum (5th field) 2 = CRC-16 on asynchronous output
        assert driver.transact(command("VNWRG,30,0,0,0,0,2,0,1")) == reply("VNWRG,30,0,0,0,0,2,0,1")
        after = driver.read(1.0)[driver.reply_end:]
        assert driver.transact(command("VNWRG,05,230400")) == reply("VNWRG,05,230400")
        driver.close()
        code, err = emu.interrupt()
    assert code == 0, err
    lines = after.split(b"\r\n")[:-1]
    assert 40 <= len(lines) <= 55 and all(l.startswith(b"$VNYMR,") for l in lines)     # 50 Hz for 1 s
    for line in lines:
        body, _, cs = line[1:].partition(b"*")
        assert len(cs) == 4 and int(cs, 16) == binascii.crc_hqx(body, 0)
    assert "baud rate 230400 followed" in err


BAD = [
    (b"$VNRRG,01*00\r\n", "VNERR,03"),          # wrong XOR
    (b"$VNRRG,01*0000\r\n", "VNERR,03", "crc"),  # wrong CRC: the error comes with a CRC too
    (b"$VNRRG,01\r\n", "VNERR,03"),             # no checksum at all
    (command("VNRRG,99"), "VNERR,08"),          # unknown register
    (command("VNWRG,01,VN-999"), "VNERR,08"),   # read-only register
    (command("VNXYZ,1"), "VNERR,04"),           # unknown command
    (command("VNRRG"), "VNERR,05"),             # truncated: no register
    (command("VNWRG,75,3,4,01"), "VNERR,05"),   # fewer fields than groups
    (command("VNWRG,75,3,4,01,0721,0001"), "VNERR,06"),
    (command("VNWRG,75,3,4,10,0008"), "VNERR,07"),    # Attitude Dcm: no data for it
    (command("VNWRG,05,12345"), "VNERR,07"),
    (command("VNWRG,06,2"), "VNERR,07"),        # VNQTN: not produced
    (command("VNASY,2"), "VNERR,07"),
]


def test_bad_commands_get_error_replies_and_a_flood_during_streaming_is_answered(tmp_path):
    scene_path = write_scene(tmp_path, rate=1000, duration=60.0)
    stats = tmp_path / "stats.json"
    with Emulator(scene_path, "--format", "vectornav-binary", "--to", "pty", "--duration", "40",
                  "--stats-json", stats) as emu:
        driver = Driver(emu.targets[0])
        for sent, expected, *kind in BAD:
            got = driver.transact(sent)
            assert got == reply(expected, *kind), sent
        rng = random.Random(11)
        noise = bytes(rng.randrange(256) for _ in range(20000)).replace(b"$", b"#")
        driver.send_all(noise)
        driver.send_all(b"$VNRRG,0")        # truncated, then cut by the next command
        driver.send_all(command("VNRRG,01") * 200)
        driver.read(1.0)
        still = driver.transact(command("VNRRG,03"))
        driver.close()
        code, err = emu.interrupt()
    assert code == 0, err
    assert "Traceback" not in err
    text = bytes(driver.data)
    assert text.count(reply("VNRRG,01,VN-100T-CR")) == 200
    assert reply("VNERR,03") in text                     # the cut fragment "$VNRRG,0" had no checksum
    assert still == reply("VNRRG,03,100012345")
    import json
    summary = json.loads(stats.read_text())
    device = summary["streams"][0]["device"]
    assert device["ignored_bytes"] >= len(noise) - 100  # noise outside command lines, counted
    assert device["replies_dropped"] == 0
    # How late the samples went out while commands flooded in is a figure, not a check here: tools/bench_device.py
    # prints the stream's lateness with and without a driver's commands, interleaved.


def test_ardupilot_preset_streams_both_packets_without_configuration(tmp_path):
    scene_path = write_scene(tmp_path, rate=800, duration=60.0)
    with Emulator(scene_path, "--format", "vectornav-binary", "--to", "pty", "--duration", "20",
                  "--option", "preset=ardupilot") as emu:
        driver = Driver(emu.targets[0])
        data = driver.read(1.0)
        driver.close()
        code, err = emu.interrupt()
    assert code == 0, err
    start = data.find(b"\xfa" + ARDUPILOT_IMU)
    found, stray = packets(data[start:], {ARDUPILOT_IMU: 82, ARDUPILOT_AHRS: 56})
    assert stray < 82 + 56          # at most one packet cut by the end of the read
    # 800 Hz unit: IMU every sample, AHRS every 16th (50 Hz)
    assert abs(len(found[ARDUPILOT_IMU]) / max(1, len(found[ARDUPILOT_AHRS])) - 16) <= 1


def test_formats_lists_devices_and_presets():
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-m", "imu_emulator", "formats"], capture_output=True, text=True,
                         check=True).stdout
    assert re.search(r"^vectornav-binary .*\[device\]$", out, re.M)
    assert "preset=ardupilot:" in out and "preset=px4:" in out


def test_warm_up_runs_every_compiled_function_a_configuration_could_need(monkeypatch):
    """The streamer warms a throwaway device before the first deadline: a VectorNav device must run there every
    compiled function that a driver's register 75-77 write could bring in (vectornav_quantities), so no reply waits
    for a compile (seconds on a cold cache; past the 500 ms after which ArduPilot and the ROS nodes resend, and the
    resend is answered twice: the ROS 2 start-up answered 20 of 19 commands on a fresh clone)."""
    import firmware_protocols
    from firmware_protocols import Samples, vectornav_quantities
    from imu_emulator.native.lazy import Deferred

    # The compiled functions are Deferred until numba is imported, numba's dispatchers after (native.lazy.realize):
    # either way the module calls them by their global names, which are replaced here by recorders.
    compiled = [name for name, value in vars(vectornav_quantities).items()
                if isinstance(value, Deferred) or type(value).__module__.startswith(("numba", "imu_emulator.native"))]
    assert len(compiled) >= 4, compiled
    called = set()
    for name in compiled:
        def recording(*args, _name=name, _function=getattr(vectornav_quantities, name)):
            called.add(_name)
            return _function(*args)
        monkeypatch.setattr(vectornav_quantities, name, recording)
    n = 3
    samples = Samples(np.arange(n) * 2_500_000, np.zeros((n, 3)), np.zeros((n, 3)), quat=np.tile([1.0, 0, 0, 0], (n, 1)))
    firmware_protocols.create_device("vectornav-binary", 400.0).warm_up(samples)
    assert set(compiled) <= called, sorted(set(compiled) - called)
