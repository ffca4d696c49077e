"""Every output format carries the same run: CSV (read back by numpy), Parquet (pyarrow) and the ROS 2 bag
(rosbags, an independent CDR reader) against the NPZ of the same Earth scene with --truth and --increments; every
registered format's own reader and size estimate against the files written."""
from __future__ import annotations

import numpy as np
import pytest

from imu_emulator.cli import main
from imu_emulator.output.formats import FORMATS

# Two IMUs (the second with a time offset and a name that needs CSV quoting), every group of columns: increments,
# temperature, truth, realized biases and the Earth truth.
SCENE = """
[scene]
rate_hz = 50
duration_s = 2.0
frame = "NED"
gravity_model = "wgs84"
seed = 7
origin = { lat_deg = 45.0, lon_deg = 7.0, height_m = 200.0 }
[trajectory]
x = "30*t + sin(t)"
y = "3*t**2"
z = "-5*t"
[attitude]
roll = "0.1*sin(t)"
pitch = "0.05"
yaw = "0.3*t"
[[imu]]
name = "front"
[imu.gyro]
bias = ["0.1 deg/s", 0, 0]
noise_density = "0.007 deg/s/sqrt(Hz)"
[imu.accel]
turn_on_bias_sd = "2 mg"
[[imu]]
name = 'rear "b"'
time_offset_s = 0.0015
[effects]
gravity = true
earth_rate = true
coriolis = true
bias = true
noise = true
temperature = true
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The same scene written in every output format (NPZ, CSV, Parquet, MCAP, ...); {suffix: path}."""
    tmp = tmp_path_factory.mktemp("earth_formats")
    scene = tmp / "s.toml"
    scene.write_text(SCENE)
    paths = {}
    for suffix, record in FORMATS.items():      # every registered format, with what it can carry
        paths[suffix] = tmp / f"o{suffix}"
        options = ["--increments"] if record.increments else []
        assert main(["generate", str(scene), "-o", str(paths[suffix]), "--quiet", "--truth", *options]) == 0
    paths["scene"] = scene
    return paths


def _npz_columns(npz) -> dict[str, np.ndarray]:
    """The NPZ's arrays as rows of (sample, IMU), IMU fastest, under the CSV's column names."""
    from imu_emulator.motion.earth_truth import COLUMNS
    from imu_emulator.output.columns import BIAS_COLUMNS, INCREMENT_COLUMNS, TRUTH_COLUMNS
    n_imu = len(npz["imu_names"])

    def per_imu(a):                              # (n_imu, n, k) -> (n * n_imu, k)
        return a.transpose(1, 0, 2).reshape(-1, a.shape[2])

    def shared(a):                               # (n, k) -> (n * n_imu, k)
        return np.repeat(a, n_imu, axis=0)

    cols = {"t": npz["t_imu"].T.ravel()}
    blocks = [(("ax", "ay", "az"), per_imu(npz["accel"])), (("gx", "gy", "gz"), per_imu(npz["gyro"])),
              (INCREMENT_COLUMNS[:3], per_imu(npz["dtheta"])), (INCREMENT_COLUMNS[3:], per_imu(npz["dvel"])),
              (("temp_c",), per_imu(npz["temperature_c"][:, :, None])),
              (TRUTH_COLUMNS, np.hstack([shared(npz[k]) for k in ("position", "velocity", "euler", "omega_body")])),
              (BIAS_COLUMNS, np.hstack([per_imu(npz["accel_bias"]), per_imu(npz["gyro_bias"])]))]
    blocks += [(names, shared(npz[key])) for key, names in COLUMNS.items()]
    for names, values in blocks:
        for i, name in enumerate(names):
            cols[name] = values[:, i]
    return cols


def _same_bits(a, b) -> bool:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def test_csv_equals_npz_bit_for_bit_in_an_earth_scene(run):
    """Every column of the CSV, parsed by numpy's loadtxt, is the NPZ's double bit for bit (the README promises
    shortest round-trip text), and the names read back through the csv module's quoting."""
    import csv
    with np.load(run[".npz"]) as npz:
        want = _npz_columns(npz)
        names = list(npz["imu_names"])
    text = run[".csv"].read_text()
    lines = [line for line in text.splitlines() if not line.startswith("#")]
    header = lines[0].split(",")
    assert set(header) - {"imu"} == set(want), "the CSV and the NPZ carry the same columns"
    rows = list(csv.reader(lines[1:]))
    assert [r[1] for r in rows[:4]] == names + names
    numbers = np.loadtxt([",".join(r[:1] + r[2:]) for r in rows], delimiter=",", dtype=np.float64)
    for i, name in enumerate(h for h in header if h != "imu"):
        assert _same_bits(numbers[:, i], want[name]), name


