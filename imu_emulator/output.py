"""Write samples to CSV or NPZ (chosen by the output file's suffix). The file appears only complete: it is
written under a temporary name and renamed when the run succeeds (imu_emulator.outfile)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imu_emulator.errors import ImuEmulatorError
from imu_emulator.outfile import AtomicOutput, FinishOnExit, output_error
from imu_emulator.samples import SampleBlock, concatenate

CSV_COLUMNS = ("t", "imu", "ax", "ay", "az", "gx", "gy", "gz")
TRUTH_COLUMNS = ("px", "py", "pz", "vx", "vy", "vz", "roll", "pitch", "yaw", "wbx", "wby", "wbz")
BIAS_COLUMNS = ("bax", "bay", "baz", "bgx", "bgy", "bgz")   # realized bias of each IMU (sensor errors on)
SUFFIXES = (".csv", ".npz", ".mcap")


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

    def __init__(self, path: str | Path, imu_names, truth: bool, bias_truth: bool = False, temperature: bool = False):
        self.path = check_path(path)
        self.imu_names = list(imu_names)
        self.truth = truth
        self.bias_truth = truth and bias_truth
        self.temperature = temperature
        self.blocks: list[SampleBlock] = []
        self.csv = self.path.suffix.lower() == ".csv"
        self._out = AtomicOutput(self.path, "w" if self.csv else "wb")
        if self.csv:
            self._out.write(",".join(CSV_COLUMNS + (("temp_c",) if temperature else ()) + (TRUTH_COLUMNS if truth else ())
                                      + (BIAS_COLUMNS if self.bias_truth else ())) + "\n")

    def write(self, block: SampleBlock) -> None:
        if not self.csv:
            self.blocks.append(block)
            return
        extra = []
        if self.truth:
            tr = block.truth
            extra = [tr["position"], tr["velocity"], tr["euler"], tr["omega_body"]]
        per_imu = []
        for m, name in enumerate(self.imu_names):
            bias = [block.truth["accel_bias"][m], block.truth["gyro_bias"][m]] if self.bias_truth else []
            temperature = [block.temperature_c[m]] if self.temperature else []
            numeric = np.column_stack([block.t_s, block.accel[m], block.gyro[m], *temperature, *extra, *bias])
            # %.17g keeps every bit: reading the CSV back gives the same doubles.
            text = np.char.mod("%.17g", numeric).tolist()
            per_imu.append([",".join((r[0], name, *r[1:])) for r in text])
        # One row per IMU per sample, sample k of every IMU before sample k+1.
        self._out.write("\n".join(row for rows in zip(*per_imu) for row in rows) + "\n")

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
        if self.truth:
            arrays.update(data.truth)
        try:
            np.savez(self._out.file, **arrays)
        except OSError as exc:
            raise output_error(self.path, exc) from None


def open_writer(path: str | Path, imu_names, truth: bool, bias_truth: bool = False, temperature: bool = False):
    """The writer for the output file's suffix: .mcap is a ROS 2 bag (imu_emulator.output_mcap; it carries no
    temperature)."""
    if Path(path).suffix.lower() == ".mcap":
        from imu_emulator.output_mcap import McapWriter
        return McapWriter(check_path(path), imu_names, truth)
    return Writer(path, imu_names, truth, bias_truth=bias_truth, temperature=temperature)
