"""Samples as NPZ (`-o run.npz`): numpy arrays of the whole run, collected in memory and saved on close: t (n,),
imu_names, accel and gyro (imu, n, 3), quat when the simulation has the attitude, temperature_c (imu, n),
dtheta and dvel (--increments), t_imu (imu, n) when an IMU has its own time_offset_s, the truth's keys
(--truth; imu_emulator.runtime.simulation.TRUTH_KEYS, the realized biases, the Earth truth), "conventions" (the
frames and units: imu_emulator.output.statement) and "units" (one line per array: its key, unit and meaning).

Size: the arrays' bytes plus NPZ_ARRAY_OVERHEAD per array: exact to within that overhead. The whole run must
fit in memory twice (the blocks, then the joined arrays): checked before the run.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from imu_emulator.output.atomic import AtomicOutput, FinishOnExit, output_error
from imu_emulator.output.base import Contents, Format
from imu_emulator.output.columns import COMPANION_GROUPS, TIME, Layout
from imu_emulator.runtime.memory import check_fits
from imu_emulator.runtime.samples import SampleBlock, concatenate

NPZ_ARRAY_OVERHEAD = 272   # .npy header (128), the zip entry's local and central headers with zip64 extras and the
                           # name twice: measured 247-251 a array with names of 1-18 characters


class NpzWriter(FinishOnExit):
    """Collects the blocks, joins and saves them on close(); the file appears at its path then."""

    def __init__(self, path: Path, contents: Contents):
        self.path = Path(path)
        self.imu_names = list(contents.imu_names)
        self.layout = contents.layout
        from imu_emulator.output.statement import statement
        self.conventions = statement(contents)
        self.units = unit_lines(contents.layout)
        self.blocks: list[SampleBlock] = []
        self._out = AtomicOutput(self.path, "wb")

    def write(self, block: SampleBlock) -> None:
        self.blocks.append(block)

    def close(self) -> None:
        """Finish the file and put it at its path."""
        try:
            self._save()
        except BaseException:
            self._out.discard()
            raise
        self._out.close()

    def discard(self) -> None:
        """The run failed: remove what was written."""
        self._out.discard()

    def _save(self) -> None:
        data = concatenate(self.blocks)
        arrays = {"t": data.t_s, "imu_names": np.array(self.imu_names), "accel": data.accel, "gyro": data.gyro}
        if data.quat is not None:
            arrays["quat"] = data.quat
        if data.temperature_c is not None:
            arrays["temperature_c"] = data.temperature_c
        if self.layout.increments:
            arrays.update(dtheta=data.dtheta, dvel=data.dvel)
        if data.time_offset_s is not None:      # [[imu]] time_offset_s: each IMU's own stamps, (imu, n)
            arrays["t_imu"] = data.imu_t_s()
        if self.layout.truth:
            arrays.update(data.truth)
        for group in self.layout.groups():     # companion sensors: (imu, n[, k]) each, NaN for IMUs without
            if group.in_companion:
                arrays.update({key: array[:, :, 0] if array.shape[2] == 1 else array
                               for key, array in zip(group.keys, group.arrays(data))})
        arrays["conventions"] = np.array(self.conventions)
        arrays["units"] = np.array([self.units[key] for key in arrays if key in self.units])
        try:
            np.savez(self._out.file, **arrays)
        except OSError as exc:
            raise output_error(self.path, exc) from None


def unit_lines(layout) -> dict[str, str]:
    """Each array's unit and meaning as a line, by its key: "<key>: <unit> (<what>)", from the column schema's
    groups (an array holds a group's key, its columns' values along its last axis)."""
    lines = {"t": "t: s (sample time on the scene's time base)", "imu_names": "imu_names: the IMUs, in order",
             "t_imu": "t_imu: s (each IMU's stamps: t plus its time_offset_s)",
             "quat": "quat: 1 (attitude sensor -> navigation, scalar first)",
             "alpha_body": "alpha_body: rad/s^2 (angular acceleration of the body, body frame)"}
    for group in layout.groups():
        for key, columns in group.key_columns():
            units = ", ".join(dict.fromkeys(c.unit for c in columns))
            what = re.sub(r", [xyz]$", "", columns[0].what)         # the quantity, not its first axis
            lines[key] = f"{key}: {units} ({what})"
    return lines


def _text_bytes(lines) -> int:
    """A numpy unicode array of these lines: 4 bytes a character of the longest."""
    return 4 * max((len(line) for line in lines), default=0) * len(lines)


def estimated_bytes(scene, truth: bool, increments: bool = False) -> int:
    """NpzWriter's arrays: (count of numbers per sample, arrays) summed, as float64."""
    from imu_emulator.scene.earth import model_on
    from imu_emulator.codegen.plan import EffectPlan
    from imu_emulator.runtime.simulation import TRUTH_KEYS
    n, n_imu = scene.n_samples, len(scene.imus)
    parts = [(1, 1), (6 * n_imu, 2)]                                  # t; accel, gyro
    if "temperature" in scene.effects:
        parts.append((n_imu, 1))
    if increments:
        parts.append((6 * n_imu, 2))
    if any(imu.time_offset_s for imu in scene.imus):
        parts.append((n_imu, 1))                                      # t_imu
    text = 4 * max(len(name) for name in scene.imu_names) * n_imu     # imu_names, a unicode array
    from imu_emulator.output.columns import scene_companions
    for group in COMPANION_GROUPS:
        if group.option in scene_companions(scene):
            parts.append((len(group.columns) * n_imu, len(group.keys)))
    if any(imu.companions for imu in scene.imus):
        parts.append((4 * n_imu, 1))      # quat: the kernel computes the attitude the companions read
    conventions = []
    if truth:
        parts.append((3 * len(TRUTH_KEYS), len(TRUTH_KEYS)))
        if EffectPlan(scene).bias_truth:
            parts.append((6 * n_imu, 2))
        if model_on(scene):
            from imu_emulator.motion import earth_truth
            parts.append((3 * len(earth_truth.KEYS), len(earth_truth.KEYS)))
            conventions = earth_truth.conventions(scene)
    from imu_emulator.output.columns import scene_layout
    from imu_emulator.output.statement import statement
    layout = scene_layout(scene, truth, increments)
    text += _text_bytes(statement(Contents(list(scene.imu_names), layout, conventions, frame=scene.frame)))
    keys = ["t", "imu_names", *(["t_imu"] if any(imu.time_offset_s for imu in scene.imus) else [])]
    units = unit_lines(layout)
    truth_keys = ["alpha_body"] if truth else []          # in the truth, not a column
    text += _text_bytes([units[key] for key in keys + [k for g in layout.groups() for k in g.keys] + truth_keys])
    arrays = 3 + sum(count for _, count in parts)            # imu_names, conventions, units
    return 8 * n * sum(numbers for numbers, _ in parts) + text + NPZ_ARRAY_OVERHEAD * arrays


