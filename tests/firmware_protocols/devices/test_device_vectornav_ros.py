"""The VectorNav ROS 1 and ROS 2 nodes' start-ups over a pty against the streaming emulator (the sequences and
packet layouts of test_vectornav_drivers, which cites the driver sources): every command answered as vnproglib
accepts it, then packets whose fields equal the scene's truth (float32 rounding): accel and gyro from the same
scene computed here, position from the scene's truth through pymap3d, ECEF and body quantities from the decoded
position and attitude with pymap3d and scipy, times consistent with one another."""
import datetime

import pytest
import numpy as np
import pymap3d
from scipy.spatial.transform import Rotation

from tests.firmware_protocols.devices.test_device_vectornav import Driver
from tests.support.stream import Emulator, reference, write_scene
from tests.firmware_protocols.devices.test_vectornav_drivers import (ROS1_HEADER, ROS1_STRUCT, ROS2_CONFIG, ROS2_HEADER, ROS2_STRUCT,
                                    ROS2_VN300_READS, WEEK, WEEK_START, ecef_vector, identity, split)

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

WEEK_NS = 7 * 86400 * 10**9


def scene_llh(scene_path, k):
    from imu_emulator.geo.geodesy import DEFAULT_ORIGIN
    from imu_emulator.runtime.simulation import Simulation
    from imu_emulator.scene.load import load_scene
    truth = Simulation(load_scene(scene_path), truth=True).block(0, int(k.max()) + 1).truth
    east, north, up = truth["position"][k].T           # the test scene is ENU
    return np.column_stack(pymap3d.enu2geodetic(east, north, up, *DEFAULT_ORIGIN))


def run(tmp_path, model: str, exchange, seconds: float = 2.0):
    rate = 400
    scene_path = write_scene(tmp_path, rate=rate, duration=60.0)
    with Emulator(scene_path, "--format", "vectornav-binary", "--to", "pty", "--duration", "40",
                  "--option", f"model={model}", "--start-time", WEEK_START) as emu:
        driver = Driver(emu.targets[0])
        after = driver.replay(exchange, then_read=seconds)
        driver.close()
        code, err = emu.interrupt()
    assert code == 0, err
    assert f"device: {len(exchange)} commands answered, 0 error replies" in err
    return scene_path, rate, after


def test_ros1_node_over_a_pty(tmp_path):
    model = "VN-200T-CR"
    exchange = ([("VNRRG,01", f"VNRRG,01,{model}"), ("VNWRG,05,115200", "VNWRG,05,115200"),
                 ("VNRRG,01", f"VNRRG,01,{model}")] + identity(model)
                + [("VNRRG,01", f"VNRRG,01,{model}"), ("VNWRG,06,0", "VNWRG,06,0"),
                   ("VNWRG,75,1,20,33,578,4C,100,69F", "VNWRG,75,1,20,33,578,4C,100,69F")])
    scene_path, rate, after = run(tmp_path, model, exchange)
    start = after.find(b"\xfa" + ROS1_HEADER)
    rows = split(after[start:], ROS1_HEADER, ROS1_STRUCT)
    assert len(rows) >= 40                                  # 800 / 20 = 40 Hz for 2 s
    v = np.array([r[:23] + r[30:] for r in rows], dtype=np.float64)       # without TimeUtc's integers
    gps = v[:, 21].astype(np.int64) + v[:, 22].astype(np.int64) * WEEK_NS
    assert set(v[:, 22]) == {WEEK} and set(np.diff(gps)) == {25_000_000}
    k = np.rint((gps - WEEK * WEEK_NS) * 1e-9 * rate).astype(int)
    _, _, accel, gyro = reference(scene_path)
    np.testing.assert_array_equal(v[:, 7:10], gyro[k].astype(np.float32))
    np.testing.assert_array_equal(v[:, 13:16], accel[k].astype(np.float32))
    llh = v[:, 10:13]
    np.testing.assert_allclose(llh, scene_llh(scene_path, k), rtol=0, atol=1e-8)
    for row, g in zip(rows, gps):                            # TimeUtc: the GPS time less 18 leap seconds
        when = datetime.datetime(1980, 1, 6) + datetime.timedelta(microseconds=int(g) // 1000, seconds=-18)
        assert row[23:30] == (when.year - 2000, when.month, when.day, when.hour, when.minute, when.second,
                              when.microsecond // 1000)
    wire = Rotation.from_quat(v[:, 3:7])
    ins = v[:, 26:]                                          # InsStatus, PosLla, PosEcef, VelBody, VelNed, AccelEcef
    assert set(ins[:, 0]) == {0x0006}
    np.testing.assert_array_equal(ins[:, 1:4], llh)
    np.testing.assert_allclose(ins[:, 4:7], np.column_stack(pymap3d.geodetic2ecef(*llh.T)), rtol=0, atol=1e-6)
    np.testing.assert_allclose(ins[:, 7:10], wire.inv().apply(ins[:, 10:13]), atol=1e-5)
    np.testing.assert_allclose(ins[:, 13:16], ecef_vector(wire.apply(v[:, 13:16]), llh), atol=1e-4)


def test_ros2_node_over_a_pty(tmp_path):
    model = "VN-300-CR"
    exchange = ([("VNRRG,01", f"VNRRG,01,{model}"), ("VNRRG,01", f"VNRRG,01,{model}")] + identity(model)
                + [("VNRRG,00", "VNRRG,00,")] + ROS2_CONFIG + ROS2_VN300_READS)
    scene_path, rate, after = run(tmp_path, model, exchange, seconds=2.5)
    start = after.find(b"\xfa" + ROS2_HEADER)
    rows = split(after[start:], ROS2_HEADER, ROS2_STRUCT)
    assert len(rows) >= 20                                  # 400 / 40 = 10 Hz for 2.5 s
    v = np.array(rows, dtype=np.float64)
    t = v[:, 0].astype(np.int64)
    assert set(np.diff(t)) == {100_000_000}
    # TimeStartup counts from the run's start, which --start-time puts at GPS week WEEK's start
    np.testing.assert_array_equal(v[:, 1], t + WEEK * WEEK_NS)
    np.testing.assert_array_equal(v[:, 2], t % 10**9)                   # TimeSyncIn
    np.testing.assert_array_equal(v[:, 41], t // 10**9)                 # SyncInCnt
    np.testing.assert_array_equal(v[:, 42], t % 10**9)                  # TimeGpsPps
    k = np.rint(t * 1e-9 * rate).astype(int)
    _, _, accel, gyro = reference(scene_path)
    np.testing.assert_array_equal(v[:, 10:13], gyro[k].astype(np.float32))
    np.testing.assert_array_equal(v[:, 19:22], accel[k].astype(np.float32))
    llh = v[:, 13:16]
    np.testing.assert_allclose(llh, scene_llh(scene_path, k), rtol=0, atol=1e-8)
    assert set(v[:, 40]) == {0x0006} and set(v[:, 43]) == {3}
    np.testing.assert_allclose(v[:, 47:50], np.column_stack(pymap3d.geodetic2ecef(*llh.T)), rtol=0, atol=1e-6)
    np.testing.assert_allclose(v[:, 50:53], Rotation.from_quat(v[:, 6:10]).inv().apply(v[:, 16:19]), atol=1e-5)
    # DeltaTheta: 40 samples' increments since the previous packet
    np.testing.assert_allclose(v[1:, 33], 40 / rate, rtol=1e-6)
