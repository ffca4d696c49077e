"""Sampled tracks from files: time, position and optionally roll/pitch/yaw, in SI units (s, m, rad).

CSV: comma-separated, UTF-8 (a byte-order mark is accepted), a header row naming the columns, in any
order: t, x, y, z and optionally roll, pitch, yaw (all three or none); or t, lat_deg, lon_deg, height_m
(WGS-84 geodetic, for scenes with the Earth model: imu_emulator.scene.sources.sampled_geodetic).  Names are
matched after stripping spaces and ignoring case.  Any other column is an error: a column we silently dropped (a
"yaw_deg", a second time base) is a column the user believed we used.  Blank lines and lines starting with '#' are
skipped; error messages give line numbers as an editor shows them (the header is usually line 1, so the
first data row is row 2).

Attitude may instead be given as a quaternion, columns qw, qx, qy, qz (all four; scalar first, body ->
navigation, any norm and either sign: it is normalised and made sign-continuous before differentiation).

NPZ: arrays t, x, y, z [, roll, pitch, yaw | qw, qx, qy, qz] (each (n,)), or t, position (n, 3) [, euler (n, 3)] with euler
columns roll, pitch, yaw.  Error messages give 0-based sample indices there, as numpy shows them.

Arrays built in code go through `track_from_arrays`, with the same checks.  `Track.position_series` and
`Track.attitude_series` (unwrapped angles) build the SampledSeries with error messages that point at the
file's rows and columns.
"""
from __future__ import annotations

import dataclasses
import io
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from imu_emulator.numerics.derivatives import SampledSeries, unwrap_angles, validate_samples
from imu_emulator.errors import DataError
from imu_emulator.scene.files import MAX_TRACK_BYTES, read_regular

POSITION_COLUMNS = ("x", "y", "z")
GEODETIC_COLUMNS = ("lat_deg", "lon_deg", "height_m")   # instead of x, y, z: WGS-84 geodetic (deg, deg, m)
EULER_COLUMNS = ("roll", "pitch", "yaw")
QUAT_COLUMNS = ("qw", "qx", "qy", "qz")     # attitude body -> navigation, scalar first, any sign


@dataclass(frozen=True)
class Track:
    t: np.ndarray                   # (n,) seconds, strictly increasing
    position: np.ndarray            # (n, 3) metres, navigation frame
    euler: np.ndarray | None        # (n, 3) roll, pitch, yaw in radians, as given (not unwrapped), or None
    source: Path
    lines: np.ndarray | None = None  # (n,) line number in the file of each sample (CSV), else None
    quat: np.ndarray | None = None   # (n, 4) qw, qx, qy, qz as given (normalised later), or None
    geodetic: bool = False          # position holds lat_deg, lon_deg, height_m (GEODETIC_COLUMNS), not x, y, z

    def row_label(self, i: int) -> str:
        """How error messages point at sample i: a line of the CSV, an index of the NPZ arrays."""
        return f"row {int(self.lines[i])}" if self.lines is not None else f"index {i}"

    def position_series(self, method: str, max_order: int = 3) -> SampledSeries:
        return SampledSeries(self.t, self.position, method, max_order, name=self.source.name,
                             columns=POSITION_COLUMNS, row_label=self.row_label)

    def attitude_series(self, method: str, max_order: int = 2) -> SampledSeries:
        """Unwrapped Euler angles; wrap yaw back with derivatives.wrap_angles for output."""
        if self.euler is None:
            raise DataError(f"{self.source.name}: no roll, pitch, yaw in this track")
        return SampledSeries(self.t, unwrap_angles(self.euler), method, max_order, name=self.source.name,
                             columns=EULER_COLUMNS, row_label=self.row_label)


def load_track(path) -> Track:
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".npz"):
        raise DataError(f"{path.name}: unsupported track file type '{path.suffix}' (expected .csv or .npz)")
    try:
        track = _load_csv(path) if suffix == ".csv" else _load_npz(path)
    except OSError as exc:
        raise DataError(f"{path.name}: cannot read: {exc.strerror or exc}") from None
    return _validated(track)


def track_from_arrays(t, position, euler=None, source: str = "<arrays>", quat=None) -> Track:
    """A Track from arrays built in code: t (n,), position (n, 3), euler (n, 3) or None, quat (n, 4) or None;
    checked like a file."""
    track = _from_arrays(t, position, euler, Path(source))
    if quat is not None:
        track = _with_quaternions(track, _numeric(track.source.name, "quat", np.asarray(quat), (track.t.size, 4)))
    return _validated(track)


