"""Scenes and files that hung or crashed the loader (issue 23, items 10 and 11), as their small reproductions:
each must end in exit 2 with one `error:` line naming the key, quickly (a subprocess time limit catches a hang;
nothing here times anything), or in a correct run."""
import ast
import os
import subprocess
import sys

import pytest

from imu_emulator import scene_from_dict
from imu_emulator.codegen.generate import generate_source
from tests.support.paths import REPO

pytestmark = pytest.mark.subprocess

ROOT = REPO
LIMIT_S = 120        # a run that loads and refuses a scene takes ~2 s (imports); the hangs took minutes or for ever

BASE = """[scene]
rate_hz = 100
duration_s = 0.1
[trajectory]
x = "cos(t)"
y = "0"
z = "0"
[[imu]]
name = "imu0"
[effects]
gravity = true
"""
TRAJECTORY = '[trajectory]\nx = "cos(t)"\ny = "0"\nz = "0"'
NAME = 'name = "imu0"'
GYRO = NAME + "\n[imu.gyro]\nbias = "


def _cli(tmp_path, scene: str, name="scene.toml"):
    path = tmp_path / name
    if not path.exists():
        path.write_text(scene)
    return subprocess.run([sys.executable, "-m", "imu_emulator", "generate", str(path), "-o",
                           str(tmp_path / "out.csv"), "--quiet"], capture_output=True, text=True, cwd=tmp_path,
                          timeout=LIMIT_S, env={**os.environ, "PYTHONPATH": str(ROOT)})


def _assert_one_error(result, words):
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("error: ") and result.stderr.count("\n") == 1, result.stderr
    for word in words:
        assert word in result.stderr, f"{word!r} not in {result.stderr!r}"


CASES = {
    # item 10: pint's evaluator took minutes (cubic regex on the spaces) or for ever (a 369-million-digit power)
    "sqrt-spaces": (NAME, GYRO + '"1 sqrt(' + " " * 4000 + 'x"', ["imu[0].gyro.bias", "longer than 100"]),
    "power-tower-deg-s": (NAME, GYRO + '"9**9**9 deg/s"', ["imu[0].gyro.bias", "exponents are integers"]),
    "power-tower-deg-h": (NAME, GYRO + '"10**10**10 deg/h"', ["imu[0].gyro.bias", "exponents are integers"]),
    # item 11: RecursionError from tomllib (2000 deep) and from the digest's recursion (below tomllib's limit)
    "nested-2000": ("[effects]", "[params]\nf = " + "[" * 2000 + "]" * 2000 + "\n[effects]", ["key f", "nested"]),
    "nested-40": ("[effects]", "[params]\nf = " + "[" * 40 + "]" * 40 + "\n[effects]", ["params.f[0]", "nested"]),
    # item 11: ZeroDivisionError from a subnormal speed (radius v^2/(g tan bank) = 0)
    "turn-subnormal-speed": (TRAJECTORY, '[trajectory]\nshape = "coordinated_turn"\nspeed_mps = 5e-324\n'
                             'bank_deg = 20', ["trajectory.speed_mps", "out of range"]),
    "racetrack-subnormal-speed": (TRAJECTORY, '[trajectory]\nshape = "racetrack"\nspeed_mps = 5e-324\n'
                                  'straight_m = 10\nradius_m = 5', ["trajectory.speed_mps", "out of range"]),
}


@pytest.mark.parametrize("old, new, words", CASES.values(), ids=CASES)
def test_reproduction_is_one_error_line(tmp_path, old, new, words):
    assert old in BASE
    _assert_one_error(_cli(tmp_path, BASE.replace(old, new, 1)), words)


@pytest.mark.parametrize("name, make, kind", [
    ("zero.csv", lambda p: p.symlink_to("/dev/zero"), "a device"),     # was read without end
    ("fifo.csv", os.mkfifo, "a FIFO"),                                  # blocked for ever in open()
    ("zero.ulg", lambda p: p.symlink_to("/dev/zero"), "a device"),     # flight logs: the same check
    ("fifo.bin", os.mkfifo, "a FIFO"),
])
def test_track_or_log_that_is_not_a_regular_file(tmp_path, name, make, kind):
    make(tmp_path / name)
    scene = BASE.replace(TRAJECTORY, f'[trajectory]\nfile = "{name}"')
    _assert_one_error(_cli(tmp_path, scene), ["trajectory.file", name, "not a regular file", kind])


