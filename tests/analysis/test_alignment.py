"""imu_emulator.analysis.alignment and `imu-emulator align`: the emulator knows the exact answer.

The oracle is the scene itself: B's mounting_rpy_deg (as a matrix from scipy's Rotation, independent of our
rotations.py), B's lever arm, and the time offset and drift written into B's stamps."""
import json
import sys
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_emulator.analysis.alignment import AlignOptions, align
from imu_emulator.cli import main
from imu_emulator.errors import DataError
from imu_emulator.analysis.imulog import ImuLog
from tests.support.paths import TOOLS

sys.path.insert(0, str(TOOLS))
import bench_align as bench  # noqa: E402


def mount_matrix(rpy_deg):
    roll, pitch, yaw = rpy_deg
    return Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_matrix()


def rotation_error_deg(C, rpy_deg):
    return np.degrees(Rotation.from_matrix(C @ mount_matrix(rpy_deg).T).magnitude())


def wrapped(x):
    return (np.asarray(x) + 180.0) % 360.0 - 180.0


@pytest.fixture(scope="module")
def case_a():
    """Case a of the accuracy table, 20 s instead of 60 (same motion, same mounting, lever arm, 3.7 ms)."""
    return bench.two_logs(bench.three_axis_scene(seed=3, duration_s=20.0))


@pytest.mark.parametrize("lever_arm", [False, True])
def test_exact_data_recovers_mounting_offset_and_lever_arm(case_a, lever_arm):
    a, b = case_a
    result = align(a, b, AlignOptions(lever_arm=lever_arm))
    assert rotation_error_deg(result.C, bench.MOUNT_B_DEG) < 1e-6
    np.testing.assert_allclose(wrapped(result.euler_deg - np.array(bench.MOUNT_B_DEG)), 0, atol=1e-6)
    q = Rotation.from_matrix(mount_matrix(bench.MOUNT_B_DEG)).as_quat()     # x, y, z, w
    q = np.roll(q, 1) * np.sign(q[3])
    np.testing.assert_allclose(result.quaternion_wxyz, q, atol=1e-8)
    assert abs(result.time_offset_s - bench.TIME_OFFSET_S) < 1e-6
    np.testing.assert_allclose(result.gyro_bias_diff, 0, atol=1e-9)
    assert all(result.observable[k] for k in ("roll", "pitch", "yaw", "time_offset_s")) and not result.reasons
    if lever_arm:
        np.testing.assert_allclose(result.lever_arm_m, bench.LEVER_B_M, atol=1e-6)
        assert result.observable["lever_arm_m"] == [True, True, True]
    else:
        assert result.lever_arm_m is None


@pytest.mark.parametrize("mount", [(180.0, 0.0, 0.0), (0.0, 0.0, 180.0), (180.0, 0.0, 90.0),
                                   (-90.0, 30.0, 180.0)])
def test_180_degree_mountings(mount):
    # 180° about some axis: the trace method of DCM -> quaternion loses all digits there, and the Kabsch sign
    # fix decides between the rotation and its reflection.
    a, b = bench.two_logs(bench.three_axis_scene(seed=1, duration_s=10.0, mount_b=mount))
    result = align(a, b)
    assert rotation_error_deg(result.C, mount) < 1e-6
    angle = np.degrees(Rotation.from_matrix(result.C).magnitude())
    assert angle == pytest.approx(np.degrees(Rotation.from_matrix(mount_matrix(mount)).magnitude()), abs=1e-6)
    assert abs(result.time_offset_s - bench.TIME_OFFSET_S) < 1e-6


@pytest.mark.parametrize("pitch", [89.99, 90.0, -89.999])
def test_mounting_near_gimbal_lock_of_the_euler_output(pitch):
    mount = (25.0, pitch, -60.0)
    a, b = bench.two_logs(bench.three_axis_scene(seed=2, duration_s=10.0, mount_b=mount))
    result = align(a, b)
    assert rotation_error_deg(result.C, mount) < 1e-6       # the estimate itself knows no gimbal lock
    assert result.euler_deg[1] == pytest.approx(pitch, abs=1e-6)
    # Roll and yaw are ill-conditioned by 1/cos(pitch) there; scipy's decomposition of the true matrix is the
    # oracle for the convention at the lock (roll 0, yaw takes the combination).
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)        # scipy says "Gimbal lock detected" at ±90°
        expected = Rotation.from_matrix(mount_matrix(mount)).as_euler("ZYX", degrees=True)[::-1] \
            if abs(pitch) == 90.0 else np.array(mount)
    tolerance = 1e-6 / max(np.cos(np.radians(pitch)), 1e-6)
    np.testing.assert_allclose(wrapped(result.euler_deg - expected), 0, atol=max(tolerance, 1e-6))
    assert any("gimbal lock" in note for note in result.notes)


