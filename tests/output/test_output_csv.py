"""CSV output: every number reads back as the identical double; rows interleave IMUs sample by sample."""
import csv
import io

import numpy as np

from imu_emulator.cli import main
from imu_emulator.output.columns import LEADING_COLUMNS as CSV_COLUMNS, TRUTH_COLUMNS
from imu_emulator.output.formats.csv import csv_rows
from imu_emulator.runtime.samples import SampleBlock
from imu_emulator.runtime.simulation import TRUTH_KEYS
from tests.support.paths import EXAMPLES

# Doubles whose text is easy to get wrong: subnormals, the extremes, negative zero, values needing all 17
# digits, powers of ten at the switch to exponent notation, integers beyond 2**53.
AWKWARD = [5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, -0.0, 0.1, 1 / 3, 2 / 3 * 1e-5,
           0.30000000000000004, 1e16, 1e21, 1e-7, 123456789012345680000.0, 9007199254740993.0, -2.5e-300]


def _block(n, n_imu, rng):
    values = np.concatenate([AWKWARD, rng.standard_normal(n) * 10.0 ** rng.integers(-300, 300, n)])
    pick = lambda shape: rng.choice(values, size=shape)  # noqa: E731
    truth = {key: pick((n, 3)) for key in TRUTH_KEYS}
    return SampleBlock(k0=0, t_s=np.sort(np.abs(pick(n))), accel=pick((n_imu, n, 3)), gyro=pick((n_imu, n, 3)),
                       quat=None, truth=truth)


def test_csv_rows_read_back_as_identical_doubles():
    rng = np.random.default_rng(11)
    block = _block(5000, 2, rng)
    text = csv_rows(block, ["imu0", "imu1"], truth=True)
    rows = list(csv.reader(io.StringIO(text)))
    assert len(rows) == 2 * 5000
    columns = CSV_COLUMNS + TRUTH_COLUMNS
    assert all(len(r) == len(columns) for r in rows)
    assert [r[1] for r in rows[:4]] == ["imu0", "imu1", "imu0", "imu1"]
    back = np.array([[float(x) for i, x in enumerate(r) if i != 1] for r in rows])   # Python's float() as oracle
    expected = []
    for k in range(5000):
        for m in range(2):
            truth = [block.truth[key][k] for key in ("position", "velocity", "euler", "omega_body")]
            expected.append(np.concatenate([[block.t_s[k]], block.accel[m, k], block.gyro[m, k], *truth]))
    expected = np.array(expected)
    # bit for bit, so -0.0 and 0.0 differ
    assert np.array_equal(back.view(np.int64), expected.view(np.int64))
    # and with the fewest digits that do so: as many significant digits as Python's repr (shortest round trip),
    # whatever the notation ("0.000005" here, "5e-06" there)
    flat = [x for r in rows for i, x in enumerate(r) if i != 1]
    assert all(_digits(x) == _digits(repr(float(x))) for x in flat)


def _digits(text):
    return len(text.lower().split("e")[0].lstrip("-").replace(".", "").strip("0"))


def test_generate_csv_equals_npz_bit_for_bit(tmp_path, monkeypatch):
    from pathlib import Path
    scene = str(EXAMPLES / "two_imus.toml")
    assert main(["generate", scene, "-o", str(tmp_path / "o.csv"), "--quiet", "--truth"]) == 0
    assert main(["generate", scene, "-o", str(tmp_path / "o.npz"), "--quiet", "--truth"]) == 0
    rows = [r for r in csv.reader(open(tmp_path / "o.csv")) if not r[0].startswith("#")][1:]   # '#': the statement
    npz = np.load(tmp_path / "o.npz")
    accel = np.array([[float(x) for x in r[2:5]] for r in rows]).reshape(-1, 2, 3).transpose(1, 0, 2)
    assert np.array_equal(accel, npz["accel"])
    t = np.array([float(r[0]) for r in rows[::2]])
    assert np.array_equal(t, npz["t"])


def test_names_with_quotes_are_quoted():
    block = _block(3, 1, np.random.default_rng(1))
    rows = list(csv.reader(io.StringIO(csv_rows(block, ['my "imu"'], truth=False))))
    assert [r[1] for r in rows] == ['my "imu"'] * 3


def test_every_column_group_and_clock_offsets_read_back_exactly():
    """Per-IMU groups (increments, temperature, realized biases), shared ones (truth, Earth truth) and per-IMU
    time stamps ([[imu]] time_offset_s) land in the right row and column, each number Python's float() of it."""
    from imu_emulator.motion.earth_truth import KEYS
    from imu_emulator.output.columns import BIAS_COLUMNS, INCREMENT_COLUMNS
    from imu_emulator.output.formats.csv import csv_segments
    rng = np.random.default_rng(5)
    n, n_imu = 300, 3
    block = _block(n, n_imu, rng)
    values = np.concatenate([AWKWARD, rng.standard_normal(50)])
    for key in ("dtheta", "dvel"):
        setattr(block, key, rng.choice(values, (n_imu, n, 3)))
    block.temperature_c = rng.choice(values, (n_imu, n))
    block.truth.update({key: rng.choice(values, (n, 3)) for key in KEYS})
    block.truth.update(accel_bias=rng.choice(values, (n_imu, n, 3)), gyro_bias=rng.choice(values, (n_imu, n, 3)))
    block.time_offset_s = np.array([0.0, 1e-3, -2.5e-3])
    names = ["a", "b,c", 'd"e']
    text = csv_rows(block, names, truth=True, bias_truth=True, temperature=True, increments=True, earth=True)
    rows = list(csv.reader(io.StringIO(text)))
    assert [r[1] for r in rows] == names * n
    back = np.array([[float(x) for i, x in enumerate(r) if i != 1] for r in rows])
    stamps = block.imu_t_s()
    want = []
    for k in range(n):
        shared_truth = [block.truth[key][k] for key in ("position", "velocity", "euler", "omega_body")]
        for m in range(n_imu):
            want.append(np.concatenate([[stamps[m, k]], block.accel[m, k], block.gyro[m, k], block.dtheta[m, k],
                                        block.dvel[m, k], [block.temperature_c[m, k]], *shared_truth,
                                        block.truth["accel_bias"][m, k], block.truth["gyro_bias"][m, k],
                                        *[block.truth[key][k] for key in KEYS]]))
    assert back.shape[1] == 1 + 6 + len(INCREMENT_COLUMNS) + 1 + 12 + len(BIAS_COLUMNS) + 3 * len(KEYS)
    assert np.array_equal(back.view(np.int64), np.array(want).view(np.int64))
    # the groups: a per-IMU time column, the shared truth columns once per sample
    assert [per_imu for per_imu, _ in csv_segments(block, n_imu, True, True, True, True, True)] == [
        True, True, False, True, False]


def test_a_block_with_nan_or_infinity_is_still_written():
    block = _block(20, 2, np.random.default_rng(3))
    block.accel[1, 4] = [np.nan, np.inf, -np.inf]
    rows = list(csv.reader(io.StringIO(csv_rows(block, ["imu0", "imu1"], truth=False))))
    assert rows[9][2:5] == ["nan", "inf", "-inf"]
    back = np.array([[float(x) for i, x in enumerate(r) if i != 1] for r in rows])
    assert np.array_equal(back[::2, 1:4], block.accel[0]) and np.array_equal(back[8, 0], block.t_s[4])
