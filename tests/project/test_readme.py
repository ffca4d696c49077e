"""The README and the docs site's pages are what a new user runs first: every ```python block of the README and of
docs/*.md runs as written (each in a fresh interpreter, from the repository root), and every shell command of a
block showing `imu-emulator generate` (the main job, in the README and in the site's getting-started page) runs
exactly as written, the main job producing the file the README describes, with values checked against the
independent sympy oracle."""
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
PAGES = {path.relative_to(REPO).as_posix(): path.read_text() for path in [REPO / "README.md",
                                                                           *sorted((REPO / "docs").rglob("*.md"))]}
# The pages that show the main job: the README and the site's first page after the home page.
MAIN_JOB_PAGES = ["README.md", "docs/getting-started.md"]


def _blocks(language: str, text: str = README) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", text, re.S | re.M)


PYTHON_BLOCKS = _blocks("python")
ALL_PYTHON_BLOCKS = [(page, block) for page, text in PAGES.items() for block in _blocks("python", text)]


def test_readme_has_the_python_blocks_this_test_runs():
    assert len(PYTHON_BLOCKS) >= 2
    assert any("imu.simulate(" in block and "imu.Simulation(" in block for block in PYTHON_BLOCKS)
    assert {page for page, _ in ALL_PYTHON_BLOCKS} >= {"README.md", "docs/getting-started.md", "docs/api.md"}


@pytest.mark.parametrize("page,block", ALL_PYTHON_BLOCKS,
                         ids=lambda b: b if b in PAGES else b.strip().splitlines()[-1][:40])
def test_python_block_runs_in_a_fresh_interpreter(page, block):
    result = subprocess.run([sys.executable, "-c", block], capture_output=True, text=True, cwd=REPO, timeout=scaled(300))
    assert result.returncode == 0, result.stderr
    assert "Warning" not in result.stderr, result.stderr


def _main_job_commands(page: str) -> list[str]:
    blocks = [b for b in _blocks("sh", PAGES[page]) if "imu-emulator generate" in b]
    assert blocks, f"{page} no longer shows the main job"
    lines = [line.split("#")[0].strip() for block in blocks for line in block.splitlines()]
    return [line for line in lines if line]


@pytest.mark.parametrize("page", MAIN_JOB_PAGES)
def test_main_job_runs_as_written_and_gives_the_described_file(page, tmp_path):
    # The commands run in a directory laid out like the repository (its .venv and examples), so they
    # can be run exactly as written without writing into the checkout.
    venv = REPO / ".venv" if (REPO / ".venv" / "bin" / "imu-emulator").exists() else Path(sys.prefix)
    assert (venv / "bin" / "imu-emulator").exists(), f"no imu-emulator script in {venv}"
    (tmp_path / ".venv").symlink_to(venv)
    (tmp_path / "examples").symlink_to(REPO / "examples")
    commands = _main_job_commands(page)
    for command in commands:
        result = subprocess.run(command, shell=True, capture_output=True, text=True, cwd=tmp_path, timeout=scaled(300))
        assert result.returncode == 0, f"{command}: {result.stderr}"
        assert "Traceback" not in result.stderr and "Warning" not in result.stderr, result.stderr
    main = [shlex.split(c) for c in commands if shlex.split(c)[1:3] == ["generate", "examples/helix.toml"]]
    assert len(main) == 1, f"{page}: the main job, generate examples/helix.toml, is shown once"
    output = tmp_path / main[0][main[0].index("-o") + 1]
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