@pytest.mark.parametrize("rate_a, rate_b", [(100.0, 400.0), (400.0, 100.0)])
@pytest.mark.parametrize("offset", [3.7e-3, -3.7e-3, 0.2537])
def test_different_rates_and_either_sensor_lagging(rate_a, rate_b, offset):
    # B's samples start 1.23 ms after A's, at another rate: no B instant coincides with an A instant, and the
    # offset is no multiple of either period. offset > 0: B's stamps run ahead of A's; < 0: behind.
    scene = bench.three_axis_scene(seed=4, rate_hz=rate_a, duration_s=12.0)
    a, b = bench.two_logs(scene, offset_s=offset, rate_b_hz=rate_b, t0_b_s=1.23e-3)
    result = align(a, b, AlignOptions(lever_arm=True))
    assert result.base == ("A" if rate_a < rate_b else "B")          # the lower rate is the common base
    assert rotation_error_deg(result.C, bench.MOUNT_B_DEG) < 1e-6
    assert abs(result.time_offset_s - offset) < 1e-6
    np.testing.assert_allclose(result.lever_arm_m, bench.LEVER_B_M, atol=1e-5)


@pytest.mark.parametrize("rate_b", [200.0, 500.0])
def test_clock_drift(rate_b):
    # 50 ppm over 30 s: the two clocks drift 1.5 ms apart, B's stamps ahead by 3.7 ms at t = 10 s.
    scene = bench.three_axis_scene(seed=5, duration_s=30.0)
    a, b = bench.two_logs(scene, rate_b_hz=rate_b, t0_b_s=0.7e-3, drift_ppm=50.0, t_ref_s=10.0)
    result = align(a, b, AlignOptions(drift=True))
    assert result.drift_ppm == pytest.approx(50.0, abs=1e-3)
    expected = bench.TIME_OFFSET_S + 50e-6 * (result.time_reference_s - 10.0)   # the offset at its reference
    assert abs(result.time_offset_s - expected) < 1e-6
    assert rotation_error_deg(result.C, bench.MOUNT_B_DEG) < 1e-6
    assert result.observable["clock_drift_ppm"]


def test_rotation_about_one_axis_reports_the_angle_it_cannot_see():
    # Yaw only, at a varying rate: the gyros see one direction, so a rotation of B about A's z axis changes
    # nothing they measure. A is unrotated, so that is the yaw of the z-y-x angles (Rz is applied last).
    scene = bench.three_axis_scene(seed=0, duration_s=10.0)
    scene["attitude"] = {"mode": "euler", "yaw": "0.5*sin(2*pi*0.4*t) + 0.2*sin(2*pi*1.1*t)"}
    a, b = bench.two_logs(scene)
    result = align(a, b)
    assert result.observable["yaw"] is False
    assert result.observable["roll"] and result.observable["pitch"]
    assert len(result.reasons) == 1 and "(+0.000, +0.000, +1.000)" in result.reasons[0]
    # The two angles it can see are still exact.
    assert result.observable["time_offset_s"] and abs(result.time_offset_s - bench.TIME_OFFSET_S) < 1e-6


def test_too_little_motion_is_unobservable_not_confident():
    scene = bench.three_axis_scene(seed=0, duration_s=10.0)
    scene["attitude"] = {"mode": "euler"}           # no rotation at all; translation only
    a, b = bench.two_logs(scene)
    result = align(a, b)
    assert not any(result.observable[k] for k in ("roll", "pitch", "yaw", "time_offset_s"))
    assert len(result.reasons) == 4
    assert any("too little motion" in note for note in result.notes)
    json.dumps(result.to_json(), allow_nan=False)       # infinite σ become null, not invalid JSON


