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
from tests.support.paths import REPO
from tests.support.timing import scaled

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

ROOT = REPO
RUN = ("import sys\n"
       "from imu_emulator import load_scene\n"
       "from imu_emulator.runtime.simulation import Simulation\n"
       "Simulation(load_scene('examples/circle.toml'), attitude=False).block(0, 10)\n"
       "print('numba imported:', 'numba' in sys.modules)\n")


def _cache_log(cache: Path, native: bool) -> tuple[str, bool]:
    env = {**os.environ, "IMU_EMULATOR_CACHE": str(cache), "NUMBA_DEBUG_CACHE": "1",
           "IMU_EMULATOR_NATIVE": "1" if native else "0"}
    done = subprocess.run([sys.executable, "-c", RUN], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=scaled(600), check=True)
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


# --- one kernel per structure (issue 25) ---------------------------------------------------------------------
# The scene's numbers arrive at run time (imu_emulator.codegen.plan: the kernel's `prm`), so scenes that differ only
# in them share one kernel. The witness is the count of kernels generated (one per key) and of cache entries, not a
# time; the samples are checked against the closed form of each scene's own numbers.

W = 0.7          # rad/s, yaw rate about the up axis (ENU): body rate (0, 0, W), no angular acceleration
G = 9.80665      # [scene] gravity_mps2 default: at rest and level in ENU the specific force is (0, 0, +g)


def _turning(duration=2.0, seed=1, t0=0.0, bias=(0.01, -0.02, 0.03), gbias=(1e-3, 2e-3, -3e-3),
             lever=(0.3, -0.2, 0.1), roll_deg=90.0, noise=0.0, trajectory=None):
    from imu_emulator import scene_from_dict
    accel = {"bias": list(bias)}
    if noise:
        accel["noise_density"] = noise
    return scene_from_dict({
        "scene": {"rate_hz": 100, "duration_s": duration, "frame": "ENU", "seed": seed, "t0_s": t0},
        "trajectory": trajectory or {"x": "0", "y": "0", "z": "0"},
        "attitude": {"roll": "0", "pitch": "0", "yaw": f"{W!r}*t"},
        "imu": [{"name": "a", "lever_arm_m": list(lever), "mounting_rpy_deg": [roll_deg, 0.0, 0.0],
                 "accel": accel, "gyro": {"bias": list(gbias)}}],
        "effects": {"gravity": True, "lever_arm": True, "mounting": True, "bias": True, "noise": bool(noise)}})


def _closed_form(lever, roll_deg, bias, gbias):
    """Sensor = Rx(roll)^T body + bias; body: f = (0, 0, g) + w x (w x r) = (-W^2 rx, -W^2 ry, g), w = (0, 0, W)."""
    import numpy as np
    a = np.radians(roll_deg)
    rx_t = np.array([[1, 0, 0], [0, np.cos(a), np.sin(a)], [0, -np.sin(a), np.cos(a)]])
    f = rx_t @ np.array([-W * W * lever[0], -W * W * lever[1], G]) + np.array(bias)
    w = rx_t @ np.array([0.0, 0.0, W]) + np.array(gbias)
    return f, w


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    from imu_emulator.runtime import kernels
    monkeypatch.setenv("IMU_EMULATOR_CACHE", str(tmp_path))
    monkeypatch.setattr(kernels, "_loaded", {})
    return tmp_path / "kernels"


