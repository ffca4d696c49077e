"""CSV formatting speed: the writer's csv_rows (pyarrow, shortest round-trip) against the former
np.char.mod("%.17g") formatting, interleaved on the same blocks of a real scene. Prints rows/s (wall and thread
CPU time, min/median/max over repeats); asserts nothing.

    .venv/bin/python tools/bench_output.py [--scene examples/two_imus.toml] [--block 65536] [--repeats 7] [--truth]
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from imu_emulator.output import csv_rows
from imu_emulator.scene import load_scene
from imu_emulator.simulation import Simulation


def percent_17g_rows(block, imu_names, truth) -> str:
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
    args = parser.parse_args()
    scene = load_scene(args.scene)
    sim = Simulation(scene, attitude=False, truth=args.truth)
    block = sim.block(0, min(args.block, scene.n_samples))
    rows = len(block) * len(scene.imus)
    variants = {"pyarrow csv_rows": csv_rows, "%.17g np.char.mod": percent_17g_rows}
    wall = {name: [] for name in variants}
    cpu = {name: [] for name in variants}
    proc = {name: [] for name in variants}   # all threads: pyarrow could format on helper threads
    for _ in range(args.repeats):
        for name, fn in variants.items():          # interleaved: A, B, A, B, ... (the machine is shared)
            w0, c0, p0 = time.perf_counter_ns(), time.thread_time_ns(), time.process_time_ns()
            text = fn(block, scene.imu_names, args.truth)
            cpu[name].append(time.thread_time_ns() - c0)
            proc[name].append(time.process_time_ns() - p0)
            wall[name].append(time.perf_counter_ns() - w0)
            size = len(text)
    print(f"{args.scene}: {rows} rows per block ({len(scene.imus)} IMU(s), truth={args.truth}), "
          f"{size / rows:.0f} bytes/row, {args.repeats} repeats")
    for name in variants:
        def rate(ns_list):
            return [rows / (ns / 1e9) / 1e6 for ns in ns_list]
        w, c, pr = rate(wall[name]), rate(cpu[name]), rate(proc[name])
        print(f"  {name:20} M rows/s  wall min/med/max {min(w):.2f}/{statistics.median(w):.2f}/{max(w):.2f}"
              f"   thread CPU {min(c):.2f}/{statistics.median(c):.2f}/{max(c):.2f}"
              f"   process CPU {min(pr):.2f}/{statistics.median(pr):.2f}/{max(pr):.2f}")
    ratio = statistics.median(wall["%.17g np.char.mod"]) / statistics.median(wall["pyarrow csv_rows"])
    print(f"  speed-up (median wall): {ratio:.1f}x")


if __name__ == "__main__":
    main()
