"""`imu-emulator replay` and the fidelity figures (imu_emulator.analysis.fidelity)."""
import json

import numpy as np
import pytest

from imu_emulator.cli import main
from imu_emulator.analysis.fidelity import compare, lowpass
from tests.scene.logs.test_logs import ULOG, write_bag
from tests.support.paths import EXAMPLES


def test_compare_recovers_a_known_offset_and_bias():
    rate = 200.0
    t = np.arange(0, 20, 1 / rate)
    rng = np.random.default_rng(11)
    signal = np.column_stack([np.sin(2 * np.pi * f * t + p) for f, p in ((0.7, 0), (1.3, 1), (0.4, 2))])
    signal += lowpass(rng.normal(0, 1, signal.shape), rate, 3.0)        # broadband, so the lag is unique
    offset, bias = 0.0125, np.array([0.01, -0.02, 0.03])
    t_rec = t + offset                    # recorded(t + offset) = emulated(t): the recording lags
    recorded = signal + bias
    c = compare("gyro", t, signal, t_rec, recorded, rate, lowpass_hz=5.0)
    # 12.5 ms is 2.5 samples: the parabola through the correlation peak finds it to a small part of a
    # sample (measured 0.6 us; the interpolation of the recorded signal between its samples limits it)
    assert abs(c.time_offset_s - offset) < 0.01 / rate
    inside = (t >= t_rec[0]) & (t <= t_rec[-1])
    rec = np.column_stack([np.interp(t[inside], t_rec, recorded[:, i]) for i in range(3)])
    for i, a in enumerate(c.axes):
        assert a.correlation == pytest.approx(np.corrcoef(rec[:, i], signal[inside, i])[0, 1], abs=1e-12)
        assert a.bias == pytest.approx(np.mean(rec[:, i] - signal[inside, i]), abs=1e-12)
        assert a.rms_difference == pytest.approx(np.sqrt(np.mean((rec[:, i] - signal[inside, i]) ** 2)), abs=1e-12)


def test_replay_of_a_bag_with_its_own_exact_imu(tmp_path):
    # the bag's Imu topic holds the exact output of the bag's motion: the replay must agree with it
    times = 0.01 * np.arange(1, 501)
    bag = tmp_path / "run.mcap"
    write_bag(bag, times, imu_times=0.005 * np.arange(2, 1000))
    report = tmp_path / "report"
    assert main(["replay", str(bag), "--report", str(report), "--quiet"]) == 0
    figures = json.loads((report / "report.json").read_text())
    assert figures["recorded_imu"] == "/imu" and figures["rate_hz"] == pytest.approx(200.0)
    for c in figures["comparisons"]:
        assert abs(c["time_offset_s"]) < 1e-4
        for a in c["axes"]:
            assert a["correlation"] > 0.999999
            assert a["rms_difference"] < 1e-5
    assert (report / "gyro.png").stat().st_size > 10_000 and (report / "accel.png").exists()


def test_replay_of_the_px4_log_writes_figures_matching_a_direct_computation(tmp_path):
    from pyulog import ULog
    report = tmp_path / "r"
    assert main(["replay", str(ULOG), "--report", str(report), "--quiet"]) == 0
    figures = json.loads((report / "report.json").read_text())
    sc = ULog(str(ULOG)).get_dataset("sensor_combined").data
    t_rec = sc["timestamp"] * 1e-6
    from imu_emulator.output.formats.csv import read_columns      # past the '#' lines stating frames and units
    columns = read_columns(report / "emulated.csv", ("t", "gx", "gy", "gz"))
    emulated = np.column_stack([columns[name] for name in ("t", "gx", "gy", "gz")])
    gyro = figures["comparisons"][0]
    assert gyro["quantity"] == "gyro"
    for i, a in enumerate(gyro["axes"]):
        rec = np.interp(emulated[:, 0], t_rec, sc[f"gyro_rad[{i}]"])
        assert a["correlation"] == pytest.approx(np.corrcoef(rec, emulated[:, 1 + i])[0, 1], abs=1e-9)
        assert a["rms_difference"] == pytest.approx(np.sqrt(np.mean((rec - emulated[:, 1 + i]) ** 2)), rel=1e-9)


@pytest.mark.parametrize("argv, match", [
    (["replay", "nope.ulg", "--report", "r"], "nope.ulg: no such file"),
    (["replay", str(ULOG)], "give --report DIR, -o FILE or both"),
])
def test_replay_errors(argv, match, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and match in err and err.count("\n") == 1


def test_example_replay_scene_loads_the_shipped_log():
    from imu_emulator import load_scene
    scene = load_scene(EXAMPLES / "replay_px4.toml")
    assert scene.frame == "NED" and scene.trajectory.derivative == "smooth" and scene.attitude.kind == "quaternion"
    assert scene.trajectory.source.endswith("sample_appended_multiple.ulg:vehicle_local_position")
    assert scene.attitude.source.endswith("sample_appended_multiple.ulg:vehicle_attitude:0")