def _with_quaternions(track: Track, quat: np.ndarray) -> Track:
    """The track with attitude quaternions; a quaternion of (nearly) zero norm is no attitude at all."""
    if track.euler is not None:
        raise DataError(f"{track.source.name}: give the attitude either as roll, pitch, yaw or as qw, qx, qy, "
                        "qz, not both")
    norm = np.linalg.norm(quat, axis=1)
    small = ~(norm > 1e-6)      # NaN counts as small here; validate_samples names NaN cells first
    if small.any() and np.isfinite(quat).all():
        i = int(np.argmax(small))
        raise DataError(f"{track.source.name}: {track.row_label(i)}: quaternion norm {float(norm[i])!r} "
                        "is not a rotation")
    return dataclasses.replace(track, quat=quat)


def _from_arrays(t, position, euler, source: Path) -> Track:
    where = source.name
    t = _numeric(where, "t", np.asarray(t), None)
    n = t.shape[0]
    if n == 0:
        raise DataError(f"{where}: array t is empty")
    position = _numeric(where, "position", np.asarray(position), (n, 3))
    euler = None if euler is None else _numeric(where, "euler", np.asarray(euler), (n, 3))
    return Track(t=t, position=position, euler=euler, source=source)


def _validated(track: Track) -> Track:
    """The track, checked for finite values and increasing time, with its arrays made read-only."""
    values = track.position if track.euler is None else np.hstack([track.position, track.euler])
    columns = ((GEODETIC_COLUMNS if track.geodetic else POSITION_COLUMNS)
               + (EULER_COLUMNS if track.euler is not None else ()))
    if track.quat is not None:
        values, columns = np.hstack([values, track.quat]), columns + QUAT_COLUMNS
    validate_samples(track.t, values, where=track.source.name, columns=columns, row_label=track.row_label)
    for a in (track.t, track.position, track.euler, track.quat):
        if a is not None:
            a.flags.writeable = False
    return track


def _check_names(where: str, names: list[str], kind: str) -> bool:
    """Whether attitude is present; DataError for missing, partial, duplicate or unknown names."""
    seen = set()
    for name in names:
        if name in seen:
            raise DataError(f"{where}: {kind} '{name}' appears twice")
        seen.add(name)
    position = GEODETIC_COLUMNS if seen & set(GEODETIC_COLUMNS) else POSITION_COLUMNS
    missing = [c for c in ("t",) + position if c not in seen]
    if missing:
        raise DataError(f"{where}: missing {kind}{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
                        f"(need t, {', '.join(position)})")
    unknown = [c for c in names if c not in ("t",) + position + EULER_COLUMNS + QUAT_COLUMNS]
    if unknown:
        raise DataError(f"{where}: unexpected {kind} '{unknown[0]}' (expected t, {', '.join(position)} and "
                        "optionally roll, pitch, yaw or qw, qx, qy, qz)")
    return _all_or_none(where, seen, EULER_COLUMNS)


def _position_columns(names) -> tuple[str, ...]:
    """x, y, z, or lat_deg, lon_deg, height_m (_check_names has refused a mix)."""
    return GEODETIC_COLUMNS if GEODETIC_COLUMNS[0] in names else POSITION_COLUMNS


def _all_or_none(where: str, names, group: tuple[str, ...]) -> bool:
    """Whether the columns of `group` (roll, pitch, yaw; qw, qx, qy, qz) are present: all or none of them."""
    present = [c for c in group if c in names]
    if present and len(present) < len(group):
        absent = [c for c in group if c not in names]
        together = ", ".join(group[:-1]) + " and " + group[-1]
        raise DataError(f"{where}: {together} come together: found {', '.join(present)} "
                        f"but not {', '.join(absent)}")
    return bool(present)


