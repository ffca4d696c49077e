"""Samples as CSV (`-o run.csv`), streamed block by block: '#' lines stating the frames, sign conventions and
units (imu_emulator.output.statement), a header row of the columns (imu_emulator.output.columns), then one row
per IMU per sample. Numbers are the shortest text that reads back as the same double
(imu_emulator.output.csv_text).

Size: CSV_CHARS_PER_NUMBER characters a number, an estimate (shortest round-trip text is 16-17 significant
digits for most measured doubles, fewer for round ones): tests/output/test_output_earth_formats.py holds it within
CSV_ESTIMATE_MARGIN of an Earth run with noise; runs of round numbers come out smaller (two_imus.toml,
noise-free: 0.72-0.99 of it). `csv_bytes`, every number at its longest, is the bound the disk check uses.
"""
from __future__ import annotations

import os
import shutil
from dataclasses import astuple
from pathlib import Path

import numpy as np

from imu_emulator.output.atomic import AtomicOutput, FinishOnExit
from imu_emulator.output.base import Contents, Format
from imu_emulator.output.columns import IMU, TIME, Layout, block_columns, scene_layout
from imu_emulator.output.statement import statement
from imu_emulator.runtime.memory import RunSizeError, gib
from imu_emulator.runtime.samples import SampleBlock

# "%.17g" of a double is at most 24 characters (sign, 17 digits, point, "e-308"), plus its comma.
CSV_BYTES_PER_VALUE = 25
# a number's typical text: 16-17 significant digits and the point for measured values, a few short ones
# (0.0, constant temperatures, round time stamps) between them; plus its comma
CSV_CHARS_PER_NUMBER = 18
CSV_ESTIMATE_MARGIN = 0.2


class CsvWriter(FinishOnExit):
    """Writes each block's rows as it comes; the file appears at its path on close()."""

    def __init__(self, path: Path, contents: Contents):
        from imu_emulator.output.csv_text import RowWriter
        self.path = Path(path)
        self.imu_names = list(contents.imu_names)
        self.layout = contents.layout
        self._options = astuple(self.layout)
        self._out = AtomicOutput(self.path, "wb")
        self._rows = RowWriter(self.imu_names)
        self._out.write("".join(f"# {line}\n" for line in statement(contents)).encode())
        self._out.write((",".join((TIME.name, IMU.name) + self.layout.names()) + "\n").encode())

    def write(self, block: SampleBlock) -> None:
        self._out.write(_csv_text(self._rows, block, self.imu_names, *self._options))

    def close(self) -> None:
        """Finish the file and put it at its path."""
        self._out.close()

    def discard(self) -> None:
        """The run failed: remove what was written."""
        self._out.discard()


def csv_rows(block: SampleBlock, imu_names, truth: bool, bias_truth: bool = False,
             temperature: bool = False, increments: bool = False, earth: bool = False, companions=()) -> str:
    """The CSV rows of one block (no header): one row per IMU per sample, sample k of every IMU before sample k+1.

    Numbers are the shortest text that reads back as the same double, like Python's repr (imu_emulator.output.csv_text;
    a block holding a NaN or infinity goes through pyarrow's CSV writer, which writes them as nan and inf).
    """
    from imu_emulator.output.csv_text import RowWriter
    return bytes(_csv_text(RowWriter(imu_names), block, imu_names, truth, bias_truth, temperature, increments,
                           earth, companions)).decode()


def _csv_text(row_writer, block: SampleBlock, imu_names, *options) -> bytes | memoryview:
    """options: Layout's fields in order (truth, bias_truth, temperature, increments, earth, companions)."""
    text = row_writer.rows(csv_segments(block, len(imu_names), *options), len(block))
    return _pyarrow_csv_rows(block, imu_names, *options).encode() if text is None else text


