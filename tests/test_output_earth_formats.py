"""Every output format carries the same run: CSV (read back by numpy), Parquet (pyarrow) and the ROS 2 bag
(rosbags, an independent CDR reader) against the NPZ of the same Earth scene with --truth and --increments, and
run_size's estimates against the files written."""
from __future__ import annotations

import numpy as np
import pytest

from imu_emulator.cli import main

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
    """The same scene written as NPZ, CSV, Parquet and MCAP; {suffix: path}."""
    import os
    tmp = tmp_path_factory.mktemp("earth_formats")
    old = os.environ.get("IMU_EMULATOR_CACHE")
    os.environ["IMU_EMULATOR_CACHE"] = str(tmp / "cache")
    scene = tmp / "s.toml"
    scene.write_text(SCENE)
    paths = {}
    try:
        for suffix, options in ((".npz", ["--increments"]), (".csv", ["--increments"]),
                                (".parquet", ["--increments"]), (".mcap", [])):
            paths[suffix] = tmp / f"o{suffix}"
            assert main(["generate", str(scene), "-o", str(paths[suffix]), "--quiet", "--truth", *options]) == 0
    finally:
        if old is None:
            os.environ.pop("IMU_EMULATOR_CACHE")
        else:
            os.environ["IMU_EMULATOR_CACHE"] = old
    paths["scene"] = scene
    return paths


def _npz_columns(npz) -> dict[str, np.ndarray]:
    """The NPZ's arrays as rows of (sample, IMU), IMU fastest, under the CSV's column names."""
    from imu_emulator.earth_truth import COLUMNS
    from imu_emulator.output import BIAS_COLUMNS, INCREMENT_COLUMNS, TRUTH_COLUMNS
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
    from imu_emulator.output_parquet import read_metadata
    assert any("f = a - g" in line for line in read_metadata(run[".parquet"])["conventions"])
