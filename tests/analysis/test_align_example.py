"""examples/align_two_imus.toml run as the README documents it (generate, then align on the one CSV): align
recovers the mounting rotation, time offset and lever arm the scene gives imu1, with every quantity observable.

Oracle: the scene file itself (read here with tomllib): C is imu1's mounting_rpy_deg as a z-y-x rotation (scipy),
t_B - t_A its time_offset_s, the lever arm its lever_arm_m (imu0 sits at the body's origin, unrotated).
Tolerances: the scene has BMI088-class white noise (seed 7), so each error is held within 5 of the 1-sigma that
align reports (those sigma match the scatter of estimates over noise seeds:
tests/analysis/test_alignment.py::test_reported_sigma_matches_the_scatter_of_noisy_estimates). For a Gaussian estimate,
|error| > 5 sigma has probability 6e-7 per component; the rotation error's length is held within 5 times the
largest direction's sigma (chi with 3 degrees of freedom beyond 5: probability 2e-5). The error must also meet
issue 12's goals, which tools/bench_align.py's 20 noise seeds of the same motion meet (README table, case b):
rotation 0.02 deg, time offset 0.1 ms, lever arm 5 mm.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from imu_emulator.scene.load import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.support.paths import REPO

EXAMPLE = REPO / "examples" / "align_two_imus.toml"

pytestmark = [pytest.mark.slow, pytest.mark.subprocess]      # a 60 s two-IMU run and the fit with the lever arm: about 10 s


def _cli(*args, cwd) -> str:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-m", "imu_emulator", *args], capture_output=True, text=True, cwd=cwd,
                         env=env)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_align_recovers_the_example_scenes_rotation_time_offset_and_lever_arm(tmp_path):
    scene = tomllib.loads(EXAMPLE.read_text())
    imu_a, imu_b = scene["imu"]
    assert "mounting_rpy_deg" not in imu_a and "lever_arm_m" not in imu_a and "time_offset_s" not in imu_a
    _cli("generate", str(EXAMPLE), "-o", "align.csv", cwd=tmp_path)
    report = _cli("align", "align.csv", "align.csv", "--imu-a", imu_a["name"], "--imu-b", imu_b["name"],
                  "--lever-arm", "--json", "align.json", cwd=tmp_path)
    assert "unobservable" not in report
    result = json.loads((tmp_path / "align.json").read_text())
    assert result["unobservable_reasons"] == []
    obs = result["observable"]
    assert all(obs[k] for k in ("roll", "pitch", "yaw", "time_offset_s")) and all(obs["lever_arm_m"])
    sigma = result["sigma"]

    roll, pitch, yaw = imu_b["mounting_rpy_deg"]
    truth = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True)
    got = Rotation.from_matrix(np.array(result["dcm"]))
    rotation_error_deg = math.degrees((got * truth.inv()).magnitude())
    assert rotation_error_deg <= min(5 * sigma["rotation_deg"], 0.02)

    offset_error_s = abs(result["time_offset_s"] - imu_b["time_offset_s"])
    assert offset_error_s <= min(5 * sigma["time_offset_s"], 1e-4)

    lever_error_m = np.abs(np.array(result["lever_arm_m"]) - imu_b["lever_arm_m"])
    assert np.all(lever_error_m <= np.minimum(5 * np.array(sigma["lever_arm_m"]), 5e-3))
