"""The VectorNav device against the configuration sequences of the drivers that use it, replayed byte for byte
over its command interface, and the packets that follow decoded with structs written here from VectorNav's
field table (vnproglib's BinaryPacketGroupLengths and its CompositeData parse order) and compared with the
truth: pymap3d for the ECEF quantities, scipy's Rotation for body/NED rotations, datetime for UTC.

Sequences transcribed from:
- ROS 1: dawonn/vectornav src/main.cpp at 0af9e1da7fd87858cdd0f879aadfd073b14879fe (vnproglib 1.1 VnSensor:
  connect + changeBaudRate + verifySensorConnectivity, the four identity reads, writeAsyncDataOutputType(VNOFF),
  writeBinaryOutput1 with the groups below, divisor fixed_imu_rate / async_output_rate = 800 / 40).
- ROS 2: dawonn/vectornav vectornav/src/vectornav.cc at 05496bcb2ee0c91619167f9a6b1f01851db3e7a5 (connect,
  identity and user tag reads, registers 6, 7, 32, 30, binary outputs 1-3 with the node's default parameters,
  BO2/BO3 `asyncMode 0, rateDivisor 0, no group` = `$VNWRG,76,0,0,0`).
- vnproglib's command texts: `$VNWRG,%u,%u,%u,%X` + `,%X` per non-zero group (genWriteBinaryOutput),
  `$VNWRG,32,%u,%u,%u,0,%u,%u,%u,%u,0`, `$VNWRG,30,%u,%u,%u,%u,%u,%u,%u`, `$VNWRG,07,%u`, 8-bit XOR checksums.
- ArduPilot: AP_ExternalAHRS_VectorNav.cpp (the sequence in ../shared/specs/devices.md; its 800 / rate divisor
  for a VN-1xx, 400 / rate for a VN-300) and healthy(): IMU packet < 40 ms old, attitude < 500 ms.
"""
import binascii
import datetime
import struct
from functools import reduce

import numpy as np
import pymap3d
import pytest
from scipy.spatial.transform import Rotation

from firmware_protocols.base import Samples
from firmware_protocols.devices.vectornav import VectorNavDevice

RATE = 400.0
WEEK = 2345
WEEK_NS = 7 * 86400 * 10**9
# GPS time - UTC Unix time from the definitions (GPS epoch 1980-01-06T00:00:00Z; 18 leap seconds since 2017-01-01):
# Samples.time_ns is UTC Unix ns (firmware_protocols.gnss_time), the GPS fields are derived from it.
GPS_MINUS_UNIX_NS = 18 * 10**9 - int((datetime.datetime(1980, 1, 6) - datetime.datetime(1970, 1, 1))
                                     .total_seconds()) * 10**9
# --start-time of a run whose scene time 0 is the start of GPS week WEEK (UTC = GPS - 18 s)
WEEK_START = (datetime.datetime(1980, 1, 6) + datetime.timedelta(weeks=WEEK, seconds=-18)).isoformat() + "Z"


def command(body: str) -> bytes:
    raw = body.encode()
    return b"$" + raw + b"*%02X\r\n" % reduce(lambda a, b: a ^ b, raw, 0)


def truth(n: int = 800, seed: int = 5) -> Samples:
    """A moving, turning unit with every field the head carries (INS estimate, its sigmas, the GNSS receiver)."""
    rng = np.random.default_rng(seed)
    # 3 s into GPS week WEEK, as UTC Unix ns
    t = WEEK * WEEK_NS + 3_000_000_000 - GPS_MINUS_UNIX_NS + np.arange(n, dtype=np.int64) * int(1e9 / RATE)
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    quat *= np.sign(quat[:, :1])
    r = Rotation.from_quat(np.column_stack((quat[:, 1:], quat[:, 0])))
    yaw, pitch, roll = r.as_euler("ZYX").T
    llh = np.column_stack((47.4 + rng.uniform(-1, 1, n), 8.5 + rng.uniform(-1, 1, n), rng.uniform(0, 2000, n)))
    return Samples(t, rng.normal(0, 3, (n, 3)), rng.normal(0, 1, (n, 3)), mag=rng.normal(0, 0.5, (n, 3)),
                   quat=quat, euler=np.column_stack((roll, pitch, yaw)),
                   temperature_c=rng.uniform(-10, 40, n), pressure_pa=rng.uniform(8e4, 1.05e5, n),
                   delta_theta=rng.normal(0, 0.01, (n, 3)), delta_velocity=rng.normal(0, 0.05, (n, 3)),
                   delta_time_s=np.full(n, 1 / RATE),
                   position_llh=llh, velocity_ned=rng.normal(0, 10, (n, 3)),
                   attitude_sigma_rad=rng.uniform(0.001, 0.02, (n, 3)), position_sigma_m=rng.uniform(0.5, 3, (n, 3)),
                   velocity_sigma_mps=rng.uniform(0.01, 0.2, (n, 3)), ins_mode=np.full(n, 2.0),
                   gnss_llh=llh + rng.normal(0, 1e-5, (n, 3)), gnss_velocity_ned=rng.normal(0, 10, (n, 3)),
                   gnss_fix=np.full(n, 3.0), gnss_satellites=np.full(n, 17.0),
                   gnss_horizontal_accuracy_m=np.full(n, 0.8), gnss_vertical_accuracy_m=np.full(n, 1.3),
                   gnss_speed_accuracy_mps=np.full(n, 0.07))