def test_parquet_equals_npz_column_by_column_in_an_earth_scene(run):
    """Parquet carries the Earth truth (and every other column) of the CSV, with t as integer ns."""
    import pyarrow.parquet as pq
    table = pq.read_table(run[".parquet"])
    with np.load(run[".npz"]) as npz:
        want = _npz_columns(npz)
        names = list(npz["imu_names"])
        offsets_ns = np.round(npz["t_imu"][:, 0] * 1e9 - npz["t"][0] * 1e9)
    assert set(table.column_names) - {"imu", "t_ns"} == set(want) - {"t"}
    assert table.column("imu").to_pylist()[:4] == names + names
    for name in want:
        if name != "t":
            assert _same_bits(table.column(name).to_numpy(), want[name]), name
    t_ns = table.column("t_ns").to_numpy().reshape(-1, len(names))
    np.testing.assert_allclose(t_ns * 1e-9, want["t"].reshape(-1, len(names)), rtol=0, atol=1e-12)
    assert np.array_equal(t_ns[:, 1] - t_ns[:, 0], np.full(len(t_ns), offsets_ns[1] - offsets_ns[0]))
    from imu_emulator.output.formats.parquet import read_metadata
    assert any("f = a - g" in line for line in read_metadata(run[".parquet"])["conventions"])


def test_ros2_bag_carries_the_earth_truth(run):
    """/truth/navsatfix and /truth/odometry_ecef, decoded by rosbags, against the NPZ of the same run and pymap3d:
    the fix is the NPZ's geodetic truth, pymap3d puts it at the odometry's ECEF position; the odometry's
    orientation is body FLU -> ECEF (pymap3d's NED axes times the NPZ's attitude w.r.t. local NED, FRD), its twist the
    ECEF velocity in body axes and a body rate that turns its own orientations (checked by differencing them)."""
    pymap3d = pytest.importorskip("pymap3d")
    from scipy.spatial.transform import Rotation
    from tests.output.test_output_mcap import read_bag
    topics = read_bag(run[".mcap"])
    assert {"/truth/navsatfix", "/truth/odometry_ecef", "/truth/odometry"} <= set(topics)
    with np.load(run[".npz"]) as npz:
        geodetic, r_ecef, v_ecef = npz["geodetic"], npz["position_ecef"], npz["velocity_ecef"]
        euler_ned, t = npz["euler_ned"], npz["t"]
    fixes = [m for _, m in topics["/truth/navsatfix"]]
    llh = np.array([[f.latitude, f.longitude, f.altitude] for f in fixes])
    assert _same_bits(llh, geodetic)
    assert {(f.status.status, f.position_covariance_type, f.header.frame_id) for f in fixes} == {(0, 3, "earth")}
    odom = [m for _, m in topics["/truth/odometry_ecef"]]
    assert {(d.header.frame_id, d.child_frame_id) for d in odom} == {("earth", "base_link")}   # REP 103: FLU
    pos = np.array([[d.pose.pose.position.x, d.pose.pose.position.y, d.pose.pose.position.z] for d in odom])
    assert _same_bits(pos, r_ecef)
    np.testing.assert_allclose(pos, np.array(pymap3d.geodetic2ecef(*llh.T)).T, rtol=0, atol=1e-6)
    q = np.array([[d.pose.pose.orientation.x, d.pose.pose.orientation.y, d.pose.pose.orientation.z,
                   d.pose.pose.orientation.w] for d in odom])
    c_be = Rotation.from_quat(q)                                      # scipy: scalar last
    # C_n^e from pymap3d: row i holds the NED components of ECEF axis i
    c_ne = np.array([np.column_stack(pymap3d.ecef2nedv(*np.eye(3), la, lo)) for la, lo, _ in llh])
    c_bn = Rotation.from_euler("ZYX", euler_ned[:, ::-1]).as_matrix()
    flu_from_frd = np.diag([1.0, -1.0, -1.0])
    np.testing.assert_allclose(c_be.as_matrix(), c_ne @ c_bn @ flu_from_frd, rtol=0, atol=1e-12)
    v_b = np.array([[d.twist.twist.linear.x, d.twist.twist.linear.y, d.twist.twist.linear.z] for d in odom])
    np.testing.assert_allclose(c_be.apply(v_b), v_ecef, rtol=0, atol=1e-9)
    _twist_moves_the_pose(odom, t)


