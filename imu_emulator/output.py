"""Write samples to CSV or NPZ (chosen by the output file's suffix)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imu_emulator.errors import ImuEmulatorError
from imu_emulator.samples import SampleBlock, concatenate

CSV_COLUMNS = ("t", "imu", "ax", "ay", "az", "gx", "gy", "gz")
TRUTH_COLUMNS = ("px", "py", "pz", "vx", "vy", "vz", "roll", "pitch", "yaw", "wbx", "wby", "wbz")
SUFFIXES = (".csv", ".npz", ".mcap")


def check_path(path: str | Path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ImuEmulatorError(f"{path}: output must end in {' or '.join(SUFFIXES)}")
    if not path.parent.exists():
        raise ImuEmulatorError(f"{path}: directory {path.parent} does not exist")
    return path


class Writer:
    """Receives blocks in order and writes them; CSV streams to disk, NPZ collects then saves."""

    def __init__(self, path: str | Path, imu_names, truth: bool):
        self.path = check_path(path)
        self.imu_names = list(imu_names)
        self.truth = truth
        self.blocks: list[SampleBlock] = []
        self._csv = None
        if self.path.suffix.lower() == ".csv":
            self._csv = open(self.path, "w", newline="")
            self._csv.write(",".join(CSV_COLUMNS + (TRUTH_COLUMNS if truth else ())) + "\n")

    def write(self, block: SampleBlock) -> None:
        if self._csv is None:
            self.blocks.append(block)
            return
        extra = []
        if self.truth:
            tr = block.truth
            extra = [tr["position"], tr["velocity"], tr["euler"], tr["omega_body"]]
        per_imu = []
        for m, name in enumerate(self.imu_names):
            numeric = np.column_stack([block.t_s, block.accel[m], block.gyro[m], *extra])
            # %.17g keeps every bit: reading the CSV back gives the same doubles.
            text = np.char.mod("%.17g", numeric).tolist()
            per_imu.append([",".join((r[0], name, *r[1:])) for r in text])
        # One row per IMU per sample, sample k of every IMU before sample k+1.
        self._csv.write("\n".join(row for rows in zip(*per_imu) for row in rows) + "\n")

    def close(self) -> None:
        if self._csv is not None:
            self._csv.close()
            return
        if not self.blocks:  # the run failed before its first block: leave no half-written file
            return
        data = concatenate(self.blocks)
        arrays = {"t": data.t_s, "imu_names": np.array(self.imu_names), "accel": data.accel, "gyro": data.gyro}
        if data.quat is not None:
            arrays["quat"] = data.quat
        if self.truth:
            arrays.update(data.truth)
        np.savez(self.path, **arrays)


def open_writer(path: str | Path, imu_names, truth: bool):
    """The writer for the output file's suffix: .mcap is a ROS 2 bag (imu_emulator.output_mcap)."""
    if Path(path).suffix.lower() == ".mcap":
        from imu_emulator.output_mcap import McapWriter
        return McapWriter(check_path(path), imu_names, truth)
    return Writer(path, imu_names, truth)
