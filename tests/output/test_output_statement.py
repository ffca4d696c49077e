"""Every output file states its frame and units (issue 24): CSV '#' lines before the header, NPZ "conventions"
and "units" arrays, Parquet's footer and each field's metadata. The units are checked against README's
"Conventions a user must know" (SI: m/s^2, rad/s, m, s), written out here, not read from the schema."""
import csv

import numpy as np
import pytest

from imu_emulator.output.formats import open_writer
from imu_emulator.runtime.samples import SampleBlock

README_UNITS = {"t": "s", "ax": "m/s^2", "ay": "m/s^2", "az": "m/s^2", "gx": "rad/s", "gy": "rad/s", "gz": "rad/s",
                "px": "m", "py": "m", "pz": "m", "vx": "m/s", "vy": "m/s", "vz": "m/s", "roll": "rad",
                "pitch": "rad", "yaw": "rad", "wbx": "rad/s", "wby": "rad/s", "wbz": "rad/s"}
BODY = {"ENU": ("ENU (x east, y north, z up)", "forward-left-up"), "NED": ("NED (x north, y east, z down)",
                                                                         "forward-right-down")}


def _block(n=4, n_imu=2):
    rng = np.random.default_rng(3)
    truth = {key: rng.normal(size=(n, 3)) for key in ("position", "velocity", "euler", "omega_body", "alpha_body")}
    return SampleBlock(k0=0, t_s=np.arange(n) / 10.0, accel=rng.normal(size=(n_imu, n, 3)),
                       gyro=rng.normal(size=(n_imu, n, 3)), quat=None, truth=truth)


def _write(path, frame):
    with open_writer(path, ["a", "b"], truth=True, frame=frame) as writer:
        writer.write(_block())


def _units_from_line(line):
    assert line.startswith("units: ")
    found = {}
    for item in line[len("units: "):].split(", "):
        name, _, unit = item.partition(" [")
        found[name] = unit.rstrip("]")
    return found


def _check_lines(lines, frame):
    where, body = BODY[frame]
    assert f"frame: trajectory px py pz, vx vy vz in {where}" in lines
    assert any(body in line and line.startswith("attitude:") for line in lines)
    assert any(line.startswith("accelerometers: specific force f = a - g") for line in lines)
    units = _units_from_line(lines[-1])
    assert {name: unit for name, unit in units.items() if name != "imu"} == README_UNITS


@pytest.mark.parametrize("frame", ["ENU", "NED"])
def test_csv_starts_with_its_frames_and_units(tmp_path, frame):
    path = tmp_path / "o.csv"
    _write(path, frame)
    lines = path.read_text().splitlines()
    stated = [line[2:] for line in lines if line.startswith("# ")]
    assert lines[:len(stated)] == [f"# {line}" for line in stated]          # all before the header
    _check_lines(stated, frame)
    rows = list(csv.reader(lines[len(stated):]))
    assert rows[0][:8] == ["t", "imu", "ax", "ay", "az", "gx", "gy", "gz"] and len(rows) == 1 + 8
    from imu_emulator.output.formats.csv import read_conventions
    assert read_conventions(path) == stated


@pytest.mark.parametrize("frame", ["ENU", "NED"])
def test_npz_states_frames_and_each_arrays_unit(tmp_path, frame):
    path = tmp_path / "o.npz"
    _write(path, frame)
    with np.load(path) as data:
        _check_lines([str(x) for x in data["conventions"]], frame)
        units = {line.split(": ", 1)[0]: line.split(": ", 1)[1] for line in map(str, data["units"])}
        keys = set(data.files) - {"conventions", "units"}
    assert set(units) == keys            # every array has its line
    for key, unit in {"t": "s", "accel": "m/s^2", "gyro": "rad/s", "position": "m", "velocity": "m/s",
                      "euler": "rad", "omega_body": "rad/s", "alpha_body": "rad/s^2"}.items():
        assert units[key].startswith(unit + " ("), (key, units[key])


@pytest.mark.parametrize("frame", ["ENU", "NED"])
def test_parquet_fields_carry_their_unit_and_the_footer_the_frames(tmp_path, frame):
    import pyarrow.parquet as pq
    from imu_emulator.output.formats.parquet import read_conventions
    path = tmp_path / "o.parquet"
    _write(path, frame)
    schema = pq.read_schema(path)
    units = {f.name: f.metadata[b"unit"].decode() for f in schema if f.name != "imu"}
    assert units.pop("t_ns") == "ns"
    assert units == {k: v for k, v in README_UNITS.items() if k != "t"}
    assert all(f.metadata[b"description"] for f in schema if f.name != "imu")
    _check_lines(read_conventions(path), frame)
    # the table itself is unchanged by the metadata: values read back
    table = pq.read_table(path)
    assert table.num_rows == 8 and table.column("ax").to_numpy()[0] == _block().accel[0, 0, 0]
