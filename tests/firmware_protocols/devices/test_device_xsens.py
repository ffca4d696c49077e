"""The Xsens device end to end: the emulator in its own process on a pty; this process replays ArduPilot's
AP_ExternalAHRS_Xsens configuration byte for byte (messages built here from the Xbus rules, not with the
emulator's code) and parses the MTData2 that follows item by item, as that driver does."""
import os
import struct
import time

import numpy as np
import pytest

from tests.support.stream import FRD_FROM_SCENE, Emulator, read_for, reference, write_scene
from tests.support.timing import scaled

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]


def message(mid: int, data: bytes = b"") -> bytes:
    body = bytes([0xFF, mid, len(data)]) + data
    return b"\xfa" + body + bytes([(0x100 - sum(body)) & 0xFF])


def frames(data: bytes) -> list:
    """(mid, payload) of every checksum-valid Xbus frame, scanning like ArduPilot's process_received_data."""
    out, pos = [], 0
    while pos + 4 <= len(data):
        if data[pos] != 0xFA or data[pos + 1] != 0xFF:
            pos += 1
            continue
        length = data[pos + 3]
        total = 4 + length + 1
        frame = data[pos:pos + total]
        if len(frame) == total and sum(frame[1:]) & 0xFF == 0:
            out.append((frame[2], frame[4:4 + length]))
            pos += total
        else:
            pos += 1
    return out


def items(payload: bytes) -> list:
    out, k = [], 0
    while k + 3 <= len(payload):
        xdi, size = struct.unpack_from(">HB", payload, k)
        out.append((xdi, payload[k + 3:k + 3 + size]))
        k += 3 + size
    return out


class Client:
    def __init__(self, path):
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self.data = b""
        assert read_for(self.fd, 30, stop_after=1)

    def transact(self, sent: bytes, expect_mid: int, timeout=scaled(5.0)):
        """Send, resend every 2 s like ArduPilot, until a frame with expect_mid (or an Error) arrives."""
        start = len(self.data)
        end, next_send = time.monotonic() + timeout, 0.0
        while time.monotonic() < end:
            if time.monotonic() >= next_send:
                os.write(self.fd, sent)
                next_send = time.monotonic() + 2.0
            self.data += read_for(self.fd, 0.05)
            for mid, payload in frames(self.data[start:]):
                if mid in (expect_mid, 0x42):
                    self.mark = len(self.data)
                    return mid, payload
        raise AssertionError(f"no reply to {sent.hex()}")


# ArduPilot's XDIs: PacketCounter, SampleTimeFine, UtcTime, Temperature, Quaternion, Acceleration, RateOfTurn,
# MagneticField, StatusWord, BaroPressure, LatLon (FP16.32), AltitudeEllipsoid (FP16.32), VelocityXYZ
# (FP16.32), GnssPvtData
ARDUPILOT_XDIS = (0x1020, 0x1060, 0x1010, 0x0810, 0x2010, 0x4020, 0x8020, 0xC020, 0xE020, 0x3010, 0x5042,
                  0x5022, 0xD012, 0x7010)


# Xsens' XsUtcTime and XsRawGnssPvtData (xstypes, packed), big-endian on the wire
UTC = struct.Struct(">IHBBBBBB")
PVT = struct.Struct(">IHBBBBBBIiBBBBiiiiIIiiiiiIIiHHHHHHH")


