"""--vary's operators (issue 25): KEY=DIST sets the value, KEY+=DIST perturbs the scene's value, KEY*=DIST scales
it. Checked on examples/two_imus.toml, whose imu1 is mounted (180, 0, 90) deg: the drawn scenes' values against
the scene's value and the distribution (sample mean within 5 standard errors sigma/sqrt(n), fixed root seed), and
the README's example end to end: imu1, upside down in a NED scene, reads +g on z (the `=` reading of the same option
replaced the mounting and read -g)."""

import numpy as np
import pyarrow.parquet as pq
import pytest

from imu_emulator.analysis import batch
from imu_emulator.cli import main
from imu_emulator.scene.load import tomllib
from tests.support.paths import EXAMPLES

TWO_IMUS = EXAMPLES / "two_imus.toml"
ROOT_SEED = 7
N = 400
G0 = 9.80665


def _values(vary, key, scene=TWO_IMUS, n=N):
    """The validated value at `key` ("imu.mounting_rpy_deg") of imu1 in each of n drawn scenes, shape (n, 3)."""
    tasks = batch.tasks_for(scene, n, ROOT_SEED, "unused", vary=[vary])
    return np.array([task.build().imus[1].values[key] for task in tasks])


def _within(values, mean, sigma):
    n = len(values)
    assert abs(values.mean() - mean) < 5 * sigma / np.sqrt(n), (values.mean(), mean)
    # sample variance: SE = sqrt(2 sigma^4 / (n - 1)) for normal draws
    assert abs(values.var(ddof=1) - sigma ** 2) < 5 * np.sqrt(2 / (n - 1)) * sigma ** 2


def test_plus_equals_perturbs_the_scenes_mounting():
    rpy = _values("imu1.mounting_rpy_deg+=normal(0,0.5) deg", "imu.mounting_rpy_deg")
    for j, scene_value in enumerate((180.0, 0.0, 90.0)):
        _within(rpy[:, j], scene_value, 0.5)


def test_equals_sets_the_value():
    rpy = _values("imu1.mounting_rpy_deg=normal(0,0.5) deg", "imu.mounting_rpy_deg")
    for j in range(3):
        _within(rpy[:, j], 0.0, 0.5)         # the scene's (180, 0, 90) is replaced


def test_times_equals_scales_the_scenes_value():
    arm = _values("imu1.lever_arm_m*=normal(1,0.01)", "imu.lever_arm_m")
    assert np.all(arm[:, [0, 2]] == 0.0)     # zero stays zero
    _within(arm[:, 1], -0.3, 0.3 * 0.01)


def test_plus_equals_converts_the_draws_unit_to_the_keys():
    """A scene value in deg/h plus draws in mdps: both in rad/s inside (1 mdps = 3.6 deg/h)."""
    raw = tomllib.loads(TWO_IMUS.read_text())
    raw["imu"][1]["gyro"] = {"bias_instability": "30 deg/h"}
    raw["effects"]["bias_instability"] = True
    values = _values("imu1.gyro.bias_instability+=normal(0,2) mdps", "imu.gyro.bias_instability", scene=raw)
    to_rad_s = np.pi / 180 / 3600
    for j in range(3):     # one draw per realization, the same on the three axes
        _within(values[:, j] / to_rad_s, 30.0, 2 * 3.6)
    assert np.all(values[:, 0] == values[:, 2])


def test_plus_equals_on_a_scene_number():
    tasks = batch.tasks_for(TWO_IMUS, 5, ROOT_SEED, "unused", vary=["scene.duration_s+=uniform(0,1)"])
    for task in tasks:
        drawn = task.drawn()["scene.duration_s+="]
        assert 0 <= drawn < 1 and task.build().duration_s == 10.0 + drawn     # the file says duration_s = 10.0


@pytest.mark.parametrize("option, message", [
    ("imu1.lever_arm_m*=normal(1,0.01) m", "*= scales the scene's value by a plain number"),
    ("imu1.gyro.misalignment+=normal(0,1) mrad", "+= works on parameters of one value or three"),
    ("params.nothing+=normal(0,1)", "params.nothing is not a number in the scene file"),
    ("imu1.mounting_rpy_deg+=normal(0,0.5) furlongs", "unknown unit 'furlongs'"),
    ("imu1.mounting_rpy_deg-=normal(0,0.5) deg", "expected KEY=DIST, KEY+=DIST or KEY*=DIST"),
])
def test_bad_operator_use_is_one_line_exit_2(tmp_path, capsys, option, message):
    assert main(["batch", str(TWO_IMUS), "--runs", "2", "-o", str(tmp_path / "out"), "--workers", "0",
                 "--vary", option]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and message in err, err


def test_the_same_key_twice_is_refused(tmp_path, capsys):
    assert main(["batch", str(TWO_IMUS), "--runs", "2", "-o", str(tmp_path / "out"), "--workers", "0",
                 "--vary", "imu1.mounting_rpy_deg=normal(0,1) deg",
                 "--vary", "imu1.mounting_rpy_deg+=normal(0,1) deg"]) == 2
    assert "imu1.mounting_rpy_deg is varied twice" in capsys.readouterr().err


def test_readme_example_reads_plus_g_on_z(tmp_path, monkeypatch):
    """The README's batch example, one realization in this process: imu1 is upside down (roll 180 deg) in a NED
    scene, so its z axis points up and reads +g on average (level circle: the horizontal centripetal 7.9 m/s^2
    leaks into z by at most sin of the perturbation's few tenths of a degree); imu0 reads -g."""
    out = tmp_path / "mc"
    assert main(["batch", str(TWO_IMUS), "--runs", "1", "--seed", "7", "-o", str(out), "--workers", "0", "--quiet",
                 "--vary", "imu0.gyro.bias_instability=uniform(1,5) deg/h",
                 "--vary", "imu1.mounting_rpy_deg+=normal(0,0.5) deg"]) == 0
    row = pq.read_table(out / "summary.parquet").to_pylist()[0]
    assert row["imu1.az.mean"] == pytest.approx(G0, abs=0.1)
    assert row["imu0.az.mean"] == pytest.approx(-G0, abs=0.1)
    assert {"imu1.mounting_rpy_deg+=[0] [deg]", "imu0.gyro.bias_instability [deg/h]"} <= set(row)
