"""A cold cache compiles a kernel once: compile_kernel compiles in a staging directory, publishes it by renaming
the directory (numba's index and data move with it, keyed by the source file's name, size and mtime, which a
rename keeps), then imports from the published path. numba's own cache log (NUMBA_DEBUG_CACHE) is the witness:
one "data saved" in the cold process and none in a warm one, which loads the published entry instead."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RUN = ("from imu_emulator import load_scene\n"
       "from imu_emulator.simulation import Simulation\n"
       "Simulation(load_scene('examples/circle.toml'), attitude=False).block(0, 10)\n")


def _cache_log(cache: Path) -> str:
    env = {**os.environ, "IMU_EMULATOR_CACHE": str(cache), "NUMBA_DEBUG_CACHE": "1"}
    done = subprocess.run([sys.executable, "-c", RUN], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600, check=True)
    return "\n".join(line for line in done.stdout.splitlines() if "kernel.kernel-" in line)


def test_a_cold_cache_compiles_the_kernel_once_and_a_warm_one_never(tmp_path):
    cold = _cache_log(tmp_path)
    assert cold.count("data saved to") == 1, cold
    published = [p for p in (tmp_path / "kernels").iterdir() if not p.name.startswith(".")]
    assert len(published) == 1 and f"data loaded from '{published[0]}" in cold, cold
    warm = _cache_log(tmp_path)
    assert "data saved to" not in warm and f"data loaded from '{published[0]}" in warm, warm
