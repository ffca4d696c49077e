"""The package's dependency rule (pyproject.toml [tool.importlinter], docs/architecture.md), checked by
import-linter, which counts imports made inside functions too."""
import shutil
import subprocess
import sys
from pathlib import Path
from tests.support.paths import REPO
from tests.support.timing import scaled

import pytest

pytestmark = pytest.mark.subprocess

ROOT = REPO
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(tree: Path) -> subprocess.CompletedProcess:
    # --no-cache: a cache from another tree (or another user) must not decide this check
    return subprocess.run([str(LINT), "--config", str(tree / "pyproject.toml"), "--no-cache"], cwd=tree,
                          env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(tree)}, capture_output=True, text=True,
                          timeout=scaled(300))


def test_imports_keep_the_contract():
    result = _lint(ROOT)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert "0 broken" in result.stdout


def test_a_back_edge_inside_a_function_breaks_the_contract(tmp_path):
    """The contract has teeth: a leaf (geo) importing a command, inside a function, is refused."""
    for part in ("imu_emulator", "firmware_protocols"):
        shutil.copytree(ROOT / part, tmp_path / part, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    wgs84 = tmp_path / "imu_emulator" / "geo" / "wgs84.py"
    wgs84.write_text(wgs84.read_text() + "\n\ndef _back_edge():\n    from imu_emulator.commands import check\n")
    result = _lint(tmp_path)
    assert result.returncode != 0
    assert "imu_emulator.geo.wgs84 -> imu_emulator.commands.check" in result.stdout
