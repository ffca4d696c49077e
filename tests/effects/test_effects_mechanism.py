"""The effect records drive validation, the kernel's source and its cache key; the cache never serves a
broken or stale entry."""
from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from imu_emulator.runtime import cache, kernels as kernel_module
from imu_emulator import scene_from_dict
from imu_emulator.effects import EFFECTS, STAGE_CONTRACT, Stage, all_params
from imu_emulator.errors import SceneError
from imu_emulator.codegen.generate import CODEGEN_VERSION, generate_source
from imu_emulator.codegen.plan import EffectPlan
from imu_emulator.runtime.cache import generator_modules, scene_key
from imu_emulator.runtime.kernels import compile_kernel
from tests.support.paths import DATA, REPO
from tests.support.timing import scaled
from tests.support import scenes

ROOT = REPO
EXAMPLES = ROOT / "examples"
GOLDEN = DATA / "kernels"


def _scene(effects=None, imu=None, **scene):
    return scenes.scene(**{"rate_hz": 100, "duration_s": 0.5, **scene}, trajectory={"x": "0.5*t*t", "y": "0", "z": "0"},
                        attitude={"roll": "0.1*t", "pitch": "0", "yaw": "0.2*t"}, imus=[imu or {"name": "a"}],
                        effects=effects or {})


def _sample_value(param, scale: float):
    """A valid, nonzero value of the parameter's shape in its own unit (the record's example if it has one)."""
    if param.example is not None:
        return param.example * scale
    if param.shape == "scalar":
        return 0.3 * scale
    if param.shape == "sines":
        return [{"axis": "y", "amplitude": 0.5 * scale, "frequency": 30.0}]
    if param.shape == "psd":
        return [[10.0, 0.01 * scale], [40.0, 0.01 * scale]]
    if param.shape == "expression":
        return f"{20 * scale!r} + 0.1*t"
    if param.shape in ("vector3", "triple"):
        return [0.1 * scale, 0.2 * scale, 0.3 * scale]
    return [[0.01 * scale * (1 + i + 3 * j) for j in range(3)] for i in range(3)]


def _imu_with(values: dict) -> dict:
    imu: dict = {"name": "a"}
    for param, value in values.items():
        if param.table == "imu":
            imu[param.key] = value
        else:
            imu.setdefault(param.table.split(".", 1)[1], {})[param.key] = value
    return imu


def test_every_parameter_of_every_effect_reaches_the_kernel_as_a_number_or_as_structure():
    """Each parameter reaches the kernel: as run-time numbers (EffectPlan.param_values, the kernel's `prm`) with the
    key and source unchanged, or, for those that shape the code (how many lines, which grid, an expression), as a
    new key and source. A parameter that reached neither would be ignored silently."""
    everything = {name: True for name in EFFECTS}
    base = {param: _sample_value(param, 1.0) for _, param in all_params()}
    origin = {"lat_deg": 47.0, "lon_deg": 8.0, "height_m": 400.0}    # the Earth effects need one
    reference = _scene(everything, _imu_with(base), origin=origin)
    ref_key, ref_source = scene_key(reference, True, False), generate_source(reference, True, False)
    ref_params = EffectPlan(reference).param_values()
    assert all_params(), "the effects declare parameters"
    structural = set()
    for effect, param in all_params():
        # x11 crosses a decade (the flicker band)
        changed = _scene(everything, _imu_with({**base, param: _sample_value(param, 11.0)}), origin=origin)
        key, source = scene_key(changed, True, False), generate_source(changed, True, False)
        if key == ref_key:
            assert source == ref_source, f"{param.path}: the source changed under the same key"
            params = EffectPlan(changed).param_values()
            assert params.shape != ref_params.shape or not np.array_equal(params, ref_params), param.path
        else:
            assert source != ref_source, f"{effect.name}: {param.path}"
            structural.add(param.path)
    # Those that shape the code: the correlation times (a Gauss-Markov process steps every sample or on a coarser
    # grid of a whole number of samples, chosen from tau / dt: the grid is in the lines), the PSD line count, the
    # temperature expression (its tree is printed into the source)
    assert structural == {f"imu.{triad}.{key}" for triad in ("gyro", "accel") for key in (
        "gauss_markov_tau_s", "bias_instability_tau_min_s", "bias_instability_tau_max_s")} | {
        "imu.vibration.psd_lines", "imu.temperature_c"}, structural


def test_effect_named_false_gives_the_same_source_as_not_named():
    for name in EFFECTS:
        off = _scene({name: False})
        assert generate_source(off, True, True) == generate_source(_scene(), True, True), name


def test_records_declare_stage_order_and_contract():
    for effect in EFFECTS.values():
        assert effect.name.isidentifier() and effect.description and "\n" not in effect.description
        assert isinstance(effect.stage, Stage) and isinstance(effect.order, int)
        for param in effect.params:
            assert param.table in ("imu", "imu.gyro", "imu.accel", "imu.vibration")
    assert set(STAGE_CONTRACT) == set(Stage)
    order = [(e.stage, e.order) for e in EFFECTS.values()]
    assert order == sorted(order)