def _twist_moves_the_pose(odom, t):
    """The twist of successive odometry messages carries the pose from one to the next: the rotation between
    orientations over dt is the mean body rate, the ECEF step the mean ECEF velocity, each to O(dt^2) of the
    derivatives' changes: with the scenes' rates (< 0.4 rad/s, changing by < 0.1 rad/s^2), accelerations
    (< 10 m/s^2, jerk < 1 m/s^3) and dt = 0.02 s that is < 1e-5 rad/s and < 1e-3 m/s."""
    from scipy.spatial.transform import Rotation
    c_be = Rotation.from_quat([[d.pose.pose.orientation.x, d.pose.pose.orientation.y, d.pose.pose.orientation.z,
                                d.pose.pose.orientation.w] for d in odom])
    w = np.array([[d.twist.twist.angular.x, d.twist.twist.angular.y, d.twist.twist.angular.z] for d in odom])
    turned = (c_be[:-1].inv() * c_be[1:]).as_rotvec() / np.diff(t)[:, None]
    np.testing.assert_allclose(turned, (w[:-1] + w[1:]) / 2, rtol=0, atol=1e-5)
    pos = np.array([[d.pose.pose.position.x, d.pose.pose.position.y, d.pose.pose.position.z] for d in odom])
    v_e = c_be.apply([[d.twist.twist.linear.x, d.twist.twist.linear.y, d.twist.twist.linear.z] for d in odom])
    np.testing.assert_allclose(np.diff(pos, axis=0) / np.diff(t)[:, None], (v_e[:-1] + v_e[1:]) / 2,
                               rtol=0, atol=1e-3)


ECI_ORBIT = 'x = "7e6*cos(1e-3*t)"\ny = "7e6*sin(1e-3*t)"\nz = "1e3*t"'   # 7 km/s: a transport rate of 1e-3 rad/s
BOTH = "earth_rate = true\ncoriolis = true\n"


@pytest.mark.parametrize("frame, trajectory, reference, effects", [
    ("ENU", 'x = "30*t + sin(t)"\ny = "3*t**2"\nz = "5*t"', "local_level", BOTH),     # a forward-left-up body
    ("ECI", ECI_ORBIT, "local_level", BOTH),
    # an attitude given w.r.t. ECEF or ECI: the kernel's body rate leaves out only what the named effects add
    ("ECEF", ECI_ORBIT, "ECEF", ""),
    ("ECEF", ECI_ORBIT, "ECEF", "earth_rate = true\n"),
    ("ECEF", ECI_ORBIT, "ECI", "earth_rate = true\n"),
    ("ECEF", ECI_ORBIT, "ECI", "coriolis = true\n"),
    ("ECEF", ECI_ORBIT, "ECI", BOTH),
])
def test_odometry_ecef_twist_in_other_frames(tmp_path, monkeypatch, frame, trajectory, reference, effects):
    from tests.output.test_output_mcap import read_bag
    scene = tmp_path / "s.toml"
    scene.write_text(f'[scene]\nrate_hz = 50\nduration_s = 1.0\nframe = "{frame}"\ngravity_model = "wgs84"\n'
                     'origin = { lat_deg = -30.0, lon_deg = 170.0, height_m = 10.0 }\n'
                     f'[trajectory]\n{trajectory}\n[attitude]\nreference = "{reference}"\nroll = "0.1*sin(t)"\n'
                     f'pitch = "0.05"\nyaw = "0.3*t"\n[[imu]]\nname = "a"\n[effects]\ngravity = true\n{effects}')
    assert main(["generate", str(scene), "-o", str(tmp_path / "o.mcap"), "--quiet", "--truth"]) == 0
    odom = [m for _, m in read_bag(tmp_path / "o.mcap")["/truth/odometry_ecef"]]
    _twist_moves_the_pose(odom, np.arange(50) / 50.0)