def test_scenes_differing_only_in_numbers_compile_one_kernel_and_give_their_own_closed_forms(fresh_cache,
                                                                                             monkeypatch):
    import numpy as np

    from imu_emulator.codegen import generate
    from imu_emulator.runtime import kernels
    from imu_emulator.runtime.simulation import Simulation
    generated = []
    original = kernels.generate_source
    monkeypatch.setattr(kernels, "generate_source", lambda *a, **k: generated.append(1) or original(*a, **k))
    variants = [dict(), dict(duration=3.5), dict(seed=99), dict(bias=(-0.5, 0.25, 0.125)),
                dict(gbias=(-1e-2, 5e-3, 7e-3)), dict(lever=(-1.5, 0.75, 2.0)), dict(roll_deg=-30.0),
                dict(roll_deg=135.0, lever=(0.01, 0.02, -0.03), bias=(1.0, 2.0, 3.0), duration=0.5)]
    for change in variants:
        options = {"bias": (0.01, -0.02, 0.03), "gbias": (1e-3, 2e-3, -3e-3), "lever": (0.3, -0.2, 0.1),
                   "roll_deg": 90.0, **change}
        block = Simulation(_turning(**change), attitude=False).run()
        f, w = _closed_form(options["lever"], options["roll_deg"], options["bias"], options["gbias"])
        assert block.accel.shape[1] == round(options.get("duration", 2.0) * 100), change
        # the sums' rounding: a few ulp of g
        np.testing.assert_allclose(block.accel[0], np.broadcast_to(f, block.accel[0].shape), rtol=0, atol=1e-12,
                                   err_msg=str(change))
        np.testing.assert_allclose(block.gyro[0], np.broadcast_to(w, block.gyro[0].shape), rtol=0, atol=1e-15,
                                   err_msg=str(change))
    assert len(generated) == 1, f"{len(generated)} kernels generated for {len(variants)} scenes of one structure"
    assert len([p for p in fresh_cache.iterdir() if not p.name.startswith(".")]) == 1
    assert len(kernels._loaded) == 1
    assert generate.CODEGEN_VERSION    # the module the counter wraps is the generator's


def test_a_zero_still_removes_its_line_and_so_is_another_structure(fresh_cache):
    """Which values are zero stays in the key (a zero lever arm has no lines), as does t0 while the motion is
    periodic (its phase constants are literals) and is not when it is not (t0 then only enters t = t0 + k dt)."""
    from imu_emulator.runtime.cache import scene_key
    base = scene_key(_turning(), False, False)
    assert scene_key(_turning(lever=(0.0, 0.0, 0.0)), False, False) != base
    assert scene_key(_turning(noise=1e-3), False, False) != base
    assert scene_key(_turning(noise=1e-3), False, False) == scene_key(_turning(noise=5e-2), False, False)
    assert scene_key(_turning(t0=10.0), False, False) != base      # yaw = W t: cos and sin of a phase
    still = {"x": "0.5*t*t", "y": "2*t", "z": "0"}
    periodic = {"x": "cos(t)", "y": "0", "z": "0"}
    for trajectory, shared in ((still, True), (periodic, False)):
        a, b = (_turning(t0=t0, trajectory=trajectory) for t0 in (0.0, 10.0))
        # the attitude's yaw expression is periodic: same attitude given as no expression needs the tangent mode
        a, b = (_tangent(s) for s in (a, b))
        assert (scene_key(a, False, False) == scene_key(b, False, False)) is shared, trajectory


def _tangent(scene):
    """The scene in tangent attitude (heading from the velocity): no attitude expression, so no attitude phase."""
    import dataclasses
    return dataclasses.replace(scene, attitude_mode="tangent", attitude=None)


def test_the_origin_is_a_number_and_its_exact_zeros_are_structure():
    """Another origin reuses the kernel (r0 and C arrive in prm); an origin where C has exact zeros or ones (lat 0,
    lon 0) leaves those terms out, so it is another structure. The values are the closed forms of
    tests/motion/test_earth.py (normal gravity at rest at each latitude), which run through the shared kernels."""
    from imu_emulator import scene_from_dict
    from imu_emulator.runtime.cache import scene_key

    def at(lat, lon, h):
        return scene_from_dict({"scene": {"rate_hz": 100, "duration_s": 1.0, "frame": "NED",
                                          "origin": {"lat_deg": lat, "lon_deg": lon, "height_m": h},
                                          "gravity_model": "wgs84"},
                                "trajectory": {"x": "0", "y": "0", "z": "0"}, "attitude": {"roll": "0", "pitch": "0",
                                                                                          "yaw": "0"},
                                "imu": [{"name": "a"}], "effects": {"gravity": True, "earth_rate": True}})
    assert scene_key(at(47.0, 8.0, 400.0), True, True) == scene_key(at(-33.5, 151.2, -20.0), True, True)
    assert scene_key(at(0.0, 0.0, 0.0), True, True) != scene_key(at(47.0, 8.0, 400.0), True, True)


# --- the numbers of the motion's expressions (issue 25 (a)) ----------------------------------------------------
# imu_emulator.numerics.expressions.lift: an expression's numbers and [params] arrive in prm too, except phases
# (the argument of sin/cos/tan linear in t, and an Euler angle or geodetic latitude/longitude linear in t as a
# whole: reduced exactly when generated), exponents and zeros.