def test_scene_file_that_is_a_fifo(tmp_path):
    os.mkfifo(tmp_path / "scene.toml")
    _assert_one_error(_cli(tmp_path, "", name="scene.toml"), ["scene.toml", "cannot read scene file", "a FIFO"])


def test_abs_of_log_reaches_the_kernel_source():
    """z = abs(log(t) - 1): sympy leaves d/dt sign(log(t) - 1) unevaluated in the second derivative, which the
    kernel printer could not print (a traceback after validation). It is zero away from t = e, as DiracDelta
    is dropped for abs(t)."""
    raw = {"scene": {"rate_hz": 100, "duration_s": 0.1, "t0_s": 1.0},
           "trajectory": {"x": "0", "y": "0", "z": "abs(log(t) - 1)"}, "imu": [{"name": "a"}],
           "effects": {"gravity": True}}
    source = generate_source(scene_from_dict(raw), attitude=False, truth=False)
    assert "Derivative" not in source and "sign" in source


def test_names_assigned_then_read_in_one_branch_are_locals():
    """An IMU function's arguments are the names it reads before assigning them, in execution order: `w` is
    assigned and then read inside one `if` (bias_instability's interpolation weights), so it is no argument,
    while `s` and `state` are (the old walk took `w` for an argument the caller did not have: NameError)."""
    from imu_emulator.codegen.generate import _read_before_assigned
    code = "if s > 0:\n    w = s * 0.5\n    y = state[0] * w\nz = w + y\nq += 1"
    assert _read_before_assigned(ast.parse(code), set()) == ["s", "state", "q"]


def test_more_than_inline_imus_with_bias_instability_generate_closed_functions():
    """17 IMUs (> INLINE_IMUS) with bias_instability: every IMU function's arguments are names the kernel has at
    the call, never a local of the function (fast: source only; the compile is test_seventeen_imus_run)."""
    from imu_emulator.codegen.generate import INLINE_IMUS
    source = generate_source(scene_from_dict(_many_imus(INLINE_IMUS + 1)), attitude=False, truth=False)
    functions = [f for f in ast.parse(source).body if isinstance(f, ast.FunctionDef) and f.name.startswith("imu_")]
    assert len(functions) == INLINE_IMUS + 1
    for function in functions:
        stored = {n.id for n in ast.walk(function) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)}
        assert not stored & {a.arg for a in function.args.args}, function.name


def _many_imus(n):
    return {"scene": {"rate_hz": 100, "duration_s": 0.05}, "trajectory": {"x": "cos(t)", "y": "0", "z": "0"},
            "imu": [{"name": f"i{k}", "gyro": {"bias_instability": "1 deg/h"}} for k in range(n)],
            "effects": {"gravity": True, "bias_instability": True}}


@pytest.mark.slow
def test_seventeen_imus_with_bias_instability_run(tmp_path):
    """The issue's reproduction end to end (numba compiles 17 IMU functions: slow)."""
    import tomli_w
    env = {**os.environ, "PYTHONPATH": str(ROOT), "IMU_EMULATOR_CACHE": str(tmp_path / "cache")}
    (tmp_path / "scene.toml").write_text(tomli_w.dumps(_many_imus(17)))
    result = subprocess.run([sys.executable, "-m", "imu_emulator", "generate", "scene.toml", "-o", "out.csv",
                             "--quiet"], capture_output=True, text=True, cwd=tmp_path, timeout=900, env=env)
    assert result.returncode == 0, result.stderr
    lines = [line for line in (tmp_path / "out.csv").read_text().splitlines() if not line.startswith("#")]
    assert len(lines) == 1 + 5 * 17        # header, 5 samples of each IMU (the # lines state frame and units)