def test_car_drive_case_e_reports_unobservable_axes():
    # Case e: a car that mostly yaws. Gyros alone cannot see a rotation about the yaw axis; the
    # accelerometers (gravity and the car's horizontal acceleration) can, but the lever arm along z then
    # escapes: centripetal and angular-acceleration terms of a yaw rotation act in the horizontal plane only.
    a, b = bench.two_logs(bench.car_scene(seed=0, duration_s=40.0))
    gyro_only = align(a, b)
    assert gyro_only.observable["yaw"] is False and gyro_only.observable["roll"] and gyro_only.observable["pitch"]
    both = align(a, b, AlignOptions(lever_arm=True))
    assert both.observable["yaw"] and both.observable["roll"] and both.observable["pitch"]
    assert both.observable["lever_arm_m"] == [True, True, False]
    assert rotation_error_deg(both.C, bench.MOUNT_B_DEG) < 1e-6
    np.testing.assert_allclose(both.lever_arm_m[:2], bench.LEVER_B_M[:2], atol=1e-5)


def test_reported_sigma_matches_the_scatter_of_noisy_estimates(case_a):
    # White noise of 3.5e-3 rad/s per sample on each gyro axis of both sensors (BMI088-class: 0.014 °/s/√Hz
    # times √200 Hz, specs/sensor-errors.md), 20 seeds. If the covariance (final Jacobian scaled by the residual variance) is right,
    # z = error/σ is standard normal per parameter, and the mean of z² over 4 parameters (3 rotation axes, Δt)
    # x 20 seeds = 80 values has mean 1 and standard deviation sqrt(2/80) = 0.16; [0.5, 1.5] is about ±3 of
    # those. (Interpolating B's noise biases Δt by a term growing as σ², small against σ at this level.)
    a, b = case_a
    truth = Rotation.from_matrix(mount_matrix(bench.MOUNT_B_DEG))
    z2 = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        na = ImuLog("A", a.t, a.accel, a.gyro + rng.normal(0, 3.5e-3, a.gyro.shape))
        nb = ImuLog("B", b.t, b.accel, b.gyro + rng.normal(0, 3.5e-3, b.gyro.shape))
        result = align(na, nb)
        err = (Rotation.from_matrix(result.C) * truth.inv()).as_rotvec()     # left error, A's frame
        cov = result.extra["rotation_covariance_rad2"]
        z2.append(err @ np.linalg.solve(cov, err) / 3)
        z2.append(((result.time_offset_s - bench.TIME_OFFSET_S) / result.sigma["time_offset_s"]) ** 2)
    assert 0.5 < np.mean(z2) < 1.5


# --- the command line -------------------------------------------------------------------------------------

HEADER = "t,ax,ay,az,gx,gy,gz"


def write_plain(path, log: ImuLog, header=HEADER):
    np.savetxt(path, np.column_stack([log.t, log.accel, log.gyro]), delimiter=",", header=header,
               comments="", fmt="%.17g")


def run_cli(argv, capsys):
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_cli_plain_logs_at_different_rates_with_json(tmp_path, capsys):
    scene = bench.three_axis_scene(seed=6, rate_hz=100.0, duration_s=12.0)
    a, b = bench.two_logs(scene, offset_s=-0.0123, rate_b_hz=400.0, t0_b_s=1e-3)
    write_plain(tmp_path / "a.csv", a)
    write_plain(tmp_path / "b.csv", b)
    out_json = tmp_path / "r.json"
    code, out, err = run_cli(["align", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"), "--lever-arm",
                              "--json", str(out_json)], capsys)
    assert code == 0, err
    data = json.loads(out_json.read_text())
    for key in ("quaternion_wxyz", "euler_deg", "time_offset_s", "lever_arm_m", "sigma", "observable"):
        assert key in data
    np.testing.assert_allclose(wrapped(np.array(data["euler_deg"]) - bench.MOUNT_B_DEG), 0, atol=1e-6)
    assert data["time_offset_s"] == pytest.approx(-0.0123, abs=1e-6)
    np.testing.assert_allclose(data["lever_arm_m"], bench.LEVER_B_M, atol=1e-5)
    assert "roll 10.000000" in out and "pitch -25.000000" in out and "yaw 137.000000" in out


