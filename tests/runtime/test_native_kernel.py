"""Kernels compiled once are loaded as machine code without numba (imu_emulator.native.objects): the same numbers as
numba's dispatcher (the oracle: the same generated source run by numba), no numba import on a warm start, a
damaged or mismatched object is compiled again, and the numba dispatcher is used when the object cannot load."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from imu_emulator.runtime import kernels as kernel_module
from imu_emulator import load_scene, scene_from_dict
from imu_emulator.native import objects as native
from imu_emulator.effects import EFFECTS, all_params
from imu_emulator.codegen.signature import ARGS, trial_arguments
from imu_emulator.runtime.simulation import Simulation
from tests.support.paths import REPO

ROOT = REPO
from tests.effects.test_effects_mechanism import _imu_with, _sample_value  # noqa: E402


def _every_effect_scene():
    """Two IMUs with every effect on (state slots, stream keys, counters, bias truth all in use)."""
    base = {param: _sample_value(param, 1.0) for _, param in all_params()}
    # the IMUs share one sample clock: the second differs in every other parameter
    imu_a, imu_b = _imu_with(base), _imu_with({p: base[p] if p.key.startswith("clock") else _sample_value(p, 2.0)
                                               for p in base})
    imu_b["name"] = "b"
    return scene_from_dict({"scene": {"rate_hz": 200, "duration_s": 3.0, "seed": 11,     # Earth effects: an origin
                                      "origin": {"lat_deg": 45.0, "lon_deg": 10.0, "height_m": 0.0}},
                            "trajectory": {"x": "0.5*t*t", "y": "sin(t)", "z": "0"},
                            "attitude": {"roll": "0.1*t", "pitch": "0", "yaw": "0.2*t"},
                            "imu": [imu_a, imu_b], "effects": {name: True for name in EFFECTS}})


def _outputs(block):
    arrays = {"accel": block.accel, "gyro": block.gyro, "quat": block.quat, "dtheta": block.dtheta,
              "dvel": block.dvel}
    arrays.update({f"truth.{k}": v for k, v in (block.truth or {}).items()})
    return arrays


def _earth_scene():
    """Earth rate and Coriolis on a moving IMU (the Earth effects' kernel lines and state)."""
    return scene_from_dict({"scene": {"rate_hz": 100, "duration_s": 3.0, "frame": "NED",
                                      "gravity_model": "wgs84",
                                      "origin": {"lat_deg": 45.0, "lon_deg": 10.0, "height_m": 0.0}},
                            "trajectory": {"x": "3*t", "y": "sin(t)", "z": "0"}, "attitude": {"mode": "tangent"},
                            "imu": [{"name": "a"}],
                            "effects": {"gravity": True, "earth_rate": True, "coriolis": True}})


@pytest.mark.parametrize("scene_name,increments", [("every_effect", 0), ("circle", 0), ("two_imus", 0),
                                                   ("sampled_track", 0), ("every_effect", 3), ("earth", 0),
                                                   ("earth", 2)])
def test_machine_code_equals_numba_dispatcher_bit_for_bit(fresh_cache, monkeypatch, scene_name, increments):
    # increments and the Earth effects add kernel arguments and outputs: the loader is typed from the trial call
    scene = {"every_effect": _every_effect_scene, "earth": _earth_scene}.get(
        scene_name, lambda: load_scene(ROOT / "examples" / f"{scene_name}.toml"))()
    fast = Simulation(scene, truth=True, increments=increments)
    assert isinstance(fast.kernel, native.NativeFunction)          # not the numba fallback
    assert (kernel_module.cached_kernel(scene, True, True, increments)[0] / kernel_module.NATIVE).exists()
    kernel_module._loaded.clear()
    monkeypatch.setattr(native, "load", lambda path, label: None)       # the oracle: numba runs the same source
    slow = Simulation(scene, truth=True, increments=increments)
    assert not isinstance(slow.kernel, native.NativeFunction)
    n = min(scene.n_samples, 600)
    # blocks of 257 into the whole run's arrays: views that are not contiguous with two IMUs
    a, b = fast.run(block_size=257), slow.run(block_size=257)
    for name, value in _outputs(a).items():
        if name in ("dtheta", "dvel") and increments == 0:
            assert value is None and _outputs(b)[name] is None, name
            continue
        assert np.array_equal(value, _outputs(b)[name], equal_nan=True), name
    assert fast.counts() == slow.counts()
    # a block after a jump back (state replayed from the start) agrees too
    assert np.array_equal(fast.fresh().block(n // 2, 100).gyro, slow.fresh().block(n // 2, 100).gyro)


def test_warm_start_does_not_import_numba(tmp_path):
    code = ("import sys; from imu_emulator.cli import main; "
            f"main(['generate', {str(ROOT / 'examples' / 'helix.toml')!r}, '-o', {str(tmp_path / 'o.npz')!r}, "
            "'--quiet']); print('numba' in sys.modules)")
    env = {**os.environ, "IMU_EMULATOR_CACHE": str(tmp_path / "cache")}
    first = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env)
    second = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env)
    assert first.returncode == 0 and second.returncode == 0, first.stderr + second.stderr
    assert first.stdout.split() == ["True"]       # compiled: numba was needed
    assert second.stdout.split() == ["False"]     # loaded as machine code


@pytest.mark.parametrize("damage", ["truncate", "flip_a_byte", "other_source"])
def test_damaged_machine_code_is_compiled_again(fresh_cache, damage):
    scene = load_scene(ROOT / "examples" / "helix.toml")
    good = Simulation(scene).block(0, 500)
    entry, compiled = kernel_module.cached_kernel(scene)
    assert compiled
    path = entry / kernel_module.NATIVE
    blob = path.read_bytes()
    if damage == "truncate":
        path.write_bytes(blob[: len(blob) // 2])
    elif damage == "flip_a_byte":
        path.write_bytes(blob[:-100] + bytes([blob[-100] ^ 0xFF]) + blob[-99:])
    else:   # intact machine code of another scene's source
        other = load_scene(ROOT / "examples" / "circle.toml")
        Simulation(other)
        path.write_bytes((kernel_module.cached_kernel(other)[0] / kernel_module.NATIVE).read_bytes())
    kernel_module._loaded.clear()
    again = Simulation(scene)
    assert isinstance(again.kernel, native.NativeFunction)          # rewritten, then loaded
    assert np.array_equal(good.accel, again.block(0, 500).accel)
    assert native.load(path, f"kernels/{entry.name}/{kernel_module.NATIVE}") is not None
    assert path.read_bytes() != blob[: len(blob) // 2]


def test_native_kernel_refuses_wrong_arguments(fresh_cache):
    scene = load_scene(ROOT / "examples" / "circle.toml")
    kernel = Simulation(scene).kernel
    args = list(trial_arguments(scene, True, False))
    with pytest.raises(TypeError, match="takes"):
        kernel(*args[:-1])
    args[ARGS.index("out_acc")] = np.zeros((1, 0))      # out_acc of the wrong rank
    with pytest.raises(TypeError, match="dimensions"):
        kernel(*args)