def check_memory(scene, output: Path, truth: bool, allow_large: bool = False, increments: bool = False) -> None:
    """An NPZ must fit in memory twice: the blocks, then the joined arrays."""
    check_fits(2 * estimated_bytes(scene, truth, increments), scene.n_samples, len(scene.imus), str(output))


def read_columns(path: Path, names: tuple[str, ...]) -> dict | None:
    """The columns `names` of a `generate` NPZ (rows IMU-fastest, as CSV's), None when it lacks one."""
    with np.load(path) as data:
        n_imu = len(data["imu_names"]) if "imu_names" in data else 1

        def rows(a, per_imu: bool):          # per IMU (n_imu, n[, k]) or shared (n[, k]) -> (n * n_imu, k)
            if per_imu:
                if "imu_names" not in data:
                    a = a[None]                     # a plain log: one IMU, (n, k)
                if a.ndim == 2:
                    a = a[:, :, None]               # (n_imu, n): temperature_c, t_imu
                return a.transpose(1, 0, 2).reshape(-1, a.shape[2])
            return np.repeat(a.reshape(len(a), -1), n_imu, axis=0)

        columns = {}
        if TIME.name in names:
            columns[TIME.name] = (rows(data["t_imu"], True) if "t_imu" in data else rows(data["t"], False))[:, 0]
        for group in Layout(True, True, True, True, True, tuple(g.option for g in COMPANION_GROUPS)).groups():
            wanted = [name for name in group.names if name in names]
            if not wanted:
                continue
            if not all(key in data for key in group.keys):
                return None
            values = np.hstack([rows(data[key], group.per_imu) for key in group.keys])
            columns.update({name: values[:, i] for i, name in enumerate(group.names) if name in wanted})
    return columns if set(names) <= set(columns) else None


def read_conventions(path: Path) -> list[str]:
    with np.load(path) as data:
        return [str(line) for line in data["conventions"]] if "conventions" in data else []


FORMAT = Format("NPZ", (".npz",), NpzWriter, estimated_bytes, order=20, margin=(0.99, 1.01),
                description="an NPZ file", check=check_memory, read_columns=read_columns,
                read_conventions=read_conventions)