def replay(device: VectorNavDevice, exchange) -> None:
    """Each command as the driver sends it and the reply it accepts (vnproglib throws on $VNERR)."""
    for sent, expected in exchange:
        assert device.receive(command(sent)) == [command(expected)], sent


def stream(device: VectorNavDevice, samples: Samples) -> bytes:
    return b"".join(device.output(samples, i) for i in range(len(samples)))


def split(data: bytes, header: bytes, fmt: str) -> list:
    """Packets with this exact header, their CRC-16/XMODEM checked (binascii.crc_hqx) and payload unpacked."""
    size = 1 + len(header) + struct.calcsize(fmt) + 2
    found, pos = [], 0
    while (pos := data.find(b"\xfa" + header, pos)) >= 0:
        packet = data[pos:pos + size]
        assert len(packet) == size and binascii.crc_hqx(packet[1:], 0) == 0
        found.append(struct.unpack_from(fmt, packet, 1 + len(header)))
        pos += size
    return found


def rotation(samples: Samples, k) -> Rotation:
    q = samples.quat[k]
    return Rotation.from_quat(np.column_stack((q[:, 1:], q[:, 0])))


def ecef_vector(ned: np.ndarray, llh: np.ndarray) -> np.ndarray:
    """NED vectors -> ECEF with pymap3d (its uvw frame is ECEF; ENU in, so north/east swap and down flips)."""
    return np.column_stack(pymap3d.enu2uvw(ned[:, 1], ned[:, 0], -ned[:, 2], llh[:, 0], llh[:, 1]))


def f32(values) -> np.ndarray:
    return np.asarray(values, dtype=np.float32).astype(np.float64)


