"""A cold cache compiles a kernel once: compile_kernel compiles in a staging directory, publishes it by renaming
the directory (numba's index and data move with it, keyed by the source file's name, size and mtime, which a
rename keeps; the machine code kernel.o is written there before the rename), then loads from the published path.
numba's own cache log (NUMBA_DEBUG_CACHE) is the witness: one "data saved" in the cold process and none in a
warm one. A warm one loads the published entry: its machine code without importing numba, or (with
IMU_EMULATOR_NATIVE=0) numba's cache data."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
RUN = ("import sys\n"
       "from imu_emulator import load_scene\n"
       "from imu_emulator.runtime.simulation import Simulation\n"
       "Simulation(load_scene('examples/circle.toml'), attitude=False).block(0, 10)\n"
       "print('numba imported:', 'numba' in sys.modules)\n")


def _cache_log(cache: Path, native: bool) -> tuple[str, bool]:
    env = {**os.environ, "IMU_EMULATOR_CACHE": str(cache), "NUMBA_DEBUG_CACHE": "1",
           "IMU_EMULATOR_NATIVE": "1" if native else "0"}
    done = subprocess.run([sys.executable, "-c", RUN], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600, check=True)
    # the generated module's functions: kernel (numba's dispatcher) and kernel_body (what the machine code runs)
    log = "\n".join(line for line in done.stdout.splitlines() if "kernel.kernel" in line)
    return log, "numba imported: True" in done.stdout


@pytest.mark.parametrize("native", [True, False], ids=["machine-code", "numba"])
def test_a_cold_cache_compiles_the_kernel_once_and_a_warm_one_never(tmp_path, native):
    cold, _ = _cache_log(tmp_path, native)
    # each function saved once: kernel_body (exported as machine code), and on numba's path its wrapper kernel
    saved = [line.rsplit("/", 1)[-1].split(".py")[0].rsplit("-", 1)[0]
             for line in cold.splitlines() if "data saved to" in line]
    assert sorted(saved) == (["kernel.kernel_body"] if native else ["kernel.kernel", "kernel.kernel_body"]), cold
    published = [p for p in (tmp_path / "kernels").iterdir() if not p.name.startswith(".")]
    assert len(published) == 1, published
    warm, numba_imported = _cache_log(tmp_path, native)
    assert "data saved to" not in warm, warm
    if native:
        assert (published[0] / "kernel.o").exists() and not numba_imported, warm
    else:
        assert f"data loaded from '{published[0]}" in cold and f"data loaded from '{published[0]}" in warm, warm
