"""A run's size, estimated before it starts, so that what cannot fit is refused with the figure instead of
ending in MemoryError (or a full disk) hours later.

In memory: an NPZ output and the Python API's `simulate()` hold every sample (t, accel, gyro per IMU, quat per
IMU, truth); a CSV streams block by block and needs disk instead. Available memory is the kernel's
MemAvailable; free disk is that of the output's directory.

`output_bytes` is each format's file size for `check` and the checks here, from the columns the writers emit
(increments, temperature, realized biases, truth and Earth truth included):
- NPZ: the arrays' bytes plus NPZ_ARRAY_OVERHEAD per array: exact to within that overhead.
- CSV: CSV_CHARS_PER_NUMBER characters a number, an estimate (shortest round-trip text is 16-17 significant
  digits for most measured doubles, fewer for round ones): tests/test_output_earth_formats.py holds it within
  CSV_ESTIMATE_MARGIN of an Earth run with noise; runs of round numbers come out smaller (two_imus.toml,
  noise-free: 0.72-0.99 of it). `csv_bytes`, every number at its longest, is the bound the disk check uses.
- Parquet and MCAP: the uncompressed bytes of every value (Parquet: 8 a number, 4 for the IMU's dictionary
  index; MCAP: the CDR messages, their records and index entries). The files are compressed (Snappy, zstd)
  and come out smaller, 0.1-0.7 of it, except a short Parquet file of noisy numbers, whose dictionary pages
  can add up to about 6 % (the test allows 25 %).
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from imu_emulator.errors import ImuEmulatorError

# "%.17g" of a double is at most 24 characters (sign, 17 digits, point, "e-308"), plus its comma.
CSV_BYTES_PER_VALUE = 25
TRUTH_VALUES = 15          # position, velocity, euler, omega, alpha (3 each)
# a number's typical text: 16-17 significant digits and the point for measured values, a few short ones
# (0.0, constant temperatures, round time stamps) between them; plus its comma
CSV_CHARS_PER_NUMBER = 18
CSV_ESTIMATE_MARGIN = 0.2
NPZ_ARRAY_OVERHEAD = 272   # .npy header (128), the zip entry's local and central headers with zip64 extras and the
                           # name twice: measured 247-251 a array with names of 1-18 characters


class RunSizeError(ImuEmulatorError):
    """The run would not fit in memory or on disk."""


def memory_bytes(n_samples: int, n_imus: int, quat: bool, truth: bool, *, increments: bool = False,
                 temperature: bool = False, earth_truth: bool = False, bias_truth: bool = False) -> int:
    """Bytes of the arrays that hold a whole run (float64; Simulation.run's): t, accel and gyro, and per IMU
    quat, dtheta and dvel, temperature, realized biases (truth); the truth's own columns and the Earth truth."""
    per_imu = 6 + 4 * quat + 6 * increments + temperature + 6 * (truth and bias_truth)
    shared = TRUTH_VALUES if truth else 0
    if truth and earth_truth:    # earth_truth (frames, rotations) imported only for scenes on the Earth
        from imu_emulator.motion.earth_truth import KEYS
        shared += 3 * len(KEYS)
    return 8 * n_samples * (1 + n_imus * per_imu + shared)


def csv_bytes(scene, truth: bool, increments: bool = False) -> int:
    """Upper bound on a CSV's size: one row per sample per IMU, every number at its longest."""
    return _csv_size(scene, truth, increments, CSV_BYTES_PER_VALUE - 1)


def _csv_size(scene, truth: bool, increments: bool, chars_per_number: int) -> int:
    per_imu, shared = row_numbers(scene, truth, increments)
    names = sum(len(name.encode()) + 1 for name in scene.imu_names)             # and its comma
    return scene.n_samples * (len(scene.imus) * (1 + per_imu + shared) * (chars_per_number + 1) + names)


def row_numbers(scene, truth: bool, increments: bool) -> tuple[int, int]:
    """The numbers of a CSV/Parquet row besides its time: (per IMU, shared by the IMUs of a sample)."""
    from imu_emulator.motion.earth import model_on
    from imu_emulator.codegen.plan import EffectPlan
    from imu_emulator.output.writer import BIAS_COLUMNS, INCREMENT_COLUMNS, TRUTH_COLUMNS
    per_imu = 6 + (len(INCREMENT_COLUMNS) if increments else 0) + ("temperature" in scene.effects)
    per_imu += len(BIAS_COLUMNS) if truth and EffectPlan(scene).bias_truth else 0
    shared = 0
    if truth:
        shared += len(TRUTH_COLUMNS)
        if model_on(scene):      # earth_truth (frames, rotations) imported only for scenes on the Earth
            from imu_emulator.motion.earth_truth import KEYS
            shared += 3 * len(KEYS)
    return per_imu, shared


def output_bytes(scene, fmt: str, truth: bool, increments: bool = False) -> int:
    """The size of `generate`'s output in format fmt ("NPZ", "CSV", "Parquet", "MCAP"): see the module's
    docstring for how close each is."""
    n, n_imu = scene.n_samples, len(scene.imus)
    per_imu, shared = row_numbers(scene, truth, increments)
    if fmt == "NPZ":
        return _npz_bytes(scene, truth, increments)
    rows = n * n_imu
    if fmt == "CSV":
        return _csv_size(scene, truth, increments, CSV_CHARS_PER_NUMBER)
    if fmt == "Parquet":
        return rows * (8 * (1 + per_imu + shared) + 4)
    if fmt == "MCAP":
        return n * sum(_MCAP_RECORD + _imu_cdr_bytes(name) for name in scene.imu_names) + (
            n * (_MCAP_RECORD + _ODOMETRY_CDR) if truth else 0) + (
            n * (2 * _MCAP_RECORD + _ODOMETRY_ECEF_CDR + _NAVSATFIX_CDR) if truth and shared > 12 else 0)
    raise ValueError(fmt)


def _npz_bytes(scene, truth: bool, increments: bool) -> int:
    """output.Writer._save_npz's arrays: (count of numbers per sample, arrays) summed, as float64."""
    from imu_emulator.motion.earth import model_on
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
    if truth:
        parts.append((3 * len(TRUTH_KEYS), len(TRUTH_KEYS)))
        if EffectPlan(scene).bias_truth:
            parts.append((6 * n_imu, 2))
        if model_on(scene):
            from imu_emulator.motion import earth_truth
            parts.append((3 * len(earth_truth.KEYS), len(earth_truth.KEYS)))
            lines = earth_truth.conventions(scene)
            text += 4 * max(len(line) for line in lines) * len(lines)
    arrays = 1 + sum(count for _, count in parts) + (truth and model_on(scene))
    return 8 * n * sum(numbers for numbers, _ in parts) + text + NPZ_ARRAY_OVERHEAD * arrays


# MCAP: a message record (opcode 1 + length 8 + channel 2 + sequence 4 + log and publish time 16) and its
# message index entry (time 8 + offset 8); CDR: a 4-byte encapsulation header, strings as a uint32 length,
# the bytes and a NUL, doubles aligned to 8 from the header's end.
_MCAP_RECORD = 31 + 16


def _cdr_string_end(at: int, text: str) -> int:
    return at + 4 + len(text.encode()) + 1


def _align8(at: int) -> int:
    return -(-at // 8) * 8


def _imu_cdr_bytes(name: str) -> int:
    from imu_emulator.output.mcap import ros_name
    end = _cdr_string_end(8, ros_name(name))               # stamp, then frame_id
    return 4 + _align8(end) + 8 * (4 + 9 + 3 + 9 + 3 + 9)


_ODOMETRY_CDR = 4 + _align8(_cdr_string_end(_cdr_string_end(8, "world"), "base_link")) + 8 * (7 + 36 + 6 + 36)
_ODOMETRY_ECEF_CDR = 4 + _align8(_cdr_string_end(_cdr_string_end(8, "earth"), "base_link_frd")) + 8 * (7 + 36 + 6 + 36)
_NAVSATFIX_CDR = 4 + _align8(_cdr_string_end(8, "earth") + 1 + 2) + 8 * (3 + 9) + 1


def available_memory() -> int | None:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _gib(n: float) -> str:
    return f"{n / 2 ** 30:.3g} GiB"


def check_memory(n_samples: int, n_imus: int, quat: bool, truth: bool, what: str, **columns) -> None:
    """RunSizeError when holding the whole run would take more than the memory available now (`columns`: the
    optional groups memory_bytes counts)."""
    _check_fits(memory_bytes(n_samples, n_imus, quat, truth, **columns), n_samples, n_imus, what)


def _check_fits(need: int, n_samples: int, n_imus: int, what: str) -> None:
    have = available_memory()
    if have is not None and need > have:
        raise RunSizeError(f"{what}: {n_samples} samples x {n_imus} IMU(s) take {_gib(need)} in memory, "
                           f"{_gib(have)} are available; write a .csv (it streams to disk), or shorten "
                           "scene.duration_s or lower scene.rate_hz")


def check_output(scene, output: str | Path, truth: bool, allow_large: bool = False, increments: bool = False) -> None:
    """Before `generate` runs: an NPZ must fit in memory (twice: the blocks, then the joined arrays); a CSV
    must fit on the disk of its directory unless `allow_large` (the estimate is an upper bound)."""
    output = Path(output)
    n = scene.n_samples
    if output.suffix.lower() == ".npz":
        _check_fits(2 * output_bytes(scene, "NPZ", truth, increments), n, len(scene.imus), str(output))
        return
    if output.suffix.lower() != ".csv":
        return    # Parquet and MCAP stream and are compressed: output_bytes is a loose bound there
    need = csv_bytes(scene, truth, increments)
    usage = shutil.disk_usage(output.parent if str(output.parent) else Path(os.curdir))
    free = usage.free
    # total 0: a pseudo file system (/proc, /dev) that reports no sizes; the writer's own errors speak there
    if usage.total and need > free and not allow_large:
        raise RunSizeError(f"{output}: {n} samples x {len(scene.imus)} IMU(s) make up to {_gib(need)} of CSV, "
                           f"{_gib(free)} are free there; shorten scene.duration_s or lower scene.rate_hz, "
                           "or pass --allow-large if you know it fits")