def test_report_prints_no_sign_on_a_value_that_rounds_to_zero():
    """An offset of -1e-13 ms is printed 0.000000, as +1e-13 is (the parquet run of the test below gave -0.000000)."""
    from imu_emulator.commands.align import _fixed
    assert _fixed(-1e-13, 6) == _fixed(1e-13, 6) == "0.000000"
    assert _fixed(-0.0000005001, 6) == "-0.000001" and _fixed(-2.5, 1) == "-2.5"


@pytest.mark.parametrize("suffix", [".csv", ".npz", ".parquet"])
def test_cli_one_emulator_file_with_two_imus(tmp_path, capsys, suffix):
    # Same file for A and B: the emulator's CSV (an imu column) or NPZ (imu_names), IMUs picked by name.
    from imu_emulator import scene_from_dict
    from imu_emulator.output.formats import open_writer
    from imu_emulator.runtime.simulation import Simulation
    scene_dict = bench.three_axis_scene(seed=7, duration_s=8.0)
    scene_dict["imu"].insert(0, {"name": "other"})
    scene = scene_from_dict(scene_dict)
    path = tmp_path / f"run{suffix}"
    writer = open_writer(path, scene.imu_names, truth=False)
    writer.write(Simulation(scene, attitude=False).run())
    writer.close()
    code, out, err = run_cli(["align", str(path), str(path), "--imu-a", "a", "--imu-b", "b"], capsys)
    assert code == 0, err
    assert "roll 10.000000" in out and "yaw 137.000000" in out and "time offset t_B - t_A: 0.000000" in out
    code, _, err = run_cli(["align", str(path), str(path)], capsys)
    assert code == 2 and err.count("\n") == 1 and "--imu-a" in err


def test_cli_parquet_and_csv_of_one_run_align_alike(tmp_path, capsys):
    """`generate` to .parquet (the large-run format, the only one `batch` writes) and to .csv: `align` reads
    both through the same column schema and reports the same result (Parquet's time stamps are integer ns, the
    CSV's the shortest text of the seconds: equal to well below the reported digits)."""
    import tomli_w
    scene_dict = bench.three_axis_scene(seed=7, duration_s=8.0)
    scene = tmp_path / "s.toml"
    scene.write_text(tomli_w.dumps(scene_dict))
    results = {}
    for suffix in (".csv", ".parquet"):
        path = tmp_path / f"run{suffix}"
        assert main(["generate", str(scene), "-o", str(path), "--quiet"]) == 0
        code, out, err = run_cli(["align", str(path), str(path), "--imu-a", "a", "--imu-b", "b", "--lever-arm",
                                  "--json", str(tmp_path / f"{suffix}.json")], capsys)
        assert code == 0, err
        results[suffix] = json.loads((tmp_path / f"{suffix}.json").read_text())
    csv, parquet = results[".csv"], results[".parquet"]
    assert csv.keys() == parquet.keys()
    for key in ("quaternion_wxyz", "euler_deg", "time_offset_s", "lever_arm_m"):
        np.testing.assert_allclose(parquet[key], csv[key], rtol=1e-9, atol=1e-12, err_msg=key)
    assert parquet["observable"] == csv["observable"]


def bad_input_cases(tmp_path, a: ImuLog, b: ImuLog):
    write_plain(tmp_path / "a.csv", a)
    write_plain(tmp_path / "names.csv", b, header="time,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z")
    write_plain(tmp_path / "late.csv", ImuLog("late", b.t + 1000.0, b.accel, b.gyro))
    gyro = b.gyro.copy()
    gyro[57, 1] = np.nan
    write_plain(tmp_path / "nan.csv", ImuLog("nan", b.t, b.accel, gyro))
    write_plain(tmp_path / "short.csv", ImuLog("short", b.t[:10], b.accel[:10], b.gyro[:10]))
    return {"names.csv": "missing columns t, ax, ay, az, gx, gy, gz",
            "late.csv": "no overlap in time",
            "nan.csv": "row 59, column 'gy': value nan is not finite",     # header is row 1, sample 57 row 59
            "short.csv": "too short: 10 samples"}


