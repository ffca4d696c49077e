"""CSV formatting speed: the writer's csv_rows (orjson's digits, rows put together in numba; shortest round-trip)
against the pyarrow CSV writer it replaced (also shortest round-trip) and, with --percent-17g, the former
np.char.mod("%.17g") formatting, interleaved on the same blocks of a real scene. Prints rows/s (wall and thread
CPU time, min/median/max over repeats) and the bytes a row; asserts nothing.

    .venv/bin/python tools/bench_output.py [--scene examples/two_imus.toml] [--block 65536] [--repeats 7] [--truth]
        [--increments] [--percent-17g]
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from imu_emulator.output.csv_text import RowWriter
from imu_emulator.output.formats.csv import _csv_text, _pyarrow_csv_rows
from imu_emulator.scene.load import load_scene
from imu_emulator.runtime.simulation import Simulation


def percent_17g_rows(block, imu_names, truth, increments=False) -> str:
    """The formatting output.py used before: every number through %.17g in numpy, rows joined in Python."""
    extra = []
    if truth:
        tr = block.truth
        extra = [tr["position"], tr["velocity"], tr["euler"], tr["omega_body"]]
    per_imu = []
    for m, name in enumerate(imu_names):
        numeric = np.column_stack([block.t_s, block.accel[m], block.gyro[m], *extra])
        text = np.char.mod("%.17g", numeric).tolist()
        per_imu.append([",".join((r[0], name, *r[1:])) for r in text])
    return "\n".join(row for rows in zip(*per_imu) for row in rows) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="examples/two_imus.toml")
    parser.add_argument("--block", type=int, default=65536)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--truth", action="store_true")
    parser.add_argument("--increments", action="store_true")
    parser.add_argument("--percent-17g", action="store_true", help="also time the former %%.17g formatting (slow)")
    args = parser.parse_args()
    scene = load_scene(args.scene)
    sim = Simulation(scene, attitude=False, truth=args.truth, increments=4 if args.increments else 0)
    block = sim.block(0, min(args.block, scene.n_samples))
    rows = len(block) * len(scene.imus)
    row_writer = RowWriter(scene.imu_names)

    def writer_rows(block, imu_names, truth, increments=False):     # what output.Writer does with each block
        return _csv_text(row_writer, block, imu_names, truth, False, False, increments, False)

    variants = {"csv_rows (orjson+numba)": writer_rows, "pyarrow CSV writer": _pyarrow_csv_rows}
    if args.percent_17g:
        if args.increments:
            parser.error("--percent-17g has no increments columns")
        variants["%.17g np.char.mod"] = percent_17g_rows
    sizes = {name: len(fn(block, scene.imu_names, args.truth, increments=args.increments))   # warm: compiled
             for name, fn in variants.items()}
    wall = {name: [] for name in variants}
    cpu = {name: [] for name in variants}
    proc = {name: [] for name in variants}   # all threads: pyarrow could format on helper threads
    for _ in range(args.repeats):
        for name, fn in variants.items():          # interleaved: A, B, A, B, ... (the machine is shared)
            w0, c0, p0 = time.perf_counter_ns(), time.thread_time_ns(), time.process_time_ns()
            fn(block, scene.imu_names, args.truth, increments=args.increments)
            cpu[name].append(time.thread_time_ns() - c0)
            proc[name].append(time.process_time_ns() - p0)
            wall[name].append(time.perf_counter_ns() - w0)
    print(f"{args.scene}: {rows} rows per block ({len(scene.imus)} IMU(s), truth={args.truth}, "
          f"increments={args.increments}), {args.repeats} repeats")
    for name in variants:
        def rate(ns_list):
            return [rows / (ns / 1e9) / 1e6 for ns in ns_list]
        w, c, pr = rate(wall[name]), rate(cpu[name]), rate(proc[name])
        print(f"  {name:24} {sizes[name] / rows:.0f} bytes/row; M rows/s  wall min/med/max {min(w):.2f}/{statistics.median(w):.2f}/{max(w):.2f}"
              f"   thread CPU {min(c):.2f}/{statistics.median(c):.2f}/{max(c):.2f}"
              f"   process CPU {min(pr):.2f}/{statistics.median(pr):.2f}/{max(pr):.2f}")
    for name in list(variants)[1:]:
        ratios = [o / n for o, n in zip(cpu[name], cpu["csv_rows (orjson+numba)"])]
        print(f"  csv_rows / {name}: {statistics.median(ratios):.1f}x faster (median of per-repeat thread CPU ratios)")


if __name__ == "__main__":
    main()
