"""Attitude on the wire is the part's forward-right-down body w.r.t. NED whatever the scene's frame (issue 24):
the emulator streams a VectorNav packet with Quaternion (VectorNav's attitude is "the body frame with respect to
the local North East Down (NED) frame", UM001 §4.4.4) into a capture file, from an ENU scene (forward-left-up body)
and from a NED scene; scipy's Rotation gives what the packet must carry from the scene's own attitude. This test
once pinned the upside-down behaviour (reference converted, body axes left forward-left-up)."""
import binascii
import struct

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.support.stream import reference, run_emulator, write_scene

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

HEADER = bytes([0x01, 0x11, 0x00])      # Common group: TimeStartup, Quaternion
SIZE = 1 + 3 + 8 + 16 + 2
# NED coordinates of ENU vectors: north = y, east = x, down = -z
NED_FROM_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
# forward-left-up coordinates of forward-right-down vectors (and back): the half turn about x
FLU_FROM_FRD = np.diag([1.0, -1.0, -1.0])


def _stream(tmp_path, scene_path, n):
    out = tmp_path / "vn.bin"
    result = run_emulator(scene_path, "--format", "vectornav-binary", "--to", f"file:{out}", "--speed", "0",
                          "--count", n, "--option", "fields=common:timestartup,quaternion")
    assert result.returncode == 0, result.stderr
    data = out.read_bytes()
    packets = [data[i:i + SIZE] for i in range(0, len(data), SIZE)]
    assert len(packets) == n
    assert all(p[:4] == b"\xfa" + HEADER and binascii.crc_hqx(p[1:], 0) == 0 for p in packets)
    return np.array([struct.unpack_from("<4f", p, 12) for p in packets])       # x, y, z, w


def _scene_attitude(scene_path, n):
    from imu_emulator.scene.load import load_scene
    from imu_emulator.runtime.simulation import Simulation
    block = Simulation(load_scene(scene_path)).block(0, n)
    return Rotation.from_quat(block.quat[0][:, [1, 2, 3, 0]])


@pytest.mark.parametrize("frame", ["ENU", "NED"])
def test_quaternion_on_the_wire_is_the_frd_body_referenced_to_ned(tmp_path, frame):
    n = 200
    scene_path = write_scene(tmp_path, rate=200, duration=5.0)
    if frame == "NED":
        text = scene_path.read_text().replace("[scene]\n", '[scene]\nframe = "NED"\n', 1)
        scene_path.write_text(text)
    wire = Rotation.from_quat(_stream(tmp_path, scene_path, n))
    scene = _scene_attitude(scene_path, n)
    want = Rotation.from_matrix(NED_FROM_ENU) * scene * Rotation.from_matrix(FLU_FROM_FRD) if frame == "ENU" else scene
    # float32 on the wire: a few 1e-7 rad
    assert np.all((want.inv() * wire).magnitude() < 1e-6)
    # What a reader does with it: the FRD specific force (what every FRD wire carries, as reference() gives it)
    # rotated by the wire attitude is the NED specific force; the scene's circle is level, so its down component
    # is -g (standard gravity, 9.80665)
    _, _, accel, _ = reference(scene_path)
    down = wire.apply(accel[:n])[:, 2]
    np.testing.assert_allclose(down, -9.80665, atol=1e-4)      # float32 quaternion: ~1e-6 relative
