"""A warm `generate` (its kernel in the cache) of a scene written with datasheet units imports nothing heavy
(issue 25): no pint (and through it dask, babel), no numba (the kernel and CSV's loops run as machine code,
imu_emulator.native), no sympy (the kernel's source is not generated again), no pandas, matplotlib or scipy.
Counted in a fresh interpreter's sys.modules at the end of the run; the cold run before it fills the cache."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.paths import REPO
from tests.support.timing import scaled

pytestmark = pytest.mark.subprocess

ROOT = REPO
HEAVY = ("pint", "dask", "distributed", "babel", "pandas", "matplotlib", "sympy", "numba", "scipy")
SCENE = """
[scene]
rate_hz = 200
duration_s = 2.0
frame = "NED"
seed = 1
[trajectory]
shape = "circle"
radius_m = 5.0
frequency_hz = 0.2
[attitude]
mode = "tangent"
[[imu]]
name = "imu0"
mounting_rpy_deg = ["0.5 deg", 0, "90 degrees"]
[imu.gyro]
arw = "0.25 deg/sqrt(h)"
bias = ["0.1 dps", "36 dph", 0]
[imu.accel]
noise_density = "120 ug/rt-Hz"
bias = "2 mg"
[effects]
gravity = true
mounting = true
noise = true
bias = true
"""
PROBE = """
import json, sys
from imu_emulator.cli import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "modules": sorted(sys.modules)}))
"""


def _generate(scene: Path, out: Path, cache: Path, native: bool = True) -> dict:
    env = {**os.environ, "IMU_EMULATOR_CACHE": str(cache), "PYTHONPATH": str(ROOT),
           "IMU_EMULATOR_NATIVE": "1" if native else "0"}
    done = subprocess.run([sys.executable, "-c", PROBE, "generate", str(scene), "-o", str(out), "--quiet"],
                          env=env, capture_output=True, text=True, timeout=scaled(900), cwd=ROOT)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["code"] in (0, None), done.stderr
    return result


def test_warm_generate_with_unit_strings_imports_nothing_heavy(tmp_path):
    scene = tmp_path / "units.toml"
    scene.write_text(SCENE)
    cold = _generate(scene, tmp_path / "cold.csv", tmp_path / "cache")
    warm = _generate(scene, tmp_path / "warm.csv", tmp_path / "cache")
    assert "numba" in cold["modules"]              # the probe sees a heavy import when there is one
    heavy = [name for name in HEAVY if name in warm["modules"]]
    assert not heavy, f"a warm generate imported {heavy}"
    # 35a2177 imported 1028 modules here (pint, dask, babel, scipy, numba); without them about 350
    assert len(warm["modules"]) < 600, len(warm["modules"])
    # numba's dispatchers (CSV's loops with their memcpy intrinsic realized by imu_emulator.native.lazy) write
    # the same bytes as the machine code
    dispatcher = _generate(scene, tmp_path / "numba.csv", tmp_path / "cache", native=False)
    assert "numba" in dispatcher["modules"]
    warm_bytes = (tmp_path / "warm.csv").read_bytes()
    rows = [line for line in warm_bytes.split(b"\n") if line and not line.startswith(b"#")]
    assert len(rows) == 401                         # header and 2 s at 200 Hz (the # lines state frame and units)
    assert warm_bytes == (tmp_path / "cold.csv").read_bytes() == (tmp_path / "numba.csv").read_bytes()