def utc(gps_ns: int) -> datetime.datetime:
    return datetime.datetime(1980, 1, 6) + datetime.timedelta(microseconds=(gps_ns // 1000)) \
        - datetime.timedelta(seconds=18)


IDENTITY = [("VNRRG,01", "VNRRG,01,{model}"), ("VNRRG,04", "VNRRG,04,2.1.0.0"), ("VNRRG,02", "VNRRG,02,2"),
            ("VNRRG,03", "VNRRG,03,100012345")]


def identity(model: str) -> list:
    return [(sent, reply.format(model=model)) for sent, reply in IDENTITY]


# ROS 1 binary output 1: Common Quaternion|YawPitchRoll|AngularRate|Position|Accel|MagPres = 0x578;
# Time GpsTow|GpsWeek|TimeUtc = 0x4C; Attitude YprU = 0x100; INS InsStatus|PosLla|PosEcef|VelBody|VelNed|
# AccelEcef|PosU|VelU = 0x69F; groups 0x33. Payload in group, then field-bit order.
ROS1_HEADER = bytes([0x33]) + struct.pack("<4H", 0x0578, 0x004C, 0x0100, 0x069F)
ROS1_STRUCT = "<3f4f3f3d3f3fff" + "QH" + "bBBBBBH" + "3f" + "H3d3d3f3f3fff"


def test_ros1_node_configures_its_output_and_every_field_equals_the_truth():
    model = "VN-200T-CR"
    device = VectorNavDevice(RATE, model=model)
    replay(device, [("VNRRG,01", f"VNRRG,01,{model}"), ("VNWRG,05,115200", "VNWRG,05,115200"),
                    ("VNRRG,01", f"VNRRG,01,{model}")] + identity(model)
           + [("VNRRG,01", f"VNRRG,01,{model}"), ("VNWRG,06,0", "VNWRG,06,0"),
              ("VNWRG,75,1,20,33,578,4C,100,69F", "VNWRG,75,1,20,33,578,4C,100,69F")])
    samples = truth()
    rows = split(stream(device, samples), ROS1_HEADER, ROS1_STRUCT)
    # 800 Hz / 20 = 40 Hz from a 400 Hz scene: every 10th sample, the first at once
    assert len(rows) == len(samples) // 10
    k = np.arange(len(rows)) * 10
    v = np.array(rows, dtype=object)
    col = lambda a, b: np.array(v[:, a:b], dtype=np.float64)      # noqa: E731
    r = rotation(samples, k)
    np.testing.assert_array_equal(col(0, 3), f32(np.degrees(samples.euler[k][:, ::-1])))
    np.testing.assert_array_equal(col(3, 7), f32(np.column_stack((samples.quat[k, 1:], samples.quat[k, 0]))))
    np.testing.assert_array_equal(col(7, 10), f32(samples.gyro[k]))
    np.testing.assert_array_equal(col(10, 13), samples.position_llh[k])
    np.testing.assert_array_equal(col(13, 16), f32(samples.accel[k]))
    np.testing.assert_array_equal(col(16, 19), f32(samples.mag[k]))
    np.testing.assert_array_equal(col(19, 20)[:, 0], f32(samples.temperature_c[k]))
    np.testing.assert_array_equal(col(20, 21)[:, 0], f32(samples.pressure_pa[k] / 1000))
    # Time group: GPS time of week and week, UTC calendar (year - 2000) with milliseconds
    gps = samples.time_ns[k] + GPS_MINUS_UNIX_NS
    np.testing.assert_array_equal(col(21, 22)[:, 0], gps % WEEK_NS)
    np.testing.assert_array_equal(col(22, 23)[:, 0], WEEK)
    for row, g in zip(rows, gps):
        when = utc(int(g))
        assert row[23:30] == (when.year - 2000, when.month, when.day, when.hour, when.minute, when.second,
                              when.microsecond // 1000)
    # Attitude YprU: yaw, pitch, roll sigma in degrees
    np.testing.assert_array_equal(col(30, 33), f32(np.degrees(samples.attitude_sigma_rad[k][:, ::-1])))
    # INS: status (tracking + GNSS fix), LLA, ECEF from pymap3d, body velocity, NED velocity, ECEF acceleration
    assert set(col(33, 34)[:, 0]) == {0x0006}
    llh = samples.position_llh[k]
    np.testing.assert_array_equal(col(34, 37), llh)
    np.testing.assert_allclose(col(37, 40), np.column_stack(pymap3d.geodetic2ecef(*llh.T)), rtol=0, atol=1e-6)
    np.testing.assert_allclose(col(40, 43), r.inv().apply(samples.velocity_ned[k]), rtol=1e-6, atol=1e-5)
    np.testing.assert_array_equal(col(43, 46), f32(samples.velocity_ned[k]))
    np.testing.assert_allclose(col(46, 49), ecef_vector(r.apply(samples.accel[k]), llh), rtol=1e-6, atol=1e-5)
    np.testing.assert_array_equal(col(49, 50)[:, 0], f32(np.linalg.norm(samples.position_sigma_m[k], axis=1)))
    np.testing.assert_array_equal(col(50, 51)[:, 0], f32(np.linalg.norm(samples.velocity_sigma_mps[k], axis=1)))
    assert device.stats.errors == 0


# ROS 2 defaults: BO1 async mode 3, divisor 40, Common 0x7FFF (all fifteen), GPS Fix|PosU = 0x210,
# INS PosEcef|VelBody = 0x0C; groups 0x29.
ROS2_HEADER = bytes([0x29]) + struct.pack("<3H", 0x7FFF, 0x0210, 0x000C)
ROS2_STRUCT = ("<QQQ3f4f3f3d3f3f3f3f3fff" + "f3f3f" + "HIQ") + "B3f" + "3d3f"
ROS2_CONFIG = [("VNWRG,06,0", "VNWRG,06,0"), ("VNWRG,07,20", "VNWRG,07,20"),
               ("VNWRG,32,3,0,0,0,0,0,0,100000000,0", "VNWRG,32,3,0,0,0,0,0,0,100000000,0"),
               ("VNWRG,30,0,0,0,0,1,0,1", "VNWRG,30,0,0,0,0,1,0,1"),
               ("VNWRG,75,3,40,29,7FFF,210,C", "VNWRG,75,3,40,29,7FFF,210,C"),
               ("VNWRG,76,0,0,0", "VNWRG,76,0,0,0"), ("VNWRG,77,0,0,0", "VNWRG,77,0,0,0")]
# then, not a VN-100 (determineDeviceFamily reads register 1 each time): GNSS configuration and antenna offset,
# and on a VN-300 the compass baseline (vnproglib genReadGpsConfiguration / AntennaOffset / CompassBaseline)
ROS2_VN300_READS = [("VNRRG,01", "VNRRG,01,VN-300-CR"), ("VNRRG,55", "VNRRG,55,0,0,5,0,0"),
                    ("VNRRG,57", "VNRRG,57,+0.000000,+0.000000,+0.000000"), ("VNRRG,01", "VNRRG,01,VN-300-CR"),
                    ("VNRRG,93", "VNRRG,93,+1.000000,+0.000000,+0.000000,+0.025400,+0.025400,+0.025400")]


def test_ros2_node_configures_every_output_turns_two_off_and_every_field_equals_the_truth():
    model = "VN-300-CR"
    device = VectorNavDevice(RATE, model=model,
                             fields="common:timestartup;imu:accel", preset=None)
    replay(device, [("VNRRG,01", f"VNRRG,01,{model}"), ("VNRRG,01", f"VNRRG,01,{model}")] + identity(model)
           + [("VNRRG,00", "VNRRG,00,")] + ROS2_CONFIG + ROS2_VN300_READS)
    # the readback shows output 2 off (vnproglib parses "mode,divisor,groups")
    assert device.receive(command("VNRRG,76")) == [command("VNRRG,76,0,0,00")]
    samples = truth()
    data = stream(device, samples)
    rows = split(data, ROS2_HEADER, ROS2_STRUCT)
    # a VN-300's 400 Hz IMU / 40 = 10 Hz: every 40th sample of the 400 Hz scene, and nothing else on the link
    assert len(rows) == len(samples) // 40
    assert len(data) == len(rows) * (1 + len(ROS2_HEADER) + struct.calcsize(ROS2_STRUCT) + 2)
    k = np.arange(len(rows)) * 40
    v = np.array(rows, dtype=np.float64)
    gps = samples.time_ns[k] + GPS_MINUS_UNIX_NS
    np.testing.assert_array_equal(v[:, 0], samples.time_ns[k])
    np.testing.assert_array_equal(v[:, 1], gps)
    np.testing.assert_array_equal(v[:, 2], gps % 10**9)                 # TimeSyncIn: SyncIn on the PPS
    np.testing.assert_array_equal(v[:, 3:6], f32(np.degrees(samples.euler[k][:, ::-1])))
    np.testing.assert_array_equal(v[:, 6:10], f32(np.column_stack((samples.quat[k, 1:], samples.quat[k, 0]))))
    np.testing.assert_array_equal(v[:, 10:13], f32(samples.gyro[k]))
    np.testing.assert_array_equal(v[:, 13:16], samples.position_llh[k])     # Common Position = INS PosLla
    np.testing.assert_array_equal(v[:, 16:19], f32(samples.velocity_ned[k]))
    np.testing.assert_array_equal(v[:, 19:22], f32(samples.accel[k]))
    np.testing.assert_array_equal(v[:, 22:25], f32(samples.accel[k]))       # Imu: uncompensated accel, gyro
    np.testing.assert_array_equal(v[:, 25:28], f32(samples.gyro[k]))
    np.testing.assert_array_equal(v[:, 28:31], f32(samples.mag[k]))
    np.testing.assert_array_equal(v[:, 31], f32(samples.temperature_c[k]))
    np.testing.assert_array_equal(v[:, 32], f32(samples.pressure_pa[k] / 1000))
    # DeltaTheta: the increments summed since the previous packet (40 samples), dtime s, angles in degrees
    sums = lambda a: np.add.reduceat(a[:k[-1] + 1], np.concatenate(([0], k[1:] - 39)))[1:]   # noqa: E731
    np.testing.assert_allclose(v[1:, 33], 40 / RATE, rtol=1e-6)
    np.testing.assert_allclose(v[1:, 34:37], np.degrees(sums(samples.delta_theta)), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(v[1:, 37:40], sums(samples.delta_velocity), rtol=1e-5, atol=1e-6)
    assert set(v[:, 40]) == {0x0006}                                        # InsStatus: tracking, GNSS fix
    np.testing.assert_array_equal(v[:, 41], (samples.time_ns[k] // 10**9))  # SyncInCnt: PPS edges since start
    np.testing.assert_array_equal(v[:, 42], gps % 10**9)                    # TimeGpsPps
    assert set(v[:, 43]) == {3}                                             # GPS Fix: 3D
    np.testing.assert_array_equal(v[:, 44:47], f32(np.tile([0.8, 0.8, 1.3], (len(k), 1))))
    llh = samples.position_llh[k]
    np.testing.assert_allclose(v[:, 47:50], np.column_stack(pymap3d.geodetic2ecef(*llh.T)), rtol=0, atol=1e-6)
    np.testing.assert_allclose(v[:, 50:53], rotation(samples, k).inv().apply(samples.velocity_ned[k]),
                               rtol=1e-6, atol=1e-5)
    assert device.stats.errors == 0


def test_gnss_registers_exist_on_gnss_models_only_and_keep_what_is_written():
    vn300, vn200, vn100 = (VectorNavDevice(RATE, model=m) for m in ("VN-300-CR", "VN-200T-CR", "VN-100T-CR"))
    replay(vn300, [("VNWRG,57,0.1,-0.2,0.3", "VNWRG,57,0.1,-0.2,0.3"),
                   ("VNRRG,57", "VNRRG,57,+0.100000,-0.200000,+0.300000"),
                   ("VNWRG,55,0,0,5,0,0", "VNWRG,55,0,0,5,0,0")])
    for bad, code in (("VNWRG,57,nan,0,0", "07"), ("VNWRG,57,1,2", "05"), ("VNWRG,93,1,0,0,1,1,1,1", "06")):
        assert vn300.receive(command(bad)) == [command(f"VNERR,{code}")], bad
    assert vn200.receive(command("VNRRG,55")) == [command("VNRRG,55,0,0,5,0,0")]
    assert vn200.receive(command("VNRRG,93")) == [command("VNERR,08")]        # a compass baseline: VN-300 only
    assert vn100.receive(command("VNRRG,57")) == [command("VNERR,08")]


def test_gnss_group_reports_the_receiver_not_the_ins():
    """GPS PosLla / VelNed / PosEcef / VelEcef / NumSats / VelU come from Samples.gnss_*, ECEF via pymap3d."""
    device = VectorNavDevice(RATE, model="VN-300-CR",
                             fields="gps:numsats,poslla,posecef,velned,velecef,velu,timeinfo")
    samples = truth(40)
    header = bytes([0x08]) + struct.pack("<H", 0x1000 | 0x0400 | 0x01E8)
    v = np.array(split(stream(device, samples), header, "<B3d3d3f3ffBb"), dtype=np.float64)
    llh, vel = samples.gnss_llh, samples.gnss_velocity_ned
    assert set(v[:, 0]) == {17}
    np.testing.assert_array_equal(v[:, 1:4], llh)
    np.testing.assert_allclose(v[:, 4:7], np.column_stack(pymap3d.geodetic2ecef(*llh.T)), rtol=0, atol=1e-6)
    np.testing.assert_array_equal(v[:, 7:10], f32(vel))
    np.testing.assert_allclose(v[:, 10:13], ecef_vector(vel, llh), rtol=1e-6, atol=1e-5)
    np.testing.assert_array_equal(v[:, 13], np.float32(0.07))
    assert set(map(tuple, v[:, 14:16])) == {(7, 18)}          # time, week, UTC valid; 18 leap seconds


def test_ardupilot_rates_come_right_from_the_model_alone():
    """AP writes 800 / EAHRS_RATE for a VN-1xx and 400 / rate for a VN-300; without options the device divides
    the model's own IMU rate, so at the default EAHRS_RATE 50 Hz both packets come every 20 ms, whatever the
    scene's rate, and healthy() (IMU < 40 ms, attitude < 500 ms) holds at every sample."""
    for model, imu_rate in (("VN-100T-CR", 800), ("VN-300-CR", 400)):
        for scene_rate in (200.0, 400.0, 1000.0):
            device = VectorNavDevice(scene_rate, model=model)
            echoed = [f"VNWRG,75,3,{imu_rate // 50},01,0721", f"VNWRG,76,3,{imu_rate // 50},11,0001,0106"]
            replay(device, [("VNASY,0", "VNASY,0"), ("VNWRG,06,0,1", "VNWRG,06,0,1"),
                            ("VNWRG,06,0,2", "VNWRG,06,0,2"), ("VNRRG,01", f"VNRRG,01,{model}")]
                   + [(body, body) for body in echoed] + [("VNASY,1", "VNASY,1")])
            n = int(scene_rate)
            samples = Samples(np.arange(n, dtype=np.int64) * int(round(1e9 / scene_rate)), np.zeros((n, 3)),
                              np.zeros((n, 3)))
            data = stream(device, samples)
            imu = [r[0] for r in split(data, bytes.fromhex("01") + struct.pack("<H", 0x0721), "<Q17f")]
            ahrs = [r[0] for r in split(data, bytes.fromhex("11") + struct.pack("<2H", 0x0001, 0x0106), "<Q10f")]
            assert set(np.diff(imu)) == {20_000_000} and set(np.diff(ahrs)) == {20_000_000}, (model, scene_rate)
            assert device.take_notes() == []


def test_a_rate_the_scene_cannot_give_is_said_and_divisor_zero_is_off():
    device = VectorNavDevice(100.0)
    replay(device, [("VNWRG,75,3,1,01,0001", "VNWRG,75,3,1,01,0001")])     # 800 Hz asked of a 100 Hz scene
    (note,) = device.take_notes()
    assert "800 Hz asked" in note and "100 Hz" in note
    samples = Samples(np.arange(10, dtype=np.int64) * 10_000_000, np.zeros((10, 3)), np.zeros((10, 3)))
    assert len(split(stream(device, samples), bytes([1]) + struct.pack("<H", 1), "<Q")) == 10
    replay(device, [("VNWRG,75,3,0,01,0001", "VNWRG,75,3,0,01,0001")])     # divisor 0: off
    assert stream(device, samples) == b""
    assert device.receive(command("VNRRG,75")) == [command("VNRRG,75,3,0,01,0001")]


@pytest.mark.parametrize("fields", ["common:insstatus", "ins:insstatus"])
def test_ins_status_follows_the_filter_mode_and_the_fix(fields):
    """InsStatus bits 0-1 the mode (0 not tracking, 1 aligning, 2 tracking), bit 2 the GNSS fix (3D)."""
    n = 4
    samples = Samples(np.arange(n, dtype=np.int64), np.zeros((n, 3)), np.zeros((n, 3)),
                      ins_mode=[0, 1, 2, 2], gnss_fix=[0, 2, 3, 0])
    device = VectorNavDevice(RATE, fields=fields)
    header = bytes([0x01 if fields.startswith("common") else 0x20]) + struct.pack("<H", 0x1000 if "common" in fields
                                                                                 else 0x0001)
    assert [r[0] for r in split(stream(device, samples), header, "<H")] == [0x0000, 0x0001, 0x0006, 0x0002]
    # without either in the samples: tracking, and the fix the device's `gnss_fix` option states
    bare = Samples(np.arange(2, dtype=np.int64), np.zeros((2, 3)), np.zeros((2, 3)))
    assert [r[0] for r in split(stream(VectorNavDevice(RATE, fields=fields), bare), header, "<H")] == [6, 6]
    lost = VectorNavDevice(RATE, fields=fields + ";time:timestatus", gnss_fix=0)
    time_mask = struct.pack("<H", 0x0200)                                   # Time group (bit 1), TimeStatus
    masks = header[1:3] + time_mask if fields.startswith("common") else time_mask + header[1:3]
    fmt = "<HB" if fields.startswith("common") else "<BH"
    rows = split(stream(lost, bare), bytes([header[0] | 0x02]) + masks, fmt)
    assert sorted(map(sorted, rows)) == [[0, 2], [0, 2]]         # mode 2 without the fix bit; no fix, no valid time


def test_attitude_and_ins_vectors_in_ned_ecef_and_body_axes():
    """Attitude MagNed, AccelNed, LinearAccelBody and INS MagEcef, LinearAccelEcef (the remaining rotated
    quantities) against scipy's Rotation and pymap3d; defaults apply for a block without the fields."""
    samples = truth(30)
    n = len(samples)
    samples.linear_accel_ned = np.random.default_rng(3).normal(0, 2, (n, 3))
    spec = "attitude:magned,accelned,linearaccelbody;ins:magecef,linearaccelecef"
    header = bytes([0x30]) + struct.pack("<2H", 0x0070, 0x0140)
    v = np.array(split(stream(VectorNavDevice(RATE, fields=spec), samples), header, "<15f"), dtype=np.float64)
    r, llh = rotation(samples, np.arange(n)), samples.position_llh
    np.testing.assert_allclose(v[:, 0:3], r.apply(samples.mag), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(v[:, 3:6], r.apply(samples.accel), rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(v[:, 6:9], r.inv().apply(samples.linear_accel_ned), rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(v[:, 9:12], ecef_vector(r.apply(samples.mag), llh), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(v[:, 12:15], ecef_vector(samples.linear_accel_ned, llh), rtol=1e-6, atol=1e-5)
    # nothing but accel and gyro: identity attitude, zero field and linear acceleration, PX4's home
    bare = Samples([0], [[1.0, 2.0, -9.0]], [[0.0, 0.0, 0.0]])
    (row,) = split(stream(VectorNavDevice(RATE, fields=spec), bare), header, "<15f")
    home = np.array([[47.397742, 8.545594, 488.0]])
    np.testing.assert_allclose(row[3:6], [1.0, 2.0, -9.0], rtol=1e-7)
    assert row[0:3] == row[6:9] == row[9:12] == row[12:15] == (0.0, 0.0, 0.0)
    assert np.isfinite(home).all()


def test_integer_time_fields_saturate_and_count_and_status_follows_the_fix():
    """TimeUtc's int8 year beyond 2127 and SyncInCnt beyond 2^32 seconds saturate (counted per wire field);
    TimeStatus and GPS TimeInfo say 0 without any fix."""
    from firmware_protocols.wire_formats.vectornav_binary import BinaryDecoder, BinaryEncoder
    for retired in (lambda: BinaryEncoder("time:timeutc", gps_week_offset=2345),
                    lambda: VectorNavDevice(RATE, gps_week_offset=2345)):
        with pytest.raises(ValueError, match="gps_week_offset: retired.*--start-time"):
            retired()
    encoder = BinaryEncoder("time:timeutc,syncincnt,timestatus;gps:timeinfo")
    later = 5 * 10**18          # UTC 2128-06: TimeUtc's year - 2000 > 127, and 5e9 s > SyncInCnt's 2^32
    fields = BinaryDecoder().feed(encoder.encode(Samples([later], [[0, 0, 0]], [[0, 0, 0]], gnss_fix=[0])).data)
    f = fields[0].fields
    assert f["time.timeutc.year"] == 127 and f["time.syncincnt"] == 2**32 - 1
    assert f["time.timestatus"] == 0 and f["gps.timeinfo.status"] == 0 and f["gps.timeinfo.leapseconds"] == 18
    assert encoder.saturated.counts == {"time.timeutc": 1, "time.syncincnt": 1}


# PX4 src/drivers/ins/vectornav/VectorNav.cpp at 004d420324d12d4b2aeb42827c189fc4005dafee (vnproglib's C library,
# async mode PORT2): output 1 TimeStartup + IMU UncompAccel|UncompGyro, divider 1; output 2 divider 8: TimeStartup;
# IMU Temp, Pres, Mag; Attitude Quaternion, LinearAccelNed; INS InsStatus, PosLla, VelNed, PosU, VelU; output 3
# divider 80: TimeStartup; GPS Utc, NumSats, Fix, PosLla, VelNed, PosU, VelU, Dop. Each parsed by
# VnUartPacket_isCompatible (exact groups) and extracted in field order, as here.
PX4_SEQUENCE = [("VNRRG,01", "VNRRG,01,VN-300-CR"), ("VNWRG,05,921600", "VNWRG,05,921600"),
                ("VNRRG,01", "VNRRG,01,VN-300-CR"), ("VNRRG,02", "VNRRG,02,2"), ("VNRRG,03", "VNRRG,03,100012345"),
                ("VNRRG,04", "VNRRG,04,2.1.0.0"), ("VNWRG,06,0", "VNWRG,06,0"), ("VNRRG,35", "VNRRG,35,1,1,1,1"),
                ("VNWRG,35,1,0,1,1", "VNWRG,35,1,0,1,1"), ("VNRRG,35", "VNRRG,35,1,0,1,1"),
                ("VNWRG,75,2,1,6,1,C", "VNWRG,75,2,1,6,1,C"), ("VNWRG,76,2,8,36,1,130,84,613",
                                                               "VNWRG,76,2,8,36,1,130,84,613"),
                ("VNWRG,77,2,80,A,1,26B9", "VNWRG,77,2,80,A,1,26B9")]


def test_px4_configures_its_three_outputs_and_parses_them_to_the_truth():
    device = VectorNavDevice(800.0, model="VN-300-CR")
    replay(device, PX4_SEQUENCE)
    n = 1600
    samples = truth(n)
    samples.time_ns = np.arange(n, dtype=np.int64) * 1_250_000
    samples.linear_accel_ned = np.random.default_rng(8).normal(0, 1, (n, 3))
    data = stream(device, samples)
    out1 = split(data, bytes([0x06]) + struct.pack("<2H", 0x0001, 0x000C), "<Q3f3f")
    out2 = split(data, bytes([0x36]) + struct.pack("<4H", 0x0001, 0x0130, 0x0084, 0x0613), "<Qff3f4f3fH3d3fff")
    out3 = split(data, bytes([0x0A]) + struct.pack("<2H", 0x0001, 0x26B9), "<QbBBBBBHBB3d3f3ff7f")
    # a VN-300's 400 Hz IMU: / 1, / 8, / 80 = 400, 50 and 5 Hz, from an 800 Hz scene
    assert (len(out1), len(out2), len(out3)) == (n // 2, n // 16, n // 160)
    v1 = np.array(out1, dtype=np.float64)
    k1 = (v1[:, 0] / 1_250_000).astype(int)
    np.testing.assert_array_equal(v1[:, 1:4], f32(samples.accel[k1]))
    np.testing.assert_array_equal(v1[:, 4:7], f32(samples.gyro[k1]))
    v2 = np.array(out2, dtype=np.float64)
    k2 = (v2[:, 0] / 1_250_000).astype(int)
    np.testing.assert_array_equal(v2[:, 1], f32(samples.temperature_c[k2]))
    np.testing.assert_array_equal(v2[:, 2] * 1000, f32(samples.pressure_pa[k2] / 1000) * 1000)   # kPa -> Pa
    q = v2[:, 6:10]                                                     # x, y, z, w -> PX4's w, x, y, z
    np.testing.assert_array_equal(np.column_stack((q[:, 3], q[:, :3])), f32(samples.quat[k2]))
    np.testing.assert_array_equal(v2[:, 10:13], f32(samples.linear_accel_ned[k2]))
    assert set(v2[:, 13].astype(int) & 0b11) == {0b10}                  # tracking: PX4 publishes the position
    np.testing.assert_array_equal(v2[:, 14:17], samples.position_llh[k2])
    v3 = np.array(out3, dtype=np.float64)
    k3 = (v3[:, 0] / 1_250_000).astype(int)
    assert set(v3[:, 8]) == {17} and set(v3[:, 9]) == {3}              # NumSats; Fix > 0: sensor_gps published
    np.testing.assert_array_equal(v3[:, 10:13], samples.gnss_llh[k3])
    np.testing.assert_array_equal(v3[:, 13:16], f32(samples.gnss_velocity_ned[k3]))
    np.testing.assert_array_equal(v3[:, 16:19], f32(np.tile([0.8, 0.8, 1.3], (len(k3), 1))))
    dop = v3[:, 20:27]                                                  # g, p, t, v, h, n, e: PX4 takes h, v
    np.testing.assert_allclose(dop[:, 0] ** 2, dop[:, 1] ** 2 + dop[:, 2] ** 2, rtol=1e-5)
    np.testing.assert_allclose(dop[:, 1] ** 2, dop[:, 3] ** 2 + dop[:, 4] ** 2, rtol=1e-5)
    assert device.stats.errors == 0