def test_ardupilot_configuration_then_exactly_the_configured_items(tmp_path):
    """ArduPilot's sequence, every item it asks for present, UtcTime and GnssPvtData decoded with Xsens' own
    struct layouts and checked against the scene's truth (pymap3d for the geodetic position), and the two
    alignment rotations ArduPilot sends (local: ENU -> NED, sensor: pi about x) applied: scipy's Rotation
    gives what the accelerometer and the quaternion must then read."""
    import datetime

    import pymap3d
    from scipy.spatial.transform import Rotation

    from imu_emulator.geo.geodesy import DEFAULT_ORIGIN
    from imu_emulator.scene.load import load_scene
    from imu_emulator.runtime.simulation import Simulation
    rate = 400
    scene_path = write_scene(tmp_path, rate=rate, duration=60.0)
    scene, _, accel, gyro = reference(scene_path)
    start_ns = int((datetime.datetime(2026, 11, 27, 12) - datetime.datetime(1970, 1, 1)).total_seconds()) * 10**9
    with Emulator(scene_path, "--format", "xsens-mtdata2", "--to", "pty", "--duration", "40",
                  "--start-time", "2026-11-27T12:00:00Z") as emu:
        client = Client(emu.targets[0])
        assert client.transact(message(0x30), 0x31) == (0x31, b"")
        in_config = read_for(client.fd, 0.3)
        assert client.transact(message(0x00), 0x01) == (0x01, struct.pack(">I", 0x03780123))
        assert client.transact(message(0x1C), 0x1D) == (0x1D, b"MTi-300-2A8G4")
        assert client.transact(message(0x12), 0x13) == (0x13, bytes([1, 8, 2]))
        ap_rate = 100
        config = b"".join(struct.pack(">HH", xdi, ap_rate) for xdi in ARDUPILOT_XDIS)
        assert client.transact(message(0xC0, config), 0xC1) == (0xC1, config)
        local_q = (0.0, 0.7071068, 0.7071068, 0.0)
        sensor_q = (0.0, 1.0, 0.0, 0.0)
        assert client.transact(message(0xEC, bytes([1]) + struct.pack(">4f", *local_q)), 0xED) == (0xED, b"")
        assert client.transact(message(0xEC, bytes([0]) + struct.pack(">4f", *sensor_q)), 0xED) == (0xED, b"")
        assert client.transact(message(0x10), 0x11) == (0x11, b"")
        client.data += read_for(client.fd, 1.0)
        after = client.data[client.mark:]
        assert client.transact(message(0x77), 0x78) == (0x42, bytes([4]))          # unknown message id
        os.close(client.fd)
        code, err = emu.interrupt()
    assert code == 0, err
    assert not [m for m, _ in frames(in_config) if m == 0x36], "MTData2 in config mode"
    packets = [dict(items(payload)) for mid, payload in frames(after) if mid == 0x36]
    assert len(packets) > 50
    for packet in packets:
        assert list(packet) == list(ARDUPILOT_XDIS)
    assert "cannot produce" not in err
    # 100 Hz of a 400 Hz scene: SampleTimeFine (10 kHz ticks) steps by 100, PacketCounter by 1
    fine = np.array([struct.unpack(">I", p[0x1060])[0] for p in packets])
    counter = np.array([struct.unpack(">H", p[0x1020])[0] for p in packets])
    assert set(np.diff(fine)) == {100} and set(np.diff(counter) % 65536) == {1}
    # SampleTimeFine counts since the unit's start (the run's), UtcTime from --start-time: start + scene time
    k = np.rint(fine * 1e-4 * rate).astype(int)
    t_ns = start_ns + k * (10**9 // rate)
    # Sensor alignment pi about x: the object frame is x, -y, -z of the sensor's, whose own axes are forward-left-up
    # (reference() gives forward-right-down: FRD_FROM_SCENE["ENU"] turns it back), so ArduPilot gets FRD
    got_acc = np.array([struct.unpack(">3f", p[0x4020]) for p in packets])
    expected = Rotation.from_quat([*sensor_q[1:], sensor_q[0]]).apply(accel[k] * FRD_FROM_SCENE["ENU"])
    np.testing.assert_allclose(got_acc, accel[k], rtol=1e-6, atol=1e-6)        # the same thing, said directly
    np.testing.assert_allclose(got_acc, expected, rtol=1e-6, atol=1e-6)
    # Quaternion: q_L'O = q_L'L q_LS q_OS*, the scene's ENU attitude turned to NED, body turned to x, -y, -z
    truth = Simulation(scene, truth=True).block(0, int(k.max()) + 1)
    q_ls = truth.quat[0][k]
    want = (Rotation.from_quat([*local_q[1:], local_q[0]]) * Rotation.from_quat(q_ls[:, [1, 2, 3, 0]])
            * Rotation.from_quat([*sensor_q[1:], sensor_q[0]]).inv())
    got_q = np.array([struct.unpack(">4f", p[0x2010]) for p in packets])
    assert np.all((want.inv() * Rotation.from_quat(got_q[:, [1, 2, 3, 0]])).magnitude() < 1e-5)
    # UtcTime: the run's --start-time + scene time
    for p, t in zip(packets, t_ns):
        nano, year, month, day, hour, minute, second, flags = UTC.unpack(p[0x1010])
        when = datetime.datetime(1970, 1, 1) + datetime.timedelta(microseconds=int(t) // 1000)
        assert (year, month, day, hour, minute, second) == (when.year, when.month, when.day, when.hour,
                                                             when.minute, when.second)
        assert nano == t % 10**9 and flags == 0x07
    # GnssPvtData: GPS time of week (UTC + 18 leap seconds since the GPS epoch 1980-01-06), a 3D fix, and the
    # scene's position and NED velocity in u-blox units (1e-7 deg, mm, mm/s)
    pvt = np.array([PVT.unpack(p[0x7010]) for p in packets], dtype=np.float64)
    gps_ms = t_ns // 10**6 + (18 - 315964800) * 1000
    np.testing.assert_array_equal(pvt[:, 0], gps_ms % (7 * 86400 * 1000))
    assert np.all(pvt[:, 10] == 3) and np.all(pvt[:, 12] > 0)
    east, north, up = truth.truth["position"][k].T
    lat, lon, h = pymap3d.enu2geodetic(east, north, up, *DEFAULT_ORIGIN)
    assert np.all(np.abs(pvt[:, 14] - lon * 1e7) <= 0.5) and np.all(np.abs(pvt[:, 15] - lat * 1e7) <= 0.5)
    assert np.all(np.abs(pvt[:, 16] - h * 1e3) <= 0.5)
    ve, vn, vu = truth.truth["velocity"][k].T
    np.testing.assert_allclose(pvt[:, 20:23], np.stack([vn, ve, -vu], axis=1) * 1e3, atol=0.5)
    dop = pvt[:, 28:35] / 100      # g, p, t, v, h, n, e: g^2 = p^2 + t^2 (to the 0.01 wire step)
    np.testing.assert_allclose(dop[:, 0] ** 2, dop[:, 1] ** 2 + dop[:, 2] ** 2, atol=0.05)
    # LatLon in FP16.32: the documented default origin within the scene's 5 m circle
    frac, whole = struct.unpack_from(">Ih", packets[0][0x5042], 0)
    assert abs(whole + frac / 2**32 - 47.397742) < 1e-4


def test_bad_frames_and_out_of_mode_commands_get_xsens_errors(tmp_path):
    scene_path = write_scene(tmp_path, rate=200, duration=60.0)
    with Emulator(scene_path, "--format", "xsens-mtdata2", "--to", "pty", "--duration", "40") as emu:
        client = Client(emu.targets[0])
        bad_checksum = message(0x30)[:-1] + b"\x00"
        assert client.transact(bad_checksum, 0x31) == (0x42, bytes([4]))
        # SetOutputConfiguration in measurement mode: not valid there
        assert client.transact(message(0xC0, struct.pack(">HH", 0x4020, 100)), 0xC1) == (0x42, bytes([4]))
        assert client.transact(message(0x30), 0x31) == (0x31, b"")
        assert client.transact(message(0xC0, b"\x40\x20\x00"), 0xC1) == (0x42, bytes([33]))   # odd length
        assert client.transact(message(0xEC, b"\x05"), 0xED) == (0x42, bytes([33]))
        os.write(client.fd, bytes(range(256)) * 8)       # noise, with false preambles among it
        assert client.transact(message(0x00), 0x01)[0] == 0x01
        os.close(client.fd)
        code, err = emu.interrupt()
    assert code == 0, err and "Traceback" not in err
