"""Bad input gets one clear line naming what and where, and a non-zero exit; never a traceback."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imu_emulator import DataError, SceneError, load_scene, scene_from_dict
from imu_emulator.simulation import Simulation

ROOT = Path(__file__).resolve().parent.parent

GOOD = """
[scene]
rate_hz = 100
duration_s = 1.0
[params]
f = 1.0
[trajectory]
x = "cos(2*pi*f*t)"
y = "sin(2*pi*f*t)"
z = "0"
[[imu]]
name = "imu0"
[effects]
gravity = true
"""

CASES = [
    # (what to replace in GOOD, by what, expected words in the message)
    ('x = "cos(2*pi*f*t)"', 'x = "foo(t)"', ["trajectory.x", "unknown function 'foo'"]),
    ('x = "cos(2*pi*f*t)"', 'x = "__import__(\'os\').system(\'true\')"', ["trajectory.x", "__import__"]),
    ('x = "cos(2*pi*f*t)"', 'x = "cos(2*pi*g*t)"', ["trajectory.x", "unknown name 'g'"]),
    ('x = "cos(2*pi*f*t)"', 'x = "cos(2*pi*f*t"', ["trajectory.x", "syntax error"]),
    ('x = "cos(2*pi*f*t)"', 'x = "t^2"', ["trajectory.x", "'**'"]),
    ('x = "cos(2*pi*f*t)"', 'x = "t.real"', ["trajectory.x", "not allowed"]),
    ('x = "cos(2*pi*f*t)"', 'x = "[t for t in ()]"', ["trajectory.x", "not allowed"]),
    ('x = "cos(2*pi*f*t)"', 'x = "lambda: 1"', ["trajectory.x", "not allowed"]),
    ('x = "cos(2*pi*f*t)"', 'x = "cos(t, t)"', ["trajectory.x", "takes 1 argument"]),
    ('rate_hz = 100', 'rate_hz = -5', ["scene.rate_hz", "positive"]),
    ('rate_hz = 100', 'rate_hz = "fast"', ["scene.rate_hz", "number"]),
    ('rate_hz = 100', '', ["scene.rate_hz", "missing"]),
    ('duration_s = 1.0', 'duration_s = 1.0\nframe = "XYZ"', ["scene.frame", "'ENU'"]),
    ('duration_s = 1.0', 'duration_s = 1.0\nrate = 5', ["scene.rate", "unknown key"]),
    ('f = 1.0', 'f = "2*t"', ["params.f", "constants"]),
    ('f = 1.0', 'sin = 1.0', ["params.sin", "not a usable name"]),
    ('gravity = true', 'gravity = true\ncoriolis = true', ["effects.coriolis", "unknown effect"]),
    ('gravity = true', 'gravity = "yes"', ["effects.gravity", "true or false"]),
    ('name = "imu0"', 'name = "imu0"\nlever_arm_m = [1, 2]', ["imu[0].lever_arm_m", "three numbers"]),
    ('name = "imu0"', 'name = "imu0"\n[[imu]]\nname = "imu0"', ["imu[1].name", "used twice"]),
    ('[[imu]]\nname = "imu0"', '', ["imu", "at least one"]),
    ('z = "0"', 'z = "0"\n[attitude]\nmode = "sideways"', ["attitude.mode", "'tangent'"]),
    ('z = "0"', 'z = "0"\n[attitude]\nmode = "file"', ["attitude.mode", "roll, pitch, yaw or qw, qx, qy, qz columns"]),
    ('[trajectory]\nx = "cos(2*pi*f*t)"\ny = "sin(2*pi*f*t)"\nz = "0"',
     '[trajectory]\nfile = "nowhere.csv"', ["trajectory.file", "no such file"]),
    ('[trajectory]\nx = "cos(2*pi*f*t)"\ny = "sin(2*pi*f*t)"\nz = "0"',
     '[trajectory]\nshape = "circle"\nradius_m = 1.0', ["trajectory.frequency_hz", "missing"]),
    ('[trajectory]\nx = "cos(2*pi*f*t)"\ny = "sin(2*pi*f*t)"\nz = "0"',
     '[trajectory]\nshape = "circle"\nradius_m = 1.0\nfrequency_hz = 1.0\nspeed = 3', ["trajectory.speed", "unknown key"]),
    ('rate_hz = 100', 'rate_hz = 100\nrate_hz = 200', ["not valid TOML"]),
]


def _write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("old, new, words", CASES, ids=[c[2][0] + ":" + c[2][-1] for c in CASES])
def test_bad_scene_names_the_key_and_reason(tmp_path, old, new, words):
    assert old in GOOD
    path = _write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    message = str(info.value)
    assert "\n" not in message
    for word in words:
        assert word in message, f"{word!r} not in {message!r}"
    assert str(path) in message


def test_good_scene_loads(tmp_path):
    scene = load_scene(_write(tmp_path, GOOD))
    assert scene.effects == {"gravity"} and scene.n_samples == 100


def _track(tmp_path, rows):
    (tmp_path / "track.csv").write_text("t,x,y,z\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n")
    return GOOD.replace('[trajectory]\nx = "cos(2*pi*f*t)"\ny = "sin(2*pi*f*t)"\nz = "0"',
                        '[trajectory]\nfile = "track.csv"\nderivative = "spline5"').replace("duration_s = 1.0", "")


def test_nan_in_track_file_names_file_row_and_column(tmp_path):
    rows = [(i * 0.01, i, 0, 0) for i in range(20)]
    rows[7] = (0.07, "nan", 0, 0)
    with pytest.raises(SceneError) as info:
        load_scene(_write(tmp_path, _track(tmp_path, rows)))
    message = str(info.value)
    assert "track.csv" in message and "x" in message and "9" in message  # data row 8 is line 9


def test_non_monotonic_time_in_track_file(tmp_path):
    rows = [(i * 0.01, i, 0, 0) for i in range(20)]
    rows[5], rows[6] = rows[6], rows[5]
    with pytest.raises(SceneError) as info:
        load_scene(_write(tmp_path, _track(tmp_path, rows)))
    assert "track.csv" in str(info.value) and "time" in str(info.value)


def test_too_few_samples_for_the_method_is_an_error(tmp_path):
    rows = [(i * 0.01, i, 0, 0) for i in range(3)]
    text = _track(tmp_path, rows).replace('"spline5"', '"central6"')
    with pytest.raises((SceneError, DataError)) as info:
        Simulation(load_scene(_write(tmp_path, text)))
    assert "central6" in str(info.value)


def test_expression_outside_its_domain_is_a_clear_error_not_nan():
    scene = scene_from_dict({"scene": {"rate_hz": 10, "duration_s": 1.0, "t0_s": -0.5},
                             "trajectory": {"x": "sqrt(t)", "y": "0", "z": "0"}, "imu": [{"name": "a"}]})
    with pytest.raises(DataError, match="non-finite value at t = -0.5"):
        Simulation(scene).run()


def test_lever_arm_without_the_effect_is_reported(tmp_path):
    text = GOOD.replace('name = "imu0"', 'name = "imu0"\nlever_arm_m = [0.1, 0, 0]')
    scene = load_scene(_write(tmp_path, text))
    assert any("lever_arm_m is ignored" in w for w in scene.warnings)


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "imu_emulator", *args], capture_output=True, text=True, cwd=cwd)


def test_cli_bad_scene_is_one_line_and_exit_2(tmp_path):
    path = _write(tmp_path, GOOD.replace('x = "cos(2*pi*f*t)"', 'x = "foo(t)"'))
    result = _cli("generate", str(path), "-o", str(tmp_path / "out.csv"))
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("error: ")
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize("args, words", [
    (["generate", "missing.toml", "-o", "out.csv"], ["missing.toml", "cannot read"]),
    (["generate", "GOOD", "-o", "out.txt"], ["out.txt", ".csv or .npz"]),
    (["generate", "GOOD", "-o", "nodir/out.csv"], ["does not exist"]),
])
def test_cli_bad_paths(tmp_path, args, words):
    good = _write(tmp_path, GOOD)
    args = [str(good) if a == "GOOD" else a for a in args]
    result = _cli(*args, cwd=tmp_path)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    for word in words:
        assert word in result.stderr


def test_cli_generate_csv_layout_and_values(tmp_path):
    text = GOOD.replace('[[imu]]\nname = "imu0"', '[[imu]]\nname = "imu0"\n[[imu]]\nname = "imu1"')
    path = _write(tmp_path, text)
    result = _cli("generate", str(path), "-o", str(tmp_path / "out.csv"), "--quiet")
    assert result.returncode == 0, result.stderr
    lines = (tmp_path / "out.csv").read_text().splitlines()
    assert lines[0] == "t,imu,ax,ay,az,gx,gy,gz"
    assert len(lines) == 1 + 2 * 100
    assert [line.split(",")[1] for line in lines[1:5]] == ["imu0", "imu1", "imu0", "imu1"]
    # x = cos(2 pi t), gravity on, attitude level: ax = -(2 pi)^2 cos(2 pi t), az = g
    row = lines[1 + 2 * 10].split(",")   # sample 10: t = 0.1
    t = float(row[0])
    assert t == pytest.approx(0.1)
    assert float(row[2]) == pytest.approx(-(2 * np.pi) ** 2 * np.cos(2 * np.pi * t), abs=1e-9)
    assert float(row[4]) == pytest.approx(9.80665, abs=1e-12)


def test_cli_generate_npz_with_truth(tmp_path):
    path = _write(tmp_path, GOOD)
    result = _cli("generate", str(path), "-o", str(tmp_path / "out.npz"), "--truth", "--quiet")
    assert result.returncode == 0, result.stderr
    data = np.load(tmp_path / "out.npz")
    assert data["accel"].shape == (1, 100, 3) and list(data["imu_names"]) == ["imu0"]
    np.testing.assert_allclose(data["position"][:, 0], np.cos(2 * np.pi * data["t"]), atol=1e-12)
    np.testing.assert_allclose(data["velocity"][:, 1], 2 * np.pi * np.cos(2 * np.pi * data["t"]), atol=1e-12)


def test_second_run_uses_the_cached_kernel_without_sympy(tmp_path):
    path = _write(tmp_path, GOOD)
    code = ("import sys; from imu_emulator import load_scene; from imu_emulator.simulation import Simulation; "
            f"Simulation(load_scene({str(path)!r})).run(); print('sympy' in sys.modules)")
    env = {"IMU_EMULATOR_CACHE": str(tmp_path / "cache"), "PATH": "/usr/bin:/bin"}
    first = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    second = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert first.stdout.strip() == "True", first.stderr
    assert second.stdout.strip() == "False", second.stderr
