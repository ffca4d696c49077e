"""tools/relative_orientation.py recovers the mounting rotation and lever arm the scene put in."""
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_emulator import scene_from_dict
from imu_emulator.simulation import Simulation

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
from relative_orientation import estimate, main  # noqa: E402

MOUNT_B = [12.0, -7.5, 95.0]
LEVER_A, LEVER_B = np.array([0.05, 0.02, -0.01]), np.array([-0.2, 0.15, 0.04])


def two_imu_run():
    scene = scene_from_dict({
        "scene": {"rate_hz": 500, "duration_s": 6.0},
        "trajectory": {"x": "3*cos(pi*t)", "y": "2*sin(pi*t)", "z": "0.5*sin(0.6*pi*t)"},
        "attitude": {"mode": "euler", "roll": "0.4*sin(1.4*pi*t)", "pitch": "0.3*cos(0.8*pi*t)", "yaw": "0.5*t"},
        "imu": [{"name": "a", "lever_arm_m": list(LEVER_A)},
                {"name": "b", "lever_arm_m": list(LEVER_B), "mounting_rpy_deg": MOUNT_B}],
        "effects": {"gravity": True, "lever_arm": True, "mounting": True}})
    return scene, Simulation(scene).run()


def test_recovers_mounting_and_lever_arm():
    scene, out = two_imu_run()
    result = estimate(out.accel[0], out.gyro[0], out.accel[1], out.gyro[1], scene.dt)
    # A is mounted like the body, so C (B sensor -> A sensor) is B's mounting matrix.
    expected = Rotation.from_euler("ZYX", MOUNT_B[::-1], degrees=True).as_matrix()
    angle = Rotation.from_matrix(result.C @ expected.T).magnitude()
    assert np.degrees(angle) < 1e-4
    np.testing.assert_allclose(result.lever_m, LEVER_A - LEVER_B, atol=1e-4)


def test_cli_prints_the_angles(tmp_path, capsys):
    scene, out = two_imu_run()
    path = tmp_path / "run.npz"
    np.savez(path, t=out.t_s, imu_names=np.array(["a", "b"]), accel=out.accel, gyro=out.gyro)
    assert main([str(path), "--a", "a", "--b", "b"]) == 0
    text = capsys.readouterr().out
    angles = [float(re.search(rf"{name} (-?[0-9.]+) deg", text).group(1)) for name in ("roll", "pitch", "yaw")]
    np.testing.assert_allclose(angles, MOUNT_B, atol=1e-4)
    assert main([str(path), "--a", "a", "--b", "zzz"]) == 2


def test_mismatched_inputs_are_refused():
    with pytest.raises(ValueError, match="same number"):
        estimate(np.zeros((5, 3)), np.zeros((5, 3)), np.zeros((4, 3)), np.zeros((4, 3)), 0.01)
