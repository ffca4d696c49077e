"""The release as a user gets it: `python -m build` makes an sdist and a wheel from it, the wheel installs into a
fresh venv with pip alone, and the installed `imu-emulator` runs its main job on a scene the test writes.

Oracles: the version is pyproject.toml's (read here with tomllib, the one place it is written); the wheel's
package data is compared with the source tree's files; the generated values are closed forms of a level circle
(specific force -g on the down axis and R*w^2 toward the centre, angular rate w about the down axis), and the
magnetometer's field strength is pygeomag's WMM2025 (called here, in the test's own environment) at the origin.

Slow (a build in an isolated environment and a venv with numba, scipy, pyarrow: about a minute with pip's cache
warm; pip may use the network). IMU_EMULATOR_WHEEL_PYTHONS (paths joined by os.pathsep) names the interpreters
whose fresh venvs get the wheel; the default is the one running the tests.
"""
from __future__ import annotations

import csv
import math
import os
import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

from imu_emulator.scene.load import tomllib

from tests.support.paths import REPO

PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
VERSION = PYPROJECT["project"]["version"]
PYTHONS = [p for p in os.environ.get("IMU_EMULATOR_WHEEL_PYTHONS", sys.executable).split(os.pathsep) if p]

pytestmark = [pytest.mark.slow, pytest.mark.subprocess]

RADIUS_M, FREQUENCY_HZ, GRAVITY = 20.0, 0.1, 9.80665
ORIGIN = (47.397742, 8.545594, 488.0)
HEIGHT_M = 30.0            # above the origin (NED: height_m = -30)
SCENE = f"""
[scene]
rate_hz = 100
duration_s = 4.0
frame = "NED"
gravity_mps2 = {GRAVITY!r}
origin = {{ lat_deg = {ORIGIN[0]!r}, lon_deg = {ORIGIN[1]!r}, height_m = {ORIGIN[2]!r} }}

[trajectory]
shape = "circle"
radius_m = {RADIUS_M!r}
frequency_hz = {FREQUENCY_HZ!r}
height_m = {-HEIGHT_M!r}

[attitude]
mode = "tangent"

[[imu]]
name = "imu0"
model = "bosch-bmi088"          # a preset: package data the wheel must carry
[imu.magnetometer]
rate_hz = 50

[effects]
gravity = true
"""


def _run(cmd, **kwargs) -> subprocess.CompletedProcess:
    out = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kwargs)
    assert out.returncode == 0, f"{cmd} exited {out.returncode}:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
    return out


@pytest.fixture(scope="module")
def dist(tmp_path_factory) -> Path:
    """The sdist and the wheel built from it, made from a copy of the source tree (setuptools leaves an
    egg-info behind in the tree it builds)."""
    root = tmp_path_factory.mktemp("dist")
    source = root / "source"
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(".git", ".venv", "__pycache__", "build", "dist",
                                                                "*.egg-info", ".pytest_cache", ".hypothesis"))
    _run([sys.executable, "-m", "build", "--outdir", root / "out", source])
    return root / "out"


def test_sdist_and_wheel_are_named_by_the_one_version_and_carry_the_licence_and_package_data(dist):
    wheels = list(dist.glob("*.whl"))
    assert [w.name for w in wheels] == [f"imu_emulator-{VERSION}-py3-none-any.whl"]
    assert [s.name for s in dist.glob("*.tar.gz")] == [f"imu_emulator-{VERSION}.tar.gz"]
    names = set(zipfile.ZipFile(wheels[0]).namelist())
    presets = {f"imu_emulator/scene/presets/{p.name}" for p in (REPO / "imu_emulator/scene/presets").glob("*.toml")}
    assert presets and presets <= names
    info = f"imu_emulator-{VERSION}.dist-info"
    license_text = zipfile.ZipFile(wheels[0]).read(f"{info}/licenses/LICENSE").decode()
    assert license_text == (REPO / "LICENSE").read_text()
    metadata = zipfile.ZipFile(wheels[0]).read(f"{info}/METADATA").decode()
    assert "License-Expression: Apache-2.0" in metadata.splitlines()
    assert not any(n.startswith("tests/") for n in names)
    sdist = tarfile.open(next(dist.glob("*.tar.gz")))
    top = f"imu_emulator-{VERSION}/"
    members = {m.name.removeprefix(top) for m in sdist.getmembers()}
    examples = {f"examples/{p.name}" for p in (REPO / "examples").glob("*.toml")}
    assert examples and examples <= members
    assert {"CHANGELOG.md", "LICENSE", "README.md", "install.sh", "pyproject.toml"} <= members
    assert not any(m.startswith("tests/") for m in members)


@pytest.mark.parametrize("python", PYTHONS)
def test_wheel_installs_into_a_fresh_venv_and_generates_the_closed_form(dist, python, tmp_path):
    venv = tmp_path / "venv"
    _run([python, "-m", "venv", venv])
    wheel = next(dist.glob("*.whl"))
    _run([venv / "bin/python", "-m", "pip", "install", "-q", "--disable-pip-version-check", wheel])
    # Out of the source tree, with a cache of its own: nothing may come from the checkout or an earlier run.
    env = {**os.environ, "IMU_EMULATOR_CACHE": str(tmp_path / "cache")}
    env.pop("PYTHONPATH", None)
    exe = venv / "bin/imu-emulator"
    assert _run([exe, "--version"], cwd=tmp_path, env=env).stdout.split() == ["imu-emulator", VERSION]
    (tmp_path / "circle.toml").write_text(SCENE)
    _run([exe, "generate", "circle.toml", "-o", "run.csv"], cwd=tmp_path, env=env)
    with open(tmp_path / "run.csv", newline="") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    assert len(rows) == 400
    col = {k: np.array([float(r[k]) for r in rows]) for k in ("ax", "ay", "az", "gx", "gy", "gz",
                                                                "mag_x", "mag_y", "mag_z")}
    w = 2 * math.pi * FREQUENCY_HZ
    # level body along the path (forward-right-down): no forward force, R w^2 sideways, -g on the down axis
    np.testing.assert_allclose(col["ax"], 0.0, atol=1e-9)
    np.testing.assert_allclose(np.abs(col["ay"]), RADIUS_M * w**2, rtol=1e-9)
    np.testing.assert_allclose(col["az"], -GRAVITY, rtol=1e-12)
    np.testing.assert_allclose(np.abs(col["gz"]), w, rtol=1e-9)
    np.testing.assert_allclose(np.hypot(col["gx"], col["gy"]), 0.0, atol=1e-12)
    # The field strength is the same in any axes. pygeomag's WMM2025 at the origin (the circle's 20 m change the
    # field by under 1 nT at its gradient of ~0.03 nT/m, hence the 2e-5 gauss = 2 nT tolerance).
    from pygeomag import GeoMag
    r = GeoMag(coefficients_file="wmm/WMM_2025.COF").calculate(
        glat=ORIGIN[0], glon=ORIGIN[1], alt=(ORIGIN[2] + HEIGHT_M) / 1000.0, time=2025.0)
    strength = np.linalg.norm(np.column_stack([col["mag_x"], col["mag_y"], col["mag_z"]]), axis=1)
    np.testing.assert_allclose(strength, math.hypot(r.x, r.y, r.z) / 1e5, atol=2e-5)