def csv_segments(block: SampleBlock, n_imu: int, truth: bool, bias_truth: bool = False, temperature: bool = False,
                 increments: bool = False, earth: bool = False, companions=()) -> list[tuple[bool, np.ndarray]]:
    """The numeric columns of a CSV row in order, as groups (per_imu, matrix) for csv_text.rows: a per-IMU
    matrix has a row per IMU per sample (IMU fastest), the others (time without offsets, truth) a row per sample.
    Neighbouring column groups of the same kind (imu_emulator.output.columns) are one matrix, formatted in one
    call."""
    def interleaved(*per_imu):      # (n_imu, n, k) arrays -> (n * n_imu, sum k), IMU index fastest
        joined = np.concatenate(per_imu, axis=2)
        return joined.transpose(1, 0, 2).reshape(len(block) * n_imu, -1)

    segments = [(True, block.imu_t_s().T.reshape(-1, 1)) if block.time_offset_s is not None
                else (False, block.t_s[:, None])]
    runs: list[tuple[bool, list]] = []
    for group in Layout(truth, bias_truth, temperature, increments, earth, tuple(companions)).groups():
        if runs and runs[-1][0] == group.per_imu:
            runs[-1][1].extend(group.arrays(block))
        else:
            runs.append((group.per_imu, group.arrays(block)))
    segments += [(per_imu, interleaved(*arrays) if per_imu else np.hstack(arrays)) for per_imu, arrays in runs]
    return segments


def _pyarrow_csv_rows(block: SampleBlock, imu_names, truth: bool, bias_truth: bool = False,
                      temperature: bool = False, increments: bool = False, earth: bool = False, companions=()) -> str:
    """csv_rows through pyarrow's CSV writer (double-conversion's shortest mode), which has a text for NaN and
    infinities; about 180 ns a number."""
    import pyarrow as pa
    import pyarrow.csv as pa_csv

    columns = block_columns(block, imu_names, Layout(truth, bias_truth, temperature, increments, earth,
                                                     tuple(companions)))
    # pyarrow's "needed" quotes every string; plain names go unquoted, as they always did.
    plain = not any(ch in name for name in imu_names for ch in '"\r\n,')
    sink = pa.BufferOutputStream()
    pa_csv.write_csv(pa.table(columns), sink, write_options=pa_csv.WriteOptions(
        include_header=False, quoting_style="none" if plain else "needed"))
    return sink.getvalue().to_pybytes().decode()


def csv_bytes(scene, truth: bool, increments: bool = False) -> int:
    """Upper bound on a CSV's size: one row per sample per IMU, every number at its longest."""
    return _csv_size(scene, truth, increments, CSV_BYTES_PER_VALUE - 1)


def estimated_bytes(scene, truth: bool, increments: bool = False) -> int:
    return _csv_size(scene, truth, increments, CSV_CHARS_PER_NUMBER)


def _csv_size(scene, truth: bool, increments: bool, chars_per_number: int) -> int:
    per_imu, shared = scene_layout(scene, truth, increments).counts()
    names = sum(len(name.encode()) + 1 for name in scene.imu_names)             # and its comma
    return scene.n_samples * (len(scene.imus) * (1 + per_imu + shared) * (chars_per_number + 1) + names)


def check_disk(scene, output: Path, truth: bool, allow_large: bool = False, increments: bool = False) -> None:
    """A CSV must fit on the disk of its directory unless `allow_large` (the estimate is an upper bound)."""
    n = scene.n_samples
    need = csv_bytes(scene, truth, increments)
    usage = shutil.disk_usage(output.parent if str(output.parent) else Path(os.curdir))
    free = usage.free
    # total 0: a pseudo file system (/proc, /dev) that reports no sizes; the writer's own errors speak there
    if usage.total and need > free and not allow_large:
        raise RunSizeError(f"{output}: {n} samples x {len(scene.imus)} IMU(s) make up to {gib(need)} of CSV, "
                           f"{gib(free)} are free there; shorten scene.duration_s or lower scene.rate_hz, "
                           "or pass --allow-large if you know it fits")


def _header(path: Path) -> tuple[list[str], list[str]]:
    """The '#' conventions lines (Earth scenes' outputs start with them) and the header's column names."""
    lines = []
    with open(path) as f:
        line = f.readline()
        while line.startswith("#"):
            lines.append(line[1:].strip())
            line = f.readline()
    return lines, [name.strip().lower() for name in line.split(",")]


def read_columns(path: Path, names: tuple[str, ...]) -> dict | None:
    conventions, header = _header(path)
    if not set(names) <= set(header):
        return None
    values = np.loadtxt(path, delimiter=",", skiprows=len(conventions) + 1,
                        usecols=[header.index(c) for c in names], ndmin=2)
    return {name: values[:, i] for i, name in enumerate(names)}


def read_conventions(path: Path) -> list[str]:
    return _header(path)[0]


FORMAT = Format("CSV", (".csv",), CsvWriter, estimated_bytes, order=10,
                margin=(1 - CSV_ESTIMATE_MARGIN, 1 + CSV_ESTIMATE_MARGIN), description="a CSV file", check=check_disk,
                read_columns=read_columns, read_conventions=read_conventions)