def test_cli_bad_input_gives_one_line_errors(tmp_path, capsys, case_a):
    a, b = case_a
    for name, message in bad_input_cases(tmp_path, a, b).items():
        code, out, err = run_cli(["align", str(tmp_path / "a.csv"), str(tmp_path / name)], capsys)
        assert code == 2, (name, err)
        assert err.startswith("error: ") and err.count("\n") == 1, err
        assert name in err and message in err, err


def test_offset_beyond_the_search_is_an_error_not_a_wrong_answer():
    # B's stamps are 4.5 s ahead of A's for the same instants (both record the same 6 s): the default search
    # (±half the record, 3 s) cannot reach that. The best match inside the search is a poor one, which is
    # refused instead of being answered.
    a, b = bench.two_logs(bench.three_axis_scene(seed=3, duration_s=6.0), offset_s=4.5)
    with pytest.raises(DataError, match="correlate at most 0.[0-7]"):
        align(a, b)
    result = align(a, b, AlignOptions(max_offset_s=5.0))
    assert abs(result.time_offset_s - 4.5) < 1e-6 and rotation_error_deg(result.C, bench.MOUNT_B_DEG) < 1e-6


def test_jittered_time_stamps():
    # Real logs are not evenly spaced. Both sensors sampled at about 200 Hz with every instant moved by up to
    # ±1.5 ms (picked from an exact 2 kHz run, so every value is exact at its own stamp), independently.
    from imu_emulator import scene_from_dict
    from imu_emulator.runtime.simulation import Simulation
    out = Simulation(scene_from_dict(bench.three_axis_scene(seed=8, rate_hz=2000.0, duration_s=10.0)),
                     attitude=False).run()
    rng = np.random.default_rng(1)

    def picks():
        return np.unique(np.clip(np.arange(5, 19995, 10) + rng.integers(-3, 4, 1999), 0, 19999))
    ia, ib = picks(), picks()
    a = ImuLog("A", out.t_s[ia], out.accel[0, ia], out.gyro[0, ia])
    b = ImuLog("B", out.t_s[ib] - 0.0421, out.accel[1, ib], out.gyro[1, ib])
    result = align(a, b, AlignOptions(lever_arm=True))
    assert rotation_error_deg(result.C, bench.MOUNT_B_DEG) < 1e-6
    assert abs(result.time_offset_s + 0.0421) < 1e-6
    np.testing.assert_allclose(result.lever_arm_m, bench.LEVER_B_M, atol=1e-5)


# --- cases b–d of the accuracy table: the sensor model's errors (tools/bench_align.py) ----------------------
# The goals are the issue's: b rotation ≤ 0.02°, |Δt error| ≤ 0.1 ms; c and d rotation ≤ 1.5 × the injected
# misalignment + 0.02° (the injected misalignment: the rotation between the two gyros' sensing axes that their
# misalignment matrices make, bench.injected_misalignment_deg, a first-order closed form); lever arm ≤ 5 mm.
# Drift (d): the clock effect's −p/(1+p) within 4 of the reported 1σ (two-sided 6e-5 per value).

def check_sensor_case(case, seeds):
    rows, skipped = bench.run_case(case, seeds)
    assert skipped is None, skipped
    for lever_arm, per_seed in rows.items():
        for row in per_seed:
            if case == "b":
                assert row["rotation_deg"] <= 0.02
                assert row["time_offset_ms"] <= 0.1
            else:
                assert row["rotation_deg"] <= 1.5 * row["injected_deg"] + 0.02
                if not lever_arm:
                    # the error is the gyros' misalignment, which no estimator can separate from the mounting,
                    # not more (with the accelerometers, theirs enters the fit too)
                    assert abs(row["rotation_deg"] - row["injected_deg"]) <= 0.02
            if lever_arm:
                assert row["lever_arm_mm"] <= 5.0
            if case == "d":
                assert row["drift_ppm"] <= 4 * row["sigma_drift_ppm"]
            assert row["unobservable"] == "none"


@pytest.mark.parametrize("case", ["b", "c", "d"])
def test_sensor_model_cases_meet_the_goals(case):
    check_sensor_case(case, seeds=2)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["b", "c", "d"])
def test_sensor_model_cases_meet_the_goals_over_20_seeds(case):
    check_sensor_case(case, seeds=20)
