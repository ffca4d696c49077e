"""Samples as Parquet (`-o run.parquet`), block by block: each block is one row group, so memory does not grow
with the run. Columns: t_ns (int64, ns on the scene's time base), imu (dictionary-encoded name), ax ay az (m/s^2),
gx gy gz (rad/s), then as in CSV the increments (--increments), temp_c, truth, realized-bias and (a scene on the
Earth, with --truth) Earth truth columns. The footer's key "imu_emulator" holds JSON: the scene's hash and seed,
the versions that wrote it, whatever the caller adds (a batch's draws) and "conventions" (the frames and units, the
lines a CSV starts with: imu_emulator.output.statement); each field's metadata holds its "unit" and "description".

Size: the uncompressed bytes of every value (8 a number, 4 for the IMU's dictionary index). The file is
compressed (Snappy) and comes out smaller, 0.1-0.7 of it, except a short file of noisy numbers, whose
dictionary pages can add up to about 6 % (the test allows 25 %).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from imu_emulator.output.atomic import AtomicOutput, FinishOnExit, output_error
from imu_emulator.output.base import Contents, Format
from imu_emulator.output.columns import TIME, block_columns, scene_layout
from imu_emulator.output.run_record import run_metadata
from imu_emulator.runtime.samples import SampleBlock

METADATA_KEY = b"imu_emulator"


def read_metadata(path: str | Path) -> dict:
    """The "imu_emulator" footer entry of a Parquet file written here ({} when it has none)."""
    import pyarrow.parquet as pq
    raw = pq.read_schema(path).metadata or {}
    return json.loads(raw[METADATA_KEY]) if METADATA_KEY in raw else {}


class ParquetWriter(FinishOnExit):
    """Receives blocks in order and writes each as a row group; the file appears at its path on close()."""

    def __init__(self, path: Path, contents: Contents):
        self.path = Path(path)
        self.imu_names = list(contents.imu_names)
        self.layout = contents.layout
        from imu_emulator.output.columns import described
        from imu_emulator.output.statement import statement
        metadata = dict(contents.metadata or {}, conventions=statement(contents))
        #: each field's unit and meaning, in the field's own metadata (what pyarrow and Arrow tools show)
        self.field_metadata = {("t_ns" if c.name == TIME.name else c.name): {
            b"unit": b"ns" if c.name == TIME.name else c.unit.encode(), b"description": c.what.encode()}
            for c in described(self.layout)}
        self.metadata = {METADATA_KEY: json.dumps(metadata, sort_keys=True).encode()}
        self._out = AtomicOutput(self.path, "wb")
        self._writer = None     # opened on the first block, when the schema is known

    def write(self, block: SampleBlock) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq
        table = pa.table(block_columns(block, self.imu_names, self.layout, time_ns=True))
        schema = pa.schema([f.with_metadata(self.field_metadata.get(f.name, {})) for f in table.schema],
                           metadata=self.metadata)
        table = pa.Table.from_arrays(table.columns, schema=schema)
        try:
            if self._writer is None:
                self._writer = pq.ParquetWriter(self._out.file, schema)
            self._writer.write_table(table)
        except OSError as exc:
            raise output_error(self.path, exc) from None

    def close(self) -> None:
        try:
            if self._writer is not None:
                self._writer.close()
        except OSError as exc:
            self._out.discard()
            raise output_error(self.path, exc) from None
        except BaseException:
            self._out.discard()
            raise
        self._out.close()

    def discard(self) -> None:
        try:
            if self._writer is not None:
                self._writer.close()
        except Exception:
            pass        # the contents are being thrown away
        self._out.discard()


def estimated_bytes(scene, truth: bool, increments: bool = False) -> int:
    per_imu, shared = scene_layout(scene, truth, increments).counts()
    return scene.n_samples * len(scene.imus) * (8 * (1 + per_imu + shared) + 4)


def read_columns(path: Path, names: tuple[str, ...]) -> dict | None:
    """The columns `names` (rows IMU-fastest, as written; "t" in seconds from t_ns, "imu" the names as an object
    array), None when one is missing."""
    import pyarrow.parquet as pq
    stored = ["t_ns" if name == TIME.name else name for name in names]
    if not set(stored) <= set(pq.read_schema(path).names):
        return None
    table = pq.read_table(path, columns=stored)
    columns = {name: table.column(column).to_numpy() for name, column in zip(names, stored)}   # imu: its names
    if TIME.name in columns:
        columns[TIME.name] = columns[TIME.name] / np.float64(1e9)
    return columns


def read_conventions(path: Path) -> list[str]:
    return list(read_metadata(path).get("conventions", []))


FORMAT = Format("Parquet", (".parquet",), ParquetWriter, estimated_bytes, order=40, margin=(0.1, 1.25),
                description="a Parquet table", run_metadata=run_metadata, read_columns=read_columns,
                read_conventions=read_conventions)