def test_imu_keys_and_warnings_come_from_the_records():
    with pytest.raises(SceneError, match=r"imu\[0\]\.wobble: unknown key"):
        _scene(imu={"name": "a", "wobble": 1})
    for effect, param in all_params():
        scene = _scene({}, _imu_with({param: _sample_value(param, 1.0)}))
        expected = f"imu[0].{param.path.split('.', 1)[1]} is ignored because effects.{effect.name} is not true"
        assert expected in scene.warnings
        on = _scene({effect.name: True}, _imu_with({p: _sample_value(p, 1.0) for p in effect.params}))
        assert not any("is ignored" in w for w in on.warnings)


def test_imu_names_and_seed_do_not_reach_the_source():
    a = _scene({"lever_arm": True}, {"name": "first", "lever_arm_m": [0.1, 0, 0]})
    b = _scene({"lever_arm": True}, {"name": "x\"; import os  # 'quoted' \u00e9", "lever_arm_m": [0.1, 0, 0]},
               seed=12345)
    assert generate_source(a, True, True) == generate_source(b, True, True)
    # names reach no line: the two scenes share a kernel (the key is the structure, imu_emulator.runtime.cache)
    assert scene_key(a, True, True) == scene_key(b, True, True)
    seeded = _scene({"lever_arm": True}, {"name": "first", "lever_arm_m": [0.1, 0, 0]}, seed=7)
    assert scene_key(seeded, True, True) == scene_key(a, True, True)   # the seed arrives at run time


def test_generator_modules_are_found_by_their_imports():
    names = {p.relative_to(ROOT).as_posix() for p in generator_modules()}
    for expected in ("codegen/generate.py", "codegen/plan.py", "codegen/signature.py", "codegen/template.py",
                     "codegen/increments.py", "motion/code.py", "numerics/expressions.py", "geo/rotations.py",
                     "numerics/phase.py", "numerics/counter_rng.py", "scene/model.py", "scene/units.py",
                     "effects/__init__.py", "effects/_record.py", *(f"effects/{name}.py" for name in EFFECTS)):
        assert f"imu_emulator/{expected}" in names, expected
    # how the kernel is compiled, and its machine code written and loaded, is part of the entry too
    assert {"imu_emulator/runtime/kernels.py", "imu_emulator/runtime/cache.py",
            "imu_emulator/native/objects.py", "imu_emulator/native/lazy.py"} <= names
    assert "imu_emulator/runtime/simulation.py" not in names     # how blocks are driven does not shape the source


def _explained_scenes():
    """Every effect on (navigation-stage streams, state blocks, counters, effect arrays), two IMUs; more IMUs than
    stay inline (each IMU a function of its own); and the examples."""
    from imu_emulator import load_scene
    base = {param: _sample_value(param, 1.0) for _, param in all_params()}
    everything = {"scene": {"rate_hz": 100, "duration_s": 0.5, "origin": {"lat_deg": 47.0, "lon_deg": 8.0}},
                  "trajectory": {"x": "0.5*t*t", "y": "sin(t)", "z": "0"},
                  "attitude": {"roll": "0.1*t", "pitch": "0", "yaw": "0.2*t"},
                  "imu": [_imu_with(base), {**_imu_with(base), "name": "b"}],
                  "effects": {name: True for name in EFFECTS}}
    many = {**everything, "imu": [{"name": f"i{m}", "gyro": {"noise_density": 1e-3}} for m in range(20)],
            "effects": {"gravity": True, "noise": True}}
    yield "every_effect", scene_from_dict(everything)
    yield "many_imus", scene_from_dict(many)
    for path in sorted(EXAMPLES.glob("*.toml")):
        yield path.stem, load_scene(path)


def _glossary(source: str, array: str) -> dict[int, str]:
    """Index -> glossary line for `#   state[i]: ...` and `#   state[i..j]: ...` (keys likewise)."""
    found = {}
    for first, last, text in re.findall(rf"^#   {array}\[(\d+)(?:\.\.(\d+))?\]: (.*)$", source, re.M):
        found.update({i: text for i in range(int(first), int(last or first) + 1)})
    return found


@pytest.mark.parametrize("truth", [False, True])
def test_the_source_explains_its_slots_streams_and_effects(truth):
    """The header and glossary name every state slot and random stream of the EffectPlan, with the effect that
    asked for it, and cover every one the code reads; each effect that emits lines has its comment line."""
    for name, scene in _explained_scenes():
        plan = EffectPlan(scene)
        source = generate_source(scene, True, truth)
        code = "\n".join(line for line in source.splitlines() if not line.lstrip().startswith("#"))
        slots, streams = _glossary(source, "state"), _glossary(source, "keys")
        assert set(slots) == set(range(len(plan.slots))), name
        assert set(streams) == set(range(len(plan.streams))), name
        assert {int(i) for i in re.findall(r"\bstate\[(\d+)\]", code)} <= set(slots), name
        assert {int(i) for i in re.findall(r"\bkeys\[(\d+)\]", code)} <= set(streams), name
        for i, (var, _, _) in enumerate(plan.slots):
            assert f"effect {plan.slot_effects[i]}," in slots[i] and (var is None or var in slots[i]), (name, i)
        for i, (_, stream) in enumerate(plan.streams):
            assert f"stream {stream} " in streams[i] and streams[i].endswith(f"effect {plan.stream_effects[i]}")
        header = source[: source.index("\nimport math")]
        for effect in plan.active:
            assert re.search(rf"^#   \d\. [^:]+: .*\b{effect.name}\b", header, re.M), (name, effect.name)
            if effect.name in plan.emitted:
                assert f"# effect {effect.name} (" in source, (name, effect.name)
        assert f"(CODEGEN_VERSION {CODEGEN_VERSION})" in header