def _expressions(amp, b, c, d, y, frequency=0.3, yaw=None):
    from imu_emulator import scene_from_dict
    return scene_from_dict({
        "scene": {"rate_hz": 100, "duration_s": 2.0, "frame": "ENU"}, "params": {"amp": amp},
        "trajectory": {"x": f"amp*cos({frequency!r}*t) + {b!r}*t**2", "y": f"{c!r}*t", "z": f"{d!r}"},
        "attitude": {"roll": "0", "pitch": "0", "yaw": yaw or f"{y!r}*t*t"},
        "imu": [{"name": "a"}], "effects": {"gravity": True}})


def _sympy_truth(amp, b, c, d, y, t):
    """Position, velocity, specific force and rate from sympy's derivatives of the literal texts (no lifting)."""
    import numpy as np
    import sympy
    s = sympy.Symbol("t", real=True)
    pos = [sympy.sympify(f"{amp!r}*cos(0.3*t) + {b!r}*t**2", locals={"t": s}), sympy.sympify(f"{c!r}*t",
                                                                                           locals={"t": s}),
           sympy.Float(d)]
    yaw = sympy.sympify(f"{y!r}*t*t", locals={"t": s})

    def f(e, n=0):
        return np.broadcast_to(sympy.lambdify(s, sympy.diff(e, s, n) if n else e, "numpy")(t), t.shape)
    p = np.stack([f(e) for e in pos], axis=1)
    v = np.stack([f(e, 1) for e in pos], axis=1)
    a = np.stack([f(e, 2) for e in pos], axis=1)
    psi, rate = f(yaw), f(yaw, 1)
    # body axes = Rz(yaw)^T nav (roll = pitch = 0); at rest ENU reads (0, 0, +g)
    accel = np.stack([np.cos(psi) * a[:, 0] + np.sin(psi) * a[:, 1], -np.sin(psi) * a[:, 0] + np.cos(psi) * a[:, 1],
                      a[:, 2] + G], axis=1)
    gyro = np.stack([0 * rate, 0 * rate, rate], axis=1)
    return p, v, accel, gyro


def test_scenes_differing_only_in_expression_numbers_share_one_kernel(fresh_cache, monkeypatch):
    import numpy as np

    from imu_emulator.runtime import kernels
    from imu_emulator.runtime.simulation import Simulation
    generated = []
    original = kernels.generate_source
    monkeypatch.setattr(kernels, "generate_source", lambda *a, **k: generated.append(original(*a, **k))
                        or generated[-1])
    numbers = [(5.0, 0.2, 1.5, 3.0, 0.05), (6.25, -0.7, 2.5, -1.0, 0.11)]
    for values in numbers:
        block = Simulation(_expressions(*values), attitude=False, truth=True).run()
        p, v, accel, gyro = _sympy_truth(*values, block.t_s)
        np.testing.assert_allclose(block.truth["position"], p, rtol=0, atol=1e-13, err_msg=str(values))
        np.testing.assert_allclose(block.truth["velocity"], v, rtol=0, atol=1e-13, err_msg=str(values))
        np.testing.assert_allclose(block.accel[0], accel, rtol=0, atol=1e-12, err_msg=str(values))
        np.testing.assert_allclose(block.gyro[0], gyro, rtol=0, atol=1e-15, err_msg=str(values))
    assert len(generated) == 1, f"{len(generated)} kernels generated for scenes differing only in numbers"
    # the numbers are not in the source (6.25 and -0.7 would print as themselves); the phase 0.3 is
    assert "6.25" not in generated[0] and "0.7" not in generated[0] and "0.11" not in generated[0]
    assert "prm_" in generated[0]


