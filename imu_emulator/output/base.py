"""What an output format is: a writer (the `Writer` protocol) and the record a format module declares
(`FORMAT = Format(...)`, found by imu_emulator.output.formats). CONTRIBUTING.md "Adding an output format"."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Protocol

from imu_emulator.output.columns import Layout


class Writer(Protocol):
    """Receives a run's blocks in order. The file is created when the writer is made (an unwritable path fails
    before the run) and appears at its path, complete, on close(); discard() (or leaving a `with` block by an
    exception) leaves nothing behind (imu_emulator.output.atomic)."""

    def write(self, block) -> None: ...

    def close(self) -> None: ...

    def discard(self) -> None: ...

    def __enter__(self) -> "Writer": ...

    def __exit__(self, kind, exc, tb) -> None: ...


@dataclass(frozen=True)
class Contents:
    """What a writer is told before the first block: the IMUs, the groups of columns, and what some formats
    record besides the samples."""
    imu_names: list[str]
    layout: Layout
    #: Earth scenes with truth: the frame and sign conventions (imu_emulator.motion.earth_truth.conventions)
    conventions: list[str] = field(default_factory=list)
    metadata: dict | None = None            # Parquet's footer: scene hash, seed, versions, a batch's draws
    covariances: dict | None = None         # MCAP: noise variances per IMU (effects.noise.variances)
    frame: str | None = None                # MCAP: the scene's frame (Earth truth's body axes)
    attitude_reference: str = "local_level"  # MCAP: what the truth's body rate is relative to
    effects: frozenset = frozenset()
    #: MCAP (output.ros2.conventions): the Unix time of scene time 0, ns (None: the documented default), the
    #: axes ("rep103" or "scene"), each IMU's (lever arm, mounting sensor -> body) in the scene's body axes
    start_ns: int | None = None
    ros_axes: str = "rep103"
    placements: list | None = None


@dataclass(frozen=True)
class Format:
    """An output format, declared by its module as FORMAT.

    `estimated_bytes(scene, truth, increments)`: the file's size before the run (`check` prints it, and the
    checks before a run use it); `margin` (low, high): the real file's size over the estimate lies in it for a
    run with noise (tests/output/test_output_earth_formats.py holds every format to its margin)."""
    name: str                                       # as `check` prints it: "CSV"
    suffixes: tuple[str, ...]                       # lower case, with the dot
    open: Callable[[Path, Contents], Writer]
    estimated_bytes: Callable[..., int]
    margin: tuple[float, float]
    description: str
    #: where the format stands when formats are listed (the suffixes an error or a help text names): the plain
    #: files first, as users met them
    order: int = 100
    increments: bool = True                         # can carry --increments
    #: the writer wants the sensor frame's attitude (block.quat): the simulation computes it only then
    attitude: bool = False
    #: what the file records about the run (scene hash, versions), from the scene; None: nothing. Called only
    #: for this format: reading the packages' versions costs a warm start 0.1-0.2 s (issue 15)
    run_metadata: Callable[..., dict] | None = None
    #: before the run, with the scene: refuse (RunSizeError) what would not fit; None: nothing to check
    check: Callable[..., None] | None = None
    #: the schema's float64 columns (besides t) the file holds for a layout; None: all of them (Layout.names)
    columns: Callable[[Layout], tuple[str, ...]] | None = None
    #: the float64 columns the file holds, read back by name: read_columns(path, names) -> {name: (rows,)}
    #: (rows IMU-fastest, "t" in seconds, "imu" the names where the format can), None when a name is missing
    read_columns: Callable[[Path, tuple[str, ...]], dict | None] | None = None
    #: the conventions lines the file states (Earth scenes), [] when none
    read_conventions: Callable[[Path], list[str]] | None = None

    def carries(self, layout: Layout) -> tuple[str, ...]:
        return layout.names() if self.columns is None else self.columns(layout)
