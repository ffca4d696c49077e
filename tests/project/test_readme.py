"""The README is what a new user runs first: every ```python block runs as written (each in a fresh
interpreter, from the repository root), and the main job's shell commands run exactly as written and
produce the file the README describes, with values checked against the independent sympy oracle."""
import csv
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from tests.support.reference import imu_functions, t
from tests.support.paths import REPO
from tests.support.timing import scaled

pytestmark = pytest.mark.subprocess

README = (REPO / "README.md").read_text()


def _blocks(language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", README, re.S | re.M)


PYTHON_BLOCKS = _blocks("python")


def test_readme_has_the_python_blocks_this_test_runs():
    assert len(PYTHON_BLOCKS) >= 2
    assert any("imu.simulate(" in block and "imu.Simulation(" in block for block in PYTHON_BLOCKS)


@pytest.mark.parametrize("block", PYTHON_BLOCKS, ids=lambda b: b.strip().splitlines()[-1][:40])
def test_python_block_runs_in_a_fresh_interpreter(block):
    result = subprocess.run([sys.executable, "-c", block], capture_output=True, text=True, cwd=REPO, timeout=scaled(300))
    assert result.returncode == 0, result.stderr
    assert "Warning" not in result.stderr, result.stderr


def _main_job_commands() -> list[str]:
    blocks = [b for b in _blocks("sh") if "imu-emulator generate" in b]
    assert blocks, "the README no longer shows the main job"
    lines = [line.split("#")[0].strip() for block in blocks for line in block.splitlines()]
    return [line for line in lines if line]


def test_main_job_runs_as_written_and_gives_the_described_file(tmp_path):
    # The commands run in a directory laid out like the repository (its .venv and examples), so they
    # can be run exactly as written without writing into the checkout.
    venv = REPO / ".venv" if (REPO / ".venv" / "bin" / "imu-emulator").exists() else Path(sys.prefix)
    assert (venv / "bin" / "imu-emulator").exists(), f"no imu-emulator script in {venv}"
    (tmp_path / ".venv").symlink_to(venv)
    (tmp_path / "examples").symlink_to(REPO / "examples")
    commands = _main_job_commands()
    for command in commands:
        result = subprocess.run(command, shell=True, capture_output=True, text=True, cwd=tmp_path, timeout=scaled(300))
        assert result.returncode == 0, f"{command}: {result.stderr}"
        assert "Traceback" not in result.stderr and "Warning" not in result.stderr, result.stderr
    output = tmp_path / shlex.split(commands[-1])[shlex.split(commands[-1]).index("-o") + 1]
    with open(output, newline="") as f:
        rows = [r for r in csv.reader(f) if not r[0].startswith("#")]   # the frames and units statement
    # What the README says of helix.csv: this header, one row per IMU per sample, round(T·f) samples.
    assert rows[0] == "t,imu,ax,ay,az,gx,gy,gz".split(",")
    assert len(rows) - 1 == round(5.0 * 200)
    assert {r[1] for r in rows[1:]} == {"imu0"}
    values = np.array([[float(v) for v in (r[0], *r[2:])] for r in rows[1:]])
    # t = t0 + k/rate; to 1 ulp, as the CSV holds k*(1/rate) (0.20500000000000002 for k = 41)
    np.testing.assert_allclose(values[:, 0], np.arange(1000) / 200, rtol=1e-15, atol=0)
    # examples/helix.toml: the helix flown tangent to the path, IMU at lever arm (-0.075, -0.075, 0.025) m.
    helix = [0.8 * 5 * sp.cos(2 * sp.pi * t), 0.8 * 5 * sp.sin(2 * sp.pi * t), 0.3 * 5 * sp.cos(2 * sp.pi * t)]
    accel, gyro = imu_functions(helix, lever=(-0.075, -0.075, 0.025))(values[:, 0])
    # Both sides are float64 evaluations of the same closed form (|f| up to 162 m/s²): they agree to ~1e-13;
    # the bounds leave room for rounding, while any modelling error (a sign, a term) is 1e-3 or more.
    np.testing.assert_allclose(values[:, 1:4], accel, rtol=0, atol=1e-9)
    np.testing.assert_allclose(values[:, 4:7], gyro, rtol=0, atol=1e-11)