def test_phases_exponents_and_zeros_of_expressions_stay_structure():
    """A linear phase's numbers are compiled in (its exact reduction is computed from them), as is an Euler angle
    linear in t (the kernel takes its cos and sin), an exponent and a zero; another amplitude or a nonlinear angle's
    coefficient is not."""
    from imu_emulator.runtime.cache import scene_key

    def key(*args, **kw):
        return scene_key(_expressions(*args, **kw), False, True)
    base = key(5.0, 0.2, 1.5, 3.0, 0.05)
    assert key(7.0, 0.3, 1.25, 3.5, 0.02) == base
    assert key(5.0, 0.2, 1.5, 3.0, 0.05, frequency=0.4) != base        # sin/cos argument linear in t
    assert key(5.0, 0.2, 1.5, 0.0, 0.05) != base                       # a zero stays a literal
    linear = key(5.0, 0.2, 1.5, 3.0, 0.05, yaw="0.05*t")
    assert linear != key(5.0, 0.2, 1.5, 3.0, 0.05, yaw="0.06*t")       # the yaw angle is a phase
    assert key(5.0, 0.2, 1.5, 3.0, 0.05, yaw="0.05*t**3") != key(5.0, 0.2, 1.5, 3.0, 0.05, yaw="0.05*t**2")
    assert key(5.0, 0.2, 1.5, 3.0, 0.05, yaw="0.05*t**3") == key(5.0, 0.2, 1.5, 3.0, 0.05, yaw="0.9*t**3")
    # a time-free part holding pi stays: sympy turns sin(pi/2 - x) into cos(x) only when it sees pi/2
    assert key(5.0, 0.2, 1.5, 3.0, 0.05, yaw="pi/2 - 0.05*t**3") != key(5.0, 0.2, 1.5, 3.0, 0.05,
                                                                        yaw="pi/3 - 0.05*t**3")
    assert key(5.0, 0.2, 1.5, 3.0, 0.05, yaw="pi/2 - 0.05*t**3") == key(5.0, 0.2, 1.5, 3.0, 0.05,
                                                                        yaw="pi/2 - 0.9*t**3")


def test_a_multiple_of_pi_keeps_sympys_exact_identities():
    """sin(pi/2 - x) = cos(x): with pi/2 kept whole, the kernel of yaw = pi/2 - x takes cos(x), the same operations
    as an angle written the other way (an ENU and a NED scene of one motion: test_axes_at_the_wire)."""
    import ast

    import sympy
    from imu_emulator.numerics.expressions import lift, to_sympy
    t = sympy.Symbol("t", real=True)
    tree = ast.parse("pi/2 - (0.6*t + 0.2*t**3)", mode="eval")
    structure, values = lift(tree, {}, phase=True)
    assert values == [0.6, 0.2] and "pi" in structure
    c = [sympy.Symbol(f"c{i}", real=True) for i in range(len(values))]
    angle = to_sympy(tree, {}, t, lifted=[str(x) for x in c], phase=True)
    assert sympy.sin(angle) == sympy.cos(c[0] * t + c[1] * t**3)


# --- one kernel for every choice of outputs: measured, not used (issue 25 (b)) ---------------------------------
# generate_source(switched=True) writes the attitude and truth only when their arrays are passed; it costs a
# measurable amount against each choice's own kernel (tools/bench_parametric.py; README "How the kernel pays only
# for what the scene names"), so the cache keeps one kernel per choice. The benchmark's figure means something only
# if both compute the same: this test holds them to it.

@pytest.mark.slow
@pytest.mark.parametrize("attitude,truth", [(False, False), (False, True), (True, False)],
                         ids=["generate", "generate-truth", "stream"])
def test_the_switched_kernel_writes_what_each_choices_own_kernel_writes(tmp_path, attitude, truth):
    import importlib.util

    import numpy as np

    from imu_emulator.codegen.generate import generate_source
    from imu_emulator.runtime import kernels
    from imu_emulator.runtime.simulation import Simulation
    # tangent attitude (its angles derived for the truth only) and biases (their realized values in the truth)
    scene = _tangent(_turning(trajectory={"x": "3*cos(0.5*t)", "y": "2*sin(0.5*t)", "z": "0.1*t"}))
    kernels._realize_runtime()
    path = tmp_path / f"switched_{attitude}_{truth}.py"
    path.write_text(generate_source(scene, attitude, truth, switched=True))
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    own = Simulation(scene, attitude=attitude, truth=truth)
    switched = Simulation(scene, attitude=attitude, truth=truth)
    switched.kernel = module.kernel
    a, b = own.run(), switched.run()
    for name in ("accel", "gyro", "quat"):
        if getattr(a, name) is None:
            assert getattr(b, name) is None, name
        else:
            np.testing.assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)
    assert (a.truth is None) == (b.truth is None)
    for key in (a.truth or {}):
        np.testing.assert_array_equal(b.truth[key], a.truth[key], err_msg=key)
    if truth:
        assert set(a.truth) >= {"euler", "gyro_bias"} and np.ptp(a.truth["euler"][:, 2]) > 0.1
