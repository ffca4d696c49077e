"""Write samples to CSV or NPZ (chosen by the output file's suffix). The file appears only complete: it is
written under a temporary name and renamed when the run succeeds (imu_emulator.output.atomic)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imu_emulator.errors import ImuEmulatorError
from imu_emulator.output.atomic import AtomicOutput, FinishOnExit, output_error
from imu_emulator.runtime.samples import SampleBlock, concatenate

CSV_COLUMNS = ("t", "imu", "ax", "ay", "az", "gx", "gy", "gz")
TRUTH_COLUMNS = ("px", "py", "pz", "vx", "vy", "vz", "roll", "pitch", "yaw", "wbx", "wby", "wbz")
BIAS_COLUMNS = ("bax", "bay", "baz", "bgx", "bgy", "bgz")   # realized bias of each IMU (sensor errors on)
#: integrated outputs over (t_k-1, t_k] (imu_emulator.codegen.increments), rad and m/s, after the gyro columns
INCREMENT_COLUMNS = ("dtheta_x", "dtheta_y", "dtheta_z", "dvel_x", "dvel_y", "dvel_z")
SUFFIXES = (".csv", ".npz", ".mcap", ".parquet")


def check_path(path: str | Path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ImuEmulatorError(f"{path}: output must end in {' or '.join(SUFFIXES)}")
    if not path.parent.exists():
        raise ImuEmulatorError(f"{path}: directory {path.parent} does not exist")
    return path


class Writer(FinishOnExit):
    """Receives blocks in order and writes them; CSV streams to disk, NPZ collects then saves.
    The output file is created at construction (an unwritable path fails before the run), and appears at
    its path on close(); discard() (or close() after an exception) leaves nothing behind."""

    def __init__(self, path: str | Path, imu_names, truth: bool, bias_truth: bool = False, temperature: bool = False,
                 increments: bool = False, conventions: list[str] | None = None):
        self.path = check_path(path)
        #: Earth scenes with truth: the frame and sign conventions ('#' lines before the CSV header, NPZ
        #: "conventions") and the Earth truth columns (imu_emulator.motion.earth_truth)
        self.conventions = list(conventions) if truth and conventions else []
        self.increments = increments
        self.imu_names = list(imu_names)
        self.truth = truth
        self.bias_truth = truth and bias_truth
        self.temperature = temperature
        self.blocks: list[SampleBlock] = []
        self.csv = self.path.suffix.lower() == ".csv"
        self._out = AtomicOutput(self.path, "wb")
        if self.csv:
            from imu_emulator.output.csv_text import RowWriter
            self._rows = RowWriter(self.imu_names)
            self._out.write("".join(f"# {line}\n" for line in self.conventions).encode())
            self._out.write((",".join(CSV_COLUMNS + (INCREMENT_COLUMNS if increments else ())
                                      + (("temp_c",) if temperature else ()) + (TRUTH_COLUMNS if truth else ())
                                      + (BIAS_COLUMNS if self.bias_truth else ()) + _earth_columns(self.conventions))
                             + "\n").encode())

    def write(self, block: SampleBlock) -> None:
        if not self.csv:
            self.blocks.append(block)
            return
        self._out.write(_csv_text(self._rows, block, self.imu_names, self.truth, self.bias_truth, self.temperature,
                                  self.increments, bool(self.conventions)))

    def close(self) -> None:
        """Finish the file and put it at its path."""
        try:
            if not self.csv:
                self._save_npz()
        except BaseException:
            self._out.discard()
            raise
        self._out.close()

    def discard(self) -> None:
        """The run failed: remove what was written."""
        self._out.discard()

    def _save_npz(self) -> None:
        data = concatenate(self.blocks)
        arrays = {"t": data.t_s, "imu_names": np.array(self.imu_names), "accel": data.accel, "gyro": data.gyro}
        if data.quat is not None:
            arrays["quat"] = data.quat
        if data.temperature_c is not None:
            arrays["temperature_c"] = data.temperature_c
        if self.increments:
            arrays.update(dtheta=data.dtheta, dvel=data.dvel)
        if data.time_offset_s is not None:      # [[imu]] time_offset_s: each IMU's own stamps, (imu, n)
            arrays["t_imu"] = data.imu_t_s()
        if self.truth:
            arrays.update(data.truth)
        if self.conventions:
            arrays["conventions"] = np.array(self.conventions)
        try:
            np.savez(self._out.file, **arrays)
        except OSError as exc:
            raise output_error(self.path, exc) from None


def open_writer(path: str | Path, imu_names, truth: bool, bias_truth: bool = False, temperature: bool = False,
                increments: bool = False, metadata: dict | None = None, conventions: list[str] | None = None,
                covariances: dict | None = None, frame: str | None = None, attitude_reference: str = "local_level",
                effects=()):
    """The writer for the output file's suffix: .mcap is a ROS 2 bag (imu_emulator.output.mcap; it carries no
    temperature, and no increments: sensor_msgs/Imu has no field for them; it takes the noise covariances per
    IMU, effects.noise.variances; with `conventions` and the scene's `frame` it adds the Earth truth, whose body
    rate needs the scene's `attitude_reference` and `effects`); .parquet
    is a table with `metadata` (scene hash, seed, versions) in its
    footer (imu_emulator.output.parquet)."""
    if Path(path).suffix.lower() == ".parquet":
        from imu_emulator.output.parquet import ParquetWriter
        return ParquetWriter(check_path(path), imu_names, truth, bias_truth=bias_truth, temperature=temperature,
                             increments=increments, metadata=metadata, conventions=conventions)
    if Path(path).suffix.lower() == ".mcap":
        if increments:
            raise ImuEmulatorError(f"{path}: --increments: a ROS 2 bag's sensor_msgs/Imu has no field for "
                                   "integrated outputs; write .csv or .npz")
        from imu_emulator.output.mcap import McapWriter
        return McapWriter(check_path(path), imu_names, truth, covariances,
                          earth_frame=frame if conventions else None, attitude_reference=attitude_reference,
                          effects=effects)
    return Writer(path, imu_names, truth, bias_truth=bias_truth, temperature=temperature, increments=increments,
                  conventions=conventions)


def _earth_columns(conventions) -> tuple[str, ...]:
    if not conventions:
        return ()
    from imu_emulator.motion.earth_truth import COLUMNS
    return tuple(name for names in COLUMNS.values() for name in names)


def csv_rows(block: SampleBlock, imu_names, truth: bool, bias_truth: bool = False,
             temperature: bool = False, increments: bool = False, earth: bool = False) -> str:
    """The CSV rows of one block (no header): one row per IMU per sample, sample k of every IMU before sample k+1.

    Numbers are the shortest text that reads back as the same double, like Python's repr (imu_emulator.output.csv_text;
    a block holding a NaN or infinity goes through pyarrow's CSV writer, which writes them as nan and inf).
    """
    from imu_emulator.output.csv_text import RowWriter
    return bytes(_csv_text(RowWriter(imu_names), block, imu_names, truth, bias_truth, temperature, increments,
                           earth)).decode()


def _csv_text(row_writer, block: SampleBlock, imu_names, *options) -> bytes | memoryview:
    text = row_writer.rows(csv_segments(block, len(imu_names), *options), len(block))
    return _pyarrow_csv_rows(block, imu_names, *options).encode() if text is None else text


def csv_segments(block: SampleBlock, n_imu: int, truth: bool, bias_truth: bool = False, temperature: bool = False,
                 increments: bool = False, earth: bool = False) -> list[tuple[bool, np.ndarray]]:
    """The numeric columns of a CSV row in order, as groups (per_imu, matrix) for csv_text.rows: a per-IMU
    matrix has a row per IMU per sample (IMU fastest), the others (time without offsets, truth) a row per sample."""
    def interleaved(*per_imu):      # (n_imu, n, k) arrays -> (n * n_imu, sum k), IMU index fastest
        joined = np.concatenate(per_imu, axis=2)
        return joined.transpose(1, 0, 2).reshape(len(block) * n_imu, -1)

    groups = [(True, block.imu_t_s().T.reshape(-1, 1)) if block.time_offset_s is not None
              else (False, block.t_s[:, None])]
    numeric = [block.accel, block.gyro] + ([block.dtheta, block.dvel] if increments else [])
    if temperature:
        numeric.append(block.temperature_c[:, :, None])
    groups.append((True, interleaved(*numeric)))
    if truth:
        groups.append((False, np.hstack([block.truth[key] for key in ("position", "velocity", "euler",
                                                                       "omega_body")])))
    if bias_truth:
        groups.append((True, interleaved(block.truth["accel_bias"], block.truth["gyro_bias"])))
    if earth:
        from imu_emulator.motion.earth_truth import KEYS
        shared = np.hstack([block.truth[key] for key in KEYS])
        if groups[-1][0]:
            groups.append((False, shared))
        else:                   # right after the truth columns: one group
            groups[-1] = (False, np.hstack([groups[-1][1], shared]))
    return groups


def _pyarrow_csv_rows(block: SampleBlock, imu_names, truth: bool, bias_truth: bool = False,
                      temperature: bool = False, increments: bool = False, earth: bool = False) -> str:
    """csv_rows through pyarrow's CSV writer (double-conversion's shortest mode), which has a text for NaN and
    infinities; about 180 ns a number."""
    import pyarrow as pa
    import pyarrow.csv as pa_csv

    columns = block_columns(block, imu_names, truth, bias_truth, temperature, increments, earth=earth)
    # pyarrow's "needed" quotes every string; plain names go unquoted, as they always did.
    plain = not any(ch in name for name in imu_names for ch in '"\r\n,')
    sink = pa.BufferOutputStream()
    pa_csv.write_csv(pa.table(columns), sink, write_options=pa_csv.WriteOptions(
        include_header=False, quoting_style="none" if plain else "needed"))
    return sink.getvalue().to_pybytes().decode()


def block_columns(block: SampleBlock, imu_names, truth: bool, bias_truth: bool = False, temperature: bool = False,
                  increments: bool = False, time_ns: bool = False, earth: bool = False) -> dict:
    """The columns of one block, one row per IMU per sample (sample k of every IMU before sample k+1): "t" in
    seconds (or "t_ns", integer nanoseconds), "imu" (a pyarrow dictionary of the names), then float64 columns."""
    import pyarrow as pa

    n_imu, n = len(imu_names), len(block)

    def interleaved(per_imu):      # (n_imu, n, k) -> (n * n_imu, k), IMU index fastest
        return np.ascontiguousarray(per_imu.transpose(1, 0, 2)).reshape(n * n_imu, -1)

    stamps = (np.stack([block.time_ns(block.imu_offset_ns(m)) for m in range(n_imu)]) if time_ns
              else block.imu_t_s())   # (n_imu, n): each IMU's own stamps ([[imu]] time_offset_s)
    columns = {"t_ns" if time_ns else "t": stamps.T.ravel(),
               "imu": pa.DictionaryArray.from_arrays(np.tile(np.arange(n_imu, dtype=np.int32), n),
                                                     pa.array(list(imu_names)))}
    numeric = [interleaved(block.accel), interleaved(block.gyro)]
    if increments:
        numeric += [interleaved(block.dtheta), interleaved(block.dvel)]
    if temperature:
        numeric.append(interleaved(block.temperature_c[:, :, None]))
    if truth:
        tr = block.truth
        numeric += [np.repeat(tr[key], n_imu, axis=0) for key in ("position", "velocity", "euler", "omega_body")]
    if bias_truth:
        numeric += [interleaved(block.truth["accel_bias"]), interleaved(block.truth["gyro_bias"])]
    if earth:
        from imu_emulator.motion.earth_truth import KEYS
        numeric += [np.repeat(block.truth[key], n_imu, axis=0) for key in KEYS]
    values = np.hstack(numeric)
    names = (CSV_COLUMNS[2:] + (INCREMENT_COLUMNS if increments else ()) + (("temp_c",) if temperature else ())
             + (TRUTH_COLUMNS if truth else ())
             + (BIAS_COLUMNS if bias_truth else ()) + _earth_columns(earth))
    for i, name in enumerate(names):
        columns[name] = values[:, i]
    return columns