def read_csv_rows(path: Path, expected_header: str) -> tuple[int, str, list[str], list[tuple[int, str]]]:
    """The header's line number and text, its column names (stripped, lower case) and the data rows as
    (line number, text), blank lines and '#' comments skipped; DataError for an empty file or one that is
    not UTF-8. Shared with imulog, so that every CSV we read follows the same rules."""
    try:
        text = read_regular(path, MAX_TRACK_BYTES).decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DataError(f"{path.name}: not UTF-8 text (byte {exc.start} is {exc.object[exc.start]:#04x})") from None
    rows = [(number, line) for number, line in enumerate(text.splitlines(), start=1)
            if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise DataError(f"{path.name}: empty file (expected a header row {expected_header})")
    header_line, header = rows[0]
    return header_line, header, [c.strip().lower() for c in header.split(",")], rows[1:]


def read_npz_arrays(path: Path) -> dict[str, np.ndarray]:
    try:
        with np.load(io.BytesIO(read_regular(path, MAX_TRACK_BYTES)), allow_pickle=False) as archive:
            return {name: archive[name] for name in archive.files}
    except (ValueError, EOFError, zipfile.BadZipFile, AttributeError) as exc:
        # AttributeError: np.load of a bare .npy returns an array, which is no context manager
        raise DataError(f"{path.name}: not a readable NPZ archive ({exc})") from None


def _load_csv(path: Path) -> Track:
    where = path.name
    header_line, header, names, data = read_csv_rows(path, "t,x,y,z[,roll,pitch,yaw]")
    if len(names) == 1 and names[0] != "t":
        raise DataError(f"{where}: row {header_line}: header '{header.strip()}' has a single column; "
                        "columns are separated by commas")
    if any(not c for c in names):
        raise DataError(f"{where}: row {header_line}: empty column name in the header")
    has_euler = _check_names(where, names, "column")
    if not data:
        raise DataError(f"{where}: no data rows after the header")
    lines = np.array([number for number, _ in data])
    table = _parse_table(where, names, data)
    col = {name: table[:, j] for j, name in enumerate(names)}
    position = _position_columns(names)
    track = Track(
        t=col["t"].copy(),
        position=np.column_stack([col[c] for c in position]),
        geodetic=position == GEODETIC_COLUMNS,
        euler=np.column_stack([col[c] for c in EULER_COLUMNS]) if has_euler else None,
        source=path,
        lines=lines,
    )
    if _all_or_none(where, names, QUAT_COLUMNS):
        track = _with_quaternions(track, np.column_stack([col[c] for c in QUAT_COLUMNS]))
    return track


def _parse(lines: list[str], width: int) -> np.ndarray | None:
    """The table, or None where numpy refuses it; an empty cell counts as refused (numpy reads no rows)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)        # "input contained no data"
        try:
            table = np.loadtxt(lines, delimiter=",", dtype=float, comments=None, ndmin=2)
        except ValueError:
            return None
    return table if table.shape == (len(lines), width) else None


def _parse_table(where: str, names: list[str], data: list[tuple[int, str]]) -> np.ndarray:
    """numpy's C parser for speed; if it refuses the table, bisect with it to the first bad row, so the
    message names a row and cell that numpy itself rejects."""
    lines = [line for _, line in data]
    table = _parse(lines, len(names))
    if table is not None:
        return table
    lo, hi = 0, len(lines)          # lines[:lo] parse; the first bad line is in lines[lo:hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if _parse(lines[lo:mid], len(names)) is None:
            hi = mid
        else:
            lo = mid
    number, line = data[lo]
    cells = line.split(",")
    if len(cells) != len(names):
        raise DataError(f"{where}: row {number}: {len(cells)} fields, the header has {len(names)}")
    for name, cell in zip(names, cells):
        if _parse([cell], 1) is None:
            raise DataError(f"{where}: row {number}, column '{name}': '{cell.strip()}' is not a number")
    raise DataError(f"{where}: row {number}: cannot parse '{line}'")


def _load_npz(path: Path) -> Track:
    where = path.name
    arrays = read_npz_arrays(path)
    if "position" in arrays:
        unknown = sorted(set(arrays) - {"t", "position", "euler"})
        if unknown:
            raise DataError(f"{where}: unexpected array '{unknown[0]}' next to 'position' (expected t, "
                            "position and optionally euler)")
        if "t" not in arrays:
            raise DataError(f"{where}: missing array t")
        return _from_arrays(arrays["t"], arrays["position"], arrays.get("euler"), path)
    has_euler = _check_names(where, list(arrays), "array")
    t = _numeric(where, "t", arrays["t"], None)
    n = t.shape[0]

    def stacked(names):
        return np.column_stack([_numeric(where, c, arrays[c], (n,)) for c in names])

    position = _position_columns(list(arrays))
    track = _from_arrays(t, stacked(position), stacked(EULER_COLUMNS) if has_euler else None, path)
    track = dataclasses.replace(track, geodetic=position == GEODETIC_COLUMNS)
    if _all_or_none(where, list(arrays), QUAT_COLUMNS):
        track = _with_quaternions(track, stacked(QUAT_COLUMNS))
    return track


def _numeric(where: str, name: str, a: np.ndarray, shape: tuple[int, ...] | None) -> np.ndarray:
    """A float copy of array `name`, which must have `shape` (None: any 1-D shape)."""
    if a.dtype.kind not in "iuf":
        raise DataError(f"{where}: array {name} has dtype {a.dtype}, expected numbers")
    if (a.ndim != 1) if shape is None else (a.shape != shape):
        expected = "one dimension" if shape is None else f"{shape} to match t"
        raise DataError(f"{where}: array {name} has shape {a.shape}, expected {expected}")
    return np.array(a, dtype=float)
