"""Bad input gets one clear line naming what and where, and a non-zero exit; never a traceback."""
import subprocess
import sys

import numpy as np
import pytest

import imu_emulator as imu
from imu_emulator import DataError, SceneError, load_scene, scene_from_dict
from imu_emulator.runtime.simulation import Simulation
from tests.support.paths import REPO

ROOT = REPO

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

X = 'x = "cos(2*pi*f*t)"'
TRACKT = '[trajectory]\nx = "cos(2*pi*f*t)"\ny = "sin(2*pi*f*t)"\nz = "0"'

CASES = [
    # complex, undefined or overflowing constant parts are refused with the key and the part (issue 8 items 4, 8, 9)
    (X, 'x = "1/0"', ["trajectory.x", "1 / 0 divides by zero", "'1/0'"]),
    (X, 'x = "0**-1"', ["trajectory.x", "divides by zero"]),
    (X, 'x = "exp(1000)*t"', ["trajectory.x", "exp(1000) is beyond the float range"]),
    (X, 'x = "asin(2)*t"', ["trajectory.x", "asin(2) is outside the domain of asin"]),
    (X, 'x = "sqrt(-1)"', ["trajectory.x", "sqrt(-1) is outside the domain of sqrt"]),
    (X, 'x = "acos(-2)"', ["trajectory.x", "outside the domain of acos"]),
    (X, 'x = "log(0)"', ["trajectory.x", "outside the domain of log"]),
    (X, 'x = "(-1)**t"', ["trajectory.x", "(-1) ** t is complex"]),
    (X, 'x = "1e999*t"', ["trajectory.x", "1e309 is beyond the float range"]),
    ('f = 1.0', 'f = "(-8)**(1/3)"', ["params.f", "is complex", "'(-8)**(1/3)'"]),
    ('f = 1.0', 'f = "1e200"\ng = "f*f"', ["params.g", "beyond the float range"]),
    ('z = "0"', 'z = "0"\n[attitude]\nyaw = "exp(1000)*t"', ["attitude.yaw", "exp(1000) is beyond the float range"]),
    # size bounds and exact powers (item 11): no RecursionError, no sympy hang
    (X, 'x = "' + "sin(" * 200 + "t" + ")" * 200 + '"', ["trajectory.x", "characters long; the limit is 1000"]),
    (X, 'x = "' + "t*" * 2000 + 't"', ["trajectory.x", "the limit is 1000"]),
    (X, 'x = "' + "-" * 5000 + 't"', ["trajectory.x", "the limit is 1000"]),
    (X, 'x = "' + "-" * 900 + 't"', ["trajectory.x", "too large", "nested"]),
    (X, 'x = "' + "sin(" * 9 + "t" + ")" * 9 + '"', ["trajectory.x", "function calls nested", "limit 8"]),
    (X, 'x = "' + "+".join(["t"] * 17) + '"', ["trajectory.x", "uses of t", "limit 16"]),
    (X, 'x = "' + "*".join(["(" + "+".join(["1"] * 40) + ")"] * 8) + '"', ["trajectory.x", "terms", "limit 256"]),
    (X, 'x = "10**10**10"', ["trajectory.x", "10 ** 10 ** 10 is beyond the float range"]),
    (X, 'x = "t**(10**5)"', ["trajectory.x", "exponent beyond +-1000"]),
    # every number in range, the bound in the message (item 9, 21)
    ('rate_hz = 100', 'rate_hz = 5e-324', ["scene.rate_hz", "out of range", "0.001 to 1e+07 Hz"]),
    ('rate_hz = 100', 'rate_hz = 1.8e308', ["scene.rate_hz", "finite", "beyond 1.8e308 as inf"]),
    ('rate_hz = 100', 'rate_hz = 123456789', ["scene.rate_hz", "out of range"]),
    ('duration_s = 1.0', 'duration_s = 1e300', ["scene.duration_s", "out of range", "1e+09 s"]),
    ('duration_s = 1.0', 'duration_s = 1.0\ngravity_mps2 = 1e6', ["scene.gravity_mps2", "1000 m/s^2"]),
    ('name = "imu0"', 'name = "imu0"\nlever_arm_m = [1.8e308, 0, 0]', ["imu[0].lever_arm_m", "finite", "1000 m"]),
    ('name = "imu0"', 'name = "imu0"\nlever_arm_m = [1e5, 0, 0]', ["imu[0].lever_arm_m", "out of range", "1000 m"]),
    ('name = "imu0"', 'name = "imu0"\nmounting_rpy_deg = [0, 1e300, 0]', ["imu[0].mounting_rpy_deg", "10000 deg"]),
    (TRACKT, '[trajectory]\nshape = "circle"\nradius_m = 1.0\nfrequency_hz = 1.8e308',
     ["trajectory.frequency_hz", "finite"]),
    (TRACKT, '[trajectory]\nshape = "circle"\nradius_m = 1.0\nfrequency_hz = 1e300',
     ["trajectory.frequency_hz", "1e+06 Hz"]),
    (TRACKT, '[trajectory]\nshape = "static"\nposition_m = [0, 1e300, 0]', ["trajectory.position_m", "1e+08 m"]),
    ('[[imu]]\nname = "imu0"', "[[imu]]\n" * 257, ["imu", "257", "limit is 256"]),
    # time stamps must stay distinct and exact (item 7)
    ('duration_s = 1.0', 'duration_s = 1.0\nt0_s = 1e16', ["scene.t0_s", "2 s apart", "keep |t0_s| + duration_s below"]),
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
    ('gravity = true', 'gravity = true\ncentrifuge = true', ["effects.centrifuge", "unknown effect"]),
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
    with pytest.raises(DataError, match=r"trajectory.x = .sqrt\(t\).: its value is not finite at t = -0.5 s"):
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
    lines = [line for line in (tmp_path / "out.csv").read_text().splitlines() if not line.startswith("#")]
    assert lines[0] == "t,imu,ax,ay,az,gx,gy,gz"           # after the '#' lines stating frames and units
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
    code = ("import sys; from imu_emulator import load_scene; from imu_emulator.runtime.simulation import Simulation; "
            f"Simulation(load_scene({str(path)!r})).run(); print('sympy' in sys.modules)")
    env = {"IMU_EMULATOR_CACHE": str(tmp_path / "cache"), "PATH": "/usr/bin:/bin"}
    first = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    second = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert first.stdout.strip() == "True", first.stderr
    assert second.stdout.strip() == "False", second.stderr


# --- expressions that are not finite at some sample (issue 8 items 4, 10) ---------------------------------

@pytest.mark.filterwarnings("error::RuntimeWarning")   # no numpy warning printed before the clean error
@pytest.mark.parametrize("traj, attitude, head, message", [
    # only the position is undefined past t = 400.0001: no output uses it without --truth, yet it must stop
    ({"x": "log(400.0001 - t)"}, {}, {"rate_hz": 1, "duration_s": 402},
     "trajectory.x = 'log(400.0001 - t)': its value is not finite at t = 401.0 s"),
    # was ZeroDivisionError from inside numba (0.0**-2); the value itself is infinite at t = 0
    ({"y": "sin(t)**-2"}, {}, {"rate_hz": 10, "duration_s": 1.0},
     "trajectory.y = 'sin(t)**-2': its value is not finite at t = 0.0 s"),
    # sin(2*pi*0.5) is exactly 0 in the kernel's reduced phase but 1.2e-16 in numpy: found exactly
    ({"x": "1/sin(2*pi*t)"}, {}, {"rate_hz": 4, "duration_s": 1.0, "t0_s": 0.25},
     "trajectory.x = '1/sin(2*pi*t)': its value is not finite at t = 0.5 s"),
    # d2/dt2 t**1.5 = 0.75/sqrt(t): the value is fine at t = 0, the acceleration is not
    ({"x": "t**1.5"}, {}, {"rate_hz": 10, "duration_s": 1.0},
     "trajectory.x = 't**1.5': its second derivative is not finite at t = 0.0 s"),
    # the second derivative holds DiracDelta(t - 0.5), which the kernel (and the diagnosis) take as 0
    ({"x": "abs(t-0.5)**1.5"}, {}, {"rate_hz": 10, "duration_s": 1.0},
     "trajectory.x = 'abs(t-0.5)**1.5': its second derivative is not finite at t = 0.5 s"),
    ({"x": "t"}, {"roll": "sqrt(t - 0.5)"}, {"rate_hz": 10, "duration_s": 1.0},
     "attitude.roll = 'sqrt(t - 0.5)': its value is not finite at t = 0.0 s"),
])
def test_nonfinite_expression_names_key_expression_derivative_and_first_bad_time(traj, attitude, head, message):
    scene = scene_from_dict({"scene": head, "trajectory": {"x": "0", "y": "0", "z": "0", **traj},
                             "attitude": attitude, "imu": [{"name": "a"}]})
    with pytest.raises(DataError) as info:
        Simulation(scene).run()
    assert str(info.value).startswith(message), str(info.value)


@pytest.mark.parametrize("text, words", [
    ("tan(pi/2)*t", ["trajectory.x", "infinite", "'tan(pi/2)*t'"]),     # sympy: zoo; math.tan: 1.6e16
    ("t/(t - t)", ["trajectory.x", "infinite"]),
    # its numbers stay literals (a time-free zero): not lifted into run-time slots that would hide the zero
    ("t/(2 - 2)", ["trajectory.x", "infinite"]),
])
def test_symbolically_infinite_expression_is_refused_before_numba(text, words):
    scene = scene_from_dict({"scene": {"rate_hz": 10, "duration_s": 1.0},
                             "trajectory": {"x": text, "y": "0", "z": "0"}, "imu": [{"name": "a"}]})
    with pytest.raises(SceneError) as info:
        Simulation(scene)
    assert all(w in str(info.value) for w in words), str(info.value)


# --- tracks (items 5, 12, 20) -----------------------------------------------------------------------------

def _euler_track_scene(tmp_path, attitude):
    rows = [f"{i * 0.01},{i * 0.01},0,0,0,0,{0.1 * i}" for i in range(30)]
    (tmp_path / "track.csv").write_text("t,x,y,z,roll,pitch,yaw\n" + "\n".join(rows) + "\n")
    return _write(tmp_path, f'[scene]\nrate_hz = 100\n[trajectory]\nfile = "track.csv"\n{attitude}'
                            '[[imu]]\nname = "a"\n')


@pytest.mark.parametrize("attitude", ["", '[attitude]\nmode = "euler"\n'])
def test_track_angles_with_euler_mode_and_no_expressions_is_refused(tmp_path, attitude):
    with pytest.raises(SceneError) as info:
        load_scene(_euler_track_scene(tmp_path, attitude))
    assert 'mode = "file"' in str(info.value) and "track.csv" in str(info.value)


def test_track_angles_used_with_file_mode(tmp_path):
    scene = load_scene(_euler_track_scene(tmp_path, '[attitude]\nmode = "file"\n'))
    assert scene.attitude_mode == "file"


def test_non_utf8_scene_file_is_one_line_naming_the_file(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_bytes(GOOD.encode().replace(b'name = "imu0"', b'name = "imu\xff"'))
    result = _cli("generate", str(path), "-o", str(tmp_path / "out.csv"))
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert str(path) in result.stderr and "not UTF-8" in result.stderr


def test_non_utf8_track_file_names_the_file(tmp_path):
    text = _track(tmp_path, [(i * 0.01, i, 0, 0) for i in range(20)])
    (tmp_path / "track.csv").write_bytes(b"t,x,y,z\n0,0,0,0\n1,\xe9,0,0\n")
    with pytest.raises(SceneError, match=r"track.csv: not UTF-8 text \(byte 18 is 0xe9\)"):
        load_scene(_write(tmp_path, text))


# --- the run's size, before it starts (item 15) -----------------------------------------------------------

HUGE = GOOD.replace("rate_hz = 100", "rate_hz = 1e7").replace("duration_s = 1.0", "duration_s = 1e5")


def test_csv_beyond_the_free_disk_is_refused_with_the_figure(tmp_path):
    result = _cli("generate", str(_write(tmp_path, HUGE)), "-o", str(tmp_path / "out.csv"))
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    # 1e12 samples x (7 values x 25 B, each with its comma or the newline, + "imu0" and its comma) = 180e12 B
    assert "1000000000000 samples x 1 IMU(s)" in result.stderr and f"{180e12 / 2 ** 30:.3g} GiB" in result.stderr
    assert "--allow-large" in result.stderr and not (tmp_path / "out.csv").exists()


def test_npz_beyond_memory_is_refused_and_allow_large_overrides_only_a_csv(tmp_path):
    from imu_emulator.output.formats import check_output
    from imu_emulator.runtime.memory import RunSizeError
    scene = load_scene(_write(tmp_path, HUGE))
    check_output(scene, tmp_path / "out.csv", truth=True, allow_large=True)
    with pytest.raises(RunSizeError, match="in memory.*write a .csv"):
        check_output(scene, tmp_path / "out.npz", truth=False, allow_large=True)


def test_simulate_refuses_a_run_beyond_memory_before_allocating(tmp_path):
    from imu_emulator.runtime.memory import RunSizeError
    with pytest.raises(RunSizeError, match=r"simulate: 1000000000000 samples x 1 IMU\(s\) take"):
        imu.simulate(load_scene(_write(tmp_path, HUGE)))


@pytest.mark.parametrize("column, value, words", [
    (1, "1e300", ["column 'x'", "1e+300 is out of range", "1e+08 m"]),
    (6, "-2e9", ["column 'yaw'", "out of range", "1e+09 rad"]),
])
def test_track_magnitudes_are_checked_with_the_bound(tmp_path, column, value, words):
    rows = [[i * 0.01, 0, 0, 0, 0, 0, 0] for i in range(20)]
    rows[3][column] = value
    (tmp_path / "track.csv").write_text("t,x,y,z,roll,pitch,yaw\n" + "\n".join(",".join(map(str, r)) for r in rows))
    path = _write(tmp_path, '[scene]\nrate_hz = 100\n[trajectory]\nfile = "track.csv"\n[attitude]\nmode = "file"\n'
                            '[[imu]]\nname = "a"\n')
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert all(w in str(info.value) for w in ["track.csv", "row 5", *words]), str(info.value)


def test_overflow_of_finite_terms_is_reported_as_such():
    # yaw rate 1e160 rad/s is finite, w x (w x r) = 1e320 * 0.1 m is not: no expression to blame
    scene = scene_from_dict({"scene": {"rate_hz": 10, "duration_s": 0.5}, "trajectory": {"x": "0", "y": "0", "z": "0"},
                             "attitude": {"yaw": "1e160*t"}, "imu": [{"name": "a", "lever_arm_m": [0.1, 0, 0]}],
                             "effects": {"lever_arm": True}})
    with pytest.raises(DataError, match=r"non-finite value at t = 0.0 s \(sample 0\) although every expression"):
        Simulation(scene).run()


def test_track_quaternions_with_euler_mode_and_no_expressions_is_refused(tmp_path):
    rows = [f"{i * 0.01},{i * 0.01},0,0,1,0,0,0" for i in range(30)]
    (tmp_path / "track.csv").write_text("t,x,y,z,qw,qx,qy,qz\n" + "\n".join(rows) + "\n")
    path = _write(tmp_path, '[scene]\nrate_hz = 100\n[trajectory]\nfile = "track.csv"\n[[imu]]\nname = "a"\n')
    with pytest.raises(SceneError, match=r'track.csv has qw, qx, qy, qz columns.*mode = "file"'):
        load_scene(path)
