"""IMU records read back from files: the emulator's own outputs and plain logs of real sensors.

CSV: a header row, then one row per sample. Columns t, ax, ay, az, gx, gy, gz (s, m/s², rad/s), in any
order, names matched after stripping spaces and ignoring case. The emulator's CSV adds a column `imu` (one
row per IMU per sample) and, with --truth or --increments, their columns (an Earth scene's too); all are understood. Any other column is an
error: a column we silently ignored (a "gx_dps", a second clock) is one the user believed we used.

Parquet: what `imu-emulator generate -o run.parquet` (and `batch`) writes: t_ns, imu and the same columns as
the CSV (imu_emulator.output.columns), read through the Parquet format's reader.

NPZ: what `imu-emulator generate -o run.npz` writes (t, imu_names, accel and gyro shaped (imu, n, 3), and t_imu
(imu, n) when an IMU has its own time_offset_s), or a plain record with t (n,), accel (n, 3), gyro (n, 3).

Every record gets the same checks as a track file: finite values, strictly increasing time stamps, errors
that name the file, the row (CSV line as an editor shows it, or 0-based NPZ index or Parquet row) and the column.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from imu_emulator.numerics.derivatives import validate_samples
from imu_emulator.errors import DataError
from imu_emulator.output.columns import IMU, LEADING_COLUMNS, all_names
from imu_emulator.scene.trackfile import _parse_table, read_csv_rows, read_npz_arrays

SAMPLE_COLUMNS = tuple(name for name in LEADING_COLUMNS if name != IMU.name)      # t, ax .. gz
VALUE_COLUMNS = SAMPLE_COLUMNS[1:]


@dataclass(frozen=True)
class ImuLog:
    label: str              # how messages name this record: "run.csv" or "run.csv[imu1]"
    t: np.ndarray           # (n,) seconds on this sensor's own clock, strictly increasing
    accel: np.ndarray       # (n, 3) specific force in the sensor frame, m/s²
    gyro: np.ndarray        # (n, 3) angular rate in the sensor frame, rad/s

    @property
    def rate_hz(self) -> float:
        return float((len(self.t) - 1) / (self.t[-1] - self.t[0])) if len(self.t) > 1 else 0.0


def read_logs(path) -> dict[str | None, ImuLog]:
    """Every IMU record in the file, keyed by IMU name (None for a plain log, which names none)."""
    path = Path(path)
    suffix = path.suffix.lower()
    readers = {".csv": _read_csv, ".npz": _read_npz, ".parquet": _read_parquet}
    if suffix not in readers:
        raise DataError(f"{path.name}: unsupported file type '{path.suffix}' (expected {', '.join(readers)})")
    try:
        return readers[suffix](path)
    except OSError as exc:
        raise DataError(f"{path.name}: cannot read: {exc.strerror or exc}") from None


def pick(logs: dict[str | None, ImuLog], name: str | None, where: str, option: str) -> ImuLog:
    """The record called `name`; `option` is the command-line flag that names it, for the message."""
    names = [n for n in logs if n is not None]
    if name is None:
        if len(logs) == 1:
            return next(iter(logs.values()))
        raise DataError(f"{where}: holds IMUs {', '.join(names)}: choose one with {option}")
    if not names:
        raise DataError(f"{where}: a plain log without IMU names; drop {option} {name}")
    if name not in logs:
        raise DataError(f"{where}: no IMU '{name}' (it holds {', '.join(names)})")
    return logs[name]


def _checked(label: str, t, accel, gyro, row_label) -> ImuLog:
    t, accel, gyro = (np.array(a, dtype=float) for a in (t, accel, gyro))
    validate_samples(t, np.hstack([accel, gyro]), where=label, columns=VALUE_COLUMNS, row_label=row_label)
    return ImuLog(label, t, accel, gyro)


def _read_csv(path: Path) -> dict[str | None, ImuLog]:
    where = path.name
    header_line, _, names, data = read_csv_rows(path, ",".join(SAMPLE_COLUMNS))
    missing = [c for c in SAMPLE_COLUMNS if c not in names]
    if missing:
        raise DataError(f"{where}: row {header_line}: missing column{'s' if len(missing) > 1 else ''} "
                        f"{', '.join(missing)} (the header has {', '.join(names)}; need "
                        f"{', '.join(SAMPLE_COLUMNS)})")
    known = all_names()      # any column of the emulator's output (imu_emulator.output.columns)
    for name in names:
        if name not in known:
            raise DataError(f"{where}: row {header_line}: unexpected column '{name}' (expected "
                            f"{', '.join(SAMPLE_COLUMNS)}, and imu for several IMUs)")
        if names.count(name) > 1:
            raise DataError(f"{where}: row {header_line}: column '{name}' appears twice")
    if not data:
        raise DataError(f"{where}: no data rows after the header")
    if "imu" not in names:
        table = _parse_table(where, names, data)
        return {None: _from_table(where, names, table, np.array([n for n, _ in data]))}
    # The emulator's layout: split by the imu column, then parse each IMU's rows as numbers.
    j = names.index("imu")
    numeric_names = names[:j] + names[j + 1:]
    groups: dict[str, list[tuple[int, str]]] = {}
    for number, line in data:
        cells = line.split(",")
        if len(cells) != len(names):
            raise DataError(f"{where}: row {number}: {len(cells)} fields, the header has {len(names)}")
        groups.setdefault(cells[j].strip(), []).append((number, ",".join(cells[:j] + cells[j + 1:])))
    logs = {}
    for imu, group in groups.items():
        table = _parse_table(where, numeric_names, group)
        logs[imu] = _from_table(f"{where}[{imu}]", numeric_names, table, np.array([n for n, _ in group]))
    return logs


def _from_table(label: str, names: list[str], table: np.ndarray, lines: np.ndarray) -> ImuLog:
    col = {name: table[:, i] for i, name in enumerate(names)}
    return _checked(label, col["t"], np.column_stack([col[c] for c in ("ax", "ay", "az")]),
                    np.column_stack([col[c] for c in ("gx", "gy", "gz")]),
                    lambda i: f"row {int(lines[i])}")


def _read_npz(path: Path) -> dict[str | None, ImuLog]:
    where = path.name
    arrays = read_npz_arrays(path)
    missing = [name for name in ("t", "accel", "gyro") if name not in arrays]
    if missing:
        raise DataError(f"{where}: missing array{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
                        f"(it has {', '.join(sorted(arrays)) or 'none'}; need t, accel, gyro)")
    t, accel, gyro = arrays["t"], arrays["accel"], arrays["gyro"]
    for name, a in (("t", t), ("accel", accel), ("gyro", gyro)):
        if a.dtype.kind not in "iuf":
            raise DataError(f"{where}: array {name} has dtype {a.dtype}, expected numbers")
    n = t.shape[0] if t.ndim == 1 else -1
    names = [str(x) for x in arrays["imu_names"]] if "imu_names" in arrays else None
    shape = (n, 3) if names is None else (len(names), n, 3)
    for name, a in (("accel", accel), ("gyro", gyro)):
        if t.ndim != 1 or a.shape != shape:
            raise DataError(f"{where}: array {name} has shape {a.shape}, expected {shape} to match t "
                            f"{t.shape}" + ("" if names is None else f" and {len(names)} imu_names"))

    def row_label(i):
        return f"index {i}"
    if names is None:
        return {None: _checked(where, t, accel, gyro, row_label)}
    # t_imu (imu, n): each IMU's own stamps, written when an [[imu]] has a time_offset_s
    stamps = arrays.get("t_imu")
    if stamps is not None and (stamps.dtype.kind not in "iuf" or stamps.shape != (len(names), n)):
        raise DataError(f"{where}: array t_imu has shape {stamps.shape} and dtype {stamps.dtype}, expected numbers "
                        f"shaped {(len(names), n)}")
    return {name: _checked(f"{where}[{name}]", t if stamps is None else stamps[m], accel[m], gyro[m], row_label)
            for m, name in enumerate(names)}


def _read_parquet(path: Path) -> dict[str | None, ImuLog]:
    from imu_emulator.output.formats import FORMATS
    where = path.name
    try:
        columns = FORMATS[".parquet"].read_columns(path, (*SAMPLE_COLUMNS, IMU.name))
    except ValueError as exc:        # pyarrow's ArrowInvalid: not a Parquet file
        raise DataError(f"{where}: cannot read as Parquet: {exc}") from None
    if columns is None:
        raise DataError(f"{where}: missing columns: need t_ns, imu, {', '.join(VALUE_COLUMNS)} (as `generate` "
                        "writes them)")
    imu = columns[IMU.name]
    values = np.column_stack([columns[c] for c in VALUE_COLUMNS])
    logs = {}
    for name in dict.fromkeys(imu):          # in the file's order
        rows = np.flatnonzero(imu == name)
        logs[str(name)] = _checked(f"{where}[{name}]", columns["t"][rows], values[rows, :3], values[rows, 3:],
                                   lambda i, rows=rows: f"row {int(rows[i])}")
    return logs
