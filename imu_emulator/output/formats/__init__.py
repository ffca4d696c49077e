"""The output formats `generate`, `replay` and `batch` write, one module each, chosen by the file's suffix.

The table is found, not kept: every module of this package not starting with "_" must define
FORMAT = imu_emulator.output.base.Format(...) (a module that fails to import is an error naming it). Format
modules import their heavy libraries (numba, pyarrow, mcap) inside functions: finding the table is cheap.
"""
from __future__ import annotations

import sys
from pathlib import Path

from imu_emulator import extensions
from imu_emulator.errors import ImuEmulatorError
from imu_emulator.output.base import Contents, Format
from imu_emulator.output.columns import Layout


def _discover() -> dict[str, Format]:
    found = {}
    records = extensions.declared(sys.modules[__name__], "FORMAT", Format, named=False)
    for record in sorted(records, key=lambda record: (record.order, record.name)):
        for suffix in record.suffixes:
            if suffix in found:
                raise ImportError(f"{record.name} format: suffix {suffix} is already {found[suffix].name}'s")
            found[suffix] = record
    return found


#: suffix ("." and lower case) -> format
FORMATS: dict[str, Format] = _discover()
SUFFIXES = tuple(FORMATS)


def by_name() -> dict[str, Format]:
    """name ("CSV") -> format, each once."""
    return {record.name: record for record in FORMATS.values()}


def format_of(path: str | Path) -> Format | None:
    return FORMATS.get(Path(path).suffix.lower())


def check_path(path: str | Path) -> Path:
    path = Path(path)
    if format_of(path) is None:
        raise ImuEmulatorError(f"{path}: output must end in {' or '.join(SUFFIXES)}")
    if not path.parent.exists():
        raise ImuEmulatorError(f"{path}: directory {path.parent} does not exist")
    return path


def open_writer(path: str | Path, imu_names, truth: bool, bias_truth: bool = False, temperature: bool = False,
                increments: bool = False, metadata: dict | None = None, conventions: list[str] | None = None,
                covariances: dict | None = None, frame: str | None = None, attitude_reference: str = "local_level",
                effects=(), companions=(), start_ns: int | None = None, ros_axes: str = "rep103", placements=None):
    """The writer for the output file's suffix (see each format's module). `conventions` (Earth scenes with
    truth) adds the Earth truth; `metadata` is what Parquet records in its footer; `covariances`, `frame`,
    `attitude_reference`, `effects`, `start_ns`, `ros_axes` and `placements` are what MCAP needs beyond the
    columns (output.base.Contents); `companions` the companion sensors' column groups
    (imu_emulator.output.columns.scene_companions)."""
    path = check_path(path)
    record = format_of(path)
    if increments and not record.increments:
        raise ImuEmulatorError(f"{path}: --increments: {record.description} has no field for integrated outputs; "
                               f"write {' or '.join(s for s, f in FORMATS.items() if f.increments)}")
    layout = Layout(truth=truth, bias_truth=bias_truth, temperature=temperature, increments=increments,
                    earth=bool(truth and conventions), companions=tuple(companions))
    return record.open(path, Contents(list(imu_names), layout, list(conventions) if layout.earth else [],
                                      metadata=metadata, covariances=covariances, frame=frame,
                                      attitude_reference=attitude_reference, effects=frozenset(effects),
                                      start_ns=start_ns, ros_axes=ros_axes, placements=placements))


def check_output(scene, output: str | Path, truth: bool, allow_large: bool = False, increments: bool = False) -> None:
    """Before `generate` runs: what the output's format checks (an NPZ must fit in memory, a CSV on its disk
    unless `allow_large`); RunSizeError (imu_emulator.runtime.memory) when it does not."""
    record = format_of(output)
    if record is not None and record.check is not None:
        record.check(scene, Path(output), truth, allow_large=allow_large, increments=increments)
