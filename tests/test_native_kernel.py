"""Kernels compiled once are loaded as machine code without numba (imu_emulator.native): same numbers as numba's
dispatcher, no numba import on a warm start, a damaged object is recompiled, the first compile is announced."""
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imu_emulator import kernel as kernel_module
from imu_emulator.scene import load_scene
from imu_emulator.simulation import Simulation

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("IMU_EMULATOR_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(kernel_module, "_loaded", {})
    return tmp_path / "cache" / "kernels"


def _numba_dispatcher_result(scene, n, cache_dir):
    """The same block computed by calling the generated module's numba dispatcher directly."""
    key = kernel_module.scene_key(scene, True, False)
    spec = importlib.util.spec_from_file_location(f"check_{key}", cache_dir / f"k_{key}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    n_imu = len(scene.imus)
    acc, gyro, quat = np.empty((n_imu, n, 3)), np.empty((n_imu, n, 3)), np.empty((n_imu, n, 4))
    h = scene.initial_heading_rad
    hold = np.array([np.cos(h), np.sin(h), 1.0, 0.0])
    empty2 = np.zeros((0, 0))
    module.kernel(np.int64(0), np.int64(n), np.zeros((0, 0, 0)), np.zeros((0, 0, 0)), hold, acc, gyro, quat,
                  *[empty2] * 5, np.empty((kernel_module.CHUNK, module.N_PHASE)))
    return acc, gyro, quat


def test_native_kernel_equals_numba_dispatcher_bit_for_bit(cache):
    scene = load_scene(ROOT / "examples" / "two_imus.toml")
    sim = Simulation(scene)
    assert (cache / f"k_{kernel_module.scene_key(scene, True, False)}.o").exists()
    assert type(sim.kernel.__closure__[0].cell_contents).__name__ == "NativeKernel"   # not the numba fallback
    native = sim.block(0, 1000)
    acc, gyro, quat = _numba_dispatcher_result(scene, 1000, cache)
    assert np.array_equal(native.accel, acc) and np.array_equal(native.gyro, gyro) and np.array_equal(native.quat, quat)
    # views into larger arrays (not contiguous with two IMUs) are written through
    whole = sim.run(block_size=300)
    assert np.array_equal(whole.accel[:, :1000], acc)


def test_warm_start_does_not_import_numba(cache, tmp_path):
    code = ("import sys; from imu_emulator.cli import main; "
            f"main(['generate', {str(ROOT / 'examples' / 'helix.toml')!r}, '-o', {str(tmp_path / 'o.npz')!r}, "
            "'--quiet']); print('numba' in sys.modules)")
    first = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    second = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert first.returncode == 0 and second.returncode == 0, first.stderr + second.stderr
    assert first.stdout.split() == ["True"]       # compiled: numba was needed
    assert second.stdout.split() == ["False"]     # loaded as machine code


def test_damaged_object_is_compiled_again(cache):
    scene = load_scene(ROOT / "examples" / "helix.toml")
    good = Simulation(scene).block(0, 500)
    path, compiled = kernel_module.cached_kernel(scene)
    assert compiled
    path.write_bytes(b"\x10\x00\x00\x00not an object at all")
    kernel_module._loaded.clear()
    again = Simulation(scene).block(0, 500)
    assert np.array_equal(good.accel, again.accel)
    assert path.read_bytes()[:4] != b"\x10\x00\x00\x00"


def test_first_compile_is_announced_with_its_time_on_a_terminal(cache, tmp_path, capsys, monkeypatch):
    from imu_emulator.cli import main
    scene = str(ROOT / "examples" / "orientation_only.toml")
    args = ["generate", scene, "-o", str(tmp_path / "o.npz")]
    assert main(args) == 0                      # stderr is not a terminal: no status line (errors stay one line)
    assert "compiling" not in capsys.readouterr().err
    kernel_module._loaded.clear()
    for leftover in cache.iterdir():
        leftover.unlink() if leftover.is_file() else None
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(args) == 0
    cold = capsys.readouterr().err
    assert f"compiling kernel for scene {scene} (first run) …" in cold and " compiled in " in cold
    kernel_module._loaded.clear()
    assert main(args) == 0                      # warm: nothing to announce
    assert "compiling" not in capsys.readouterr().err