@pytest.mark.parametrize("scene_path", sorted(EXAMPLES.glob("*.toml")), ids=lambda p: p.stem)
def test_golden_kernels(scene_path):
    """Regenerate with `python tools/regen_golden_kernels.py` after a deliberate change, and review the diff."""
    from imu_emulator import load_scene
    golden = (GOLDEN / f"{scene_path.stem}.py.txt").read_text()
    assert generate_source(load_scene(scene_path), attitude=True, truth=False) == golden


def test_kernel_command_prints_the_source():
    out = subprocess.run([sys.executable, "-m", "imu_emulator", "kernel", str(EXAMPLES / "circle.toml")],
                         capture_output=True, text=True, check=True).stdout
    assert out == (GOLDEN / "circle.py.txt").read_text()
    table = subprocess.run([sys.executable, "-m", "imu_emulator", "kernel", "--effects"],
                           capture_output=True, text=True, check=True).stdout
    for name in EFFECTS:
        assert f"`{name}`" in table


def test_the_docs_parameter_table_is_the_records_table():
    """The docs site's effects table is generated at build time from documentation_table(), which
    `imu-emulator kernel --effects` prints too (tests/project/test_docs_site.py reads each row back from the built page)."""
    assert "<!-- generated: effects -->" in (ROOT / "docs" / "sensor-errors.md").read_text()


# --- cache ------------------------------------------------------------------------------------------

def _entries(root: Path) -> list[str]:
    return sorted(p.name for p in root.iterdir()) if root.exists() else []


def _run(scene):
    from imu_emulator.runtime.simulation import Simulation
    return Simulation(scene).run()


def test_a_kernel_that_fails_to_compile_leaves_no_entry(fresh_cache, monkeypatch):
    scene = _scene({"gravity": True})
    original = EFFECTS["gravity"]
    monkeypatch.setitem(EFFECTS, "gravity", dataclasses.replace(original, emit=lambda ctx: ["fnz = fnz + nowhere"]))
    with pytest.raises(Exception):
        compile_kernel(scene)
    assert _entries(fresh_cache) == []
    # the same key, now generated correctly, compiles and runs: nothing broken was kept
    EFFECTS["gravity"] = original
    out = _run(scene)
    np.testing.assert_allclose(out.accel[0, 0], [1.0, 0, 9.80665], atol=1e-12)   # t=0: level, a = (1, 0, 0)
    assert _entries(fresh_cache) == [scene_key(scene, True, False)]


@pytest.mark.parametrize("damage", ["truncate", "garbage", "does_not_compile"])
def test_a_corrupt_entry_is_regenerated(fresh_cache, damage):
    scene = _scene({"gravity": True})
    expected = _run(scene)
    source_file = fresh_cache / scene_key(scene, True, False) / "kernel.py"
    text = source_file.read_text()
    if damage == "truncate":
        source_file.write_text(text[: len(text) // 2])
    elif damage == "garbage":
        source_file.write_bytes(os.urandom(300))
    else:   # sealed by this cache, but source that does not compile
        bad = text.split("\n", 1)[1].replace("fnz = fnz + 9.80665", "fnz = fnz + not_defined")
        source_file.write_text(cache.sealed(source_file.parent.name, bad))
    kernel_module._loaded.clear()
    again = _run(scene)
    np.testing.assert_array_equal(again.accel, expected.accel)
    assert cache.entry_source(source_file, source_file.parent.name) is not None
    assert _entries(fresh_cache) == [scene_key(scene, True, False)]


def test_two_processes_fill_the_cache_at_once(tmp_path):
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(ROOT)!r})
        from imu_emulator import load_scene, simulate
        out = simulate(load_scene({str(EXAMPLES / 'two_imus.toml')!r}))
        print(repr(float(out.accel.sum() + out.gyro.sum())))
    """)
    env = {**os.environ, "IMU_EMULATOR_CACHE": str(tmp_path)}
    procs = [subprocess.Popen([sys.executable, "-c", script], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [p.communicate(timeout=scaled(600)) for p in procs]
    assert all(p.returncode == 0 for p in procs), [r[1] for r in results]
    assert results[0][0] == results[1][0]
    entries = _entries(tmp_path / "kernels")
    assert len(entries) == 1 and not entries[0].startswith("."), entries