@pytest.mark.parametrize("suffix", sorted(FORMATS))
def test_every_format_reads_back_the_schemas_columns(run, suffix):
    """Every registered format's file of the Earth run, read back by its own reader (Format.read_columns, what
    `plot` and `align` use), holds the schema's columns it declares (Format.carries: all of them, or what a
    ROS bag holds as such) with the NPZ's values: bit for bit, time stamps to the ns."""
    from imu_emulator.output.columns import Layout
    record = FORMATS[suffix]
    assert record.read_columns is not None, f"{record.name} cannot be read back"
    layout = Layout(truth=True, bias_truth=True, temperature=True, increments=record.increments, earth=True)
    names = ("t",) + record.carries(layout)
    found = record.read_columns(run[suffix], names)
    assert found is not None and set(found) == set(names)
    with np.load(run[".npz"]) as npz:
        want = _npz_columns(npz)
    np.testing.assert_allclose(found["t"], want["t"], rtol=0, atol=1e-9)
    for name in names[1:]:
        assert _same_bits(found[name], want[name]), (record.name, name)


def test_run_size_matches_the_files_written(run):
    """Every format's estimated_bytes with --truth and --increments (where it carries them) against its file of
    the Earth run, within the margin the format states (imu_emulator.output.base.Format.margin): NPZ to within
    1 % (its arrays exactly, plus per-array headers); CSV within CSV_ESTIMATE_MARGIN of the estimate and under
    the bound; Parquet and MCAP under their uncompressed bounds (Parquet: plus 25 % for the dictionary pages a
    short file keeps beside its values)."""
    import os

    from imu_emulator.output.formats.csv import CSV_ESTIMATE_MARGIN, csv_bytes
    from imu_emulator.scene.load import load_scene
    scene = load_scene(run["scene"])
    size = {suffix: os.path.getsize(run[suffix]) for suffix in FORMATS}
    for suffix, record in FORMATS.items():
        low, high = record.margin
        ratio = size[suffix] / record.estimated_bytes(scene, True, record.increments)
        assert low <= ratio <= high, (record.name, ratio, record.margin)
    # the CSV's '#' convention lines are not rows
    rows = size[".csv"] - sum(len(line) + 1 for line in run[".csv"].read_text().splitlines()[:7])
    assert abs(rows / FORMATS[".csv"].estimated_bytes(scene, True, True) - 1) < CSV_ESTIMATE_MARGIN
    assert size[".csv"] <= csv_bytes(scene, True, True)
    # and each group of columns counts: without truth and increments every estimate is smaller
    for record in FORMATS.values():
        assert record.estimated_bytes(scene, False, False) < record.estimated_bytes(scene, True, record.increments)


def test_simulate_memory_check_counts_every_array(run, monkeypatch):
    """simulate()'s memory check (run_size.check_memory) counts exactly the arrays Simulation.run allocates,
    increments, temperature, realized biases and Earth truth included: with the available memory one byte
    short of their nbytes it refuses, with exactly that it runs."""
    from imu_emulator.runtime import memory as run_size
    from imu_emulator.scene.load import load_scene
    from imu_emulator.runtime.simulation import simulate
    scene = load_scene(run["scene"])
    monkeypatch.setattr(run_size, "available_memory", lambda: None)
    out = simulate(scene, truth=True, increments=4)
    arrays = [out.t_s, out.accel, out.gyro, out.quat, out.temperature_c, out.dtheta, out.dvel, *out.truth.values()]
    allocated = sum(a.nbytes for a in arrays)
    assert len(out.truth) == 5 + 2 + 9      # the truth, the realized biases, the Earth truth: all counted
    monkeypatch.setattr(run_size, "available_memory", lambda: allocated - 1)
    with pytest.raises(run_size.RunSizeError, match=r"simulate: \d+ samples x 2 IMU"):
        simulate(scene, truth=True, increments=4)
    monkeypatch.setattr(run_size, "available_memory", lambda: allocated)
    simulate(scene, truth=True, increments=4)


def test_a_batch_writes_the_earth_truth_too(run, tmp_path, monkeypatch):
    """batch's Parquet files carry the same Earth truth columns (the truth does not depend on the seed)."""
    import pyarrow.parquet as pq

    from imu_emulator.analysis import batch
    from imu_emulator.motion.earth_truth import COLUMNS
    result = batch.run(str(run["scene"]), 1, 3, tmp_path / "mc", truth=True)
    assert result.ok, result.failures
    table = pq.read_table(batch.run_file(tmp_path / "mc", 0))
    with np.load(run[".npz"]) as npz:
        want = _npz_columns(npz)
    for name in (name for names in COLUMNS.values() for name in names):
        assert _same_bits(table.column(name).to_numpy(), want[name]), name
