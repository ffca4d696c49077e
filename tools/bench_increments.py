"""Cost of the integrated outputs (dtheta, dvel; imu_emulator.codegen.increments) per sample, by number of
Gauss-Legendre nodes, on the circle scene at 1 kHz with a lever arm (tangent attitude), bare and with the full
error model of tools/bench_effects.py.

    .venv/bin/python tools/bench_increments.py [--rounds 7] [--seconds 20]

Variants are interleaved (A, B, C, A, B, C, ...) and timed in thread CPU time (time.thread_time_ns) beside
wall time, because the machine is shared: compare the ratios, not one run's absolute figures. Prints figures;
asserts nothing.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from bench_effects import BLOCK, FULL, circle, time_run  # noqa: E402

from imu_emulator.codegen.increments import DEFAULT_NODES  # noqa: E402
from imu_emulator.runtime.simulation import Simulation  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--seconds", type=float, default=20.0, help="scene length per timed run (1 kHz)")
    args = parser.parse_args()

    variants = []
    for effects, name in (([], "kinematics"), (FULL, "full error model")):
        for nodes in (0, 2, 3, DEFAULT_NODES, 6):
            label = f"{name}, " + (f"increments {nodes} nodes" if nodes else "no increments")
            variants.append((label, effects, nodes))
    sims = []
    for label, effects, nodes in variants:
        scene = circle(effects, args.seconds)
        sim = Simulation(scene, attitude=False, increments=nodes)
        out = sim.block(0, BLOCK)
        sims.append((label, sim, out, scene.n_samples, nodes))
    cpu = {label: [] for label, *_ in sims}
    wall = {label: [] for label, *_ in sims}
    for _ in range(args.rounds):
        for label, sim, out, n, _ in sims:
            c, w = time_run(sim, n, out)
            cpu[label].append(c / n)
            wall[label].append(w / n)
    print(f"circle scene, 1 kHz, lever arm, {args.seconds:g} s per run, {args.rounds} interleaved rounds "
          f"(ns/sample; thread CPU min / median / max, wall median; cost over the same scene without increments)")
    base = None
    for label, *_, nodes in sims:
        c = np.array(cpu[label])
        if nodes == 0:
            base = np.median(c)
        extra = np.median(c) - base
        print(f"  {label:44} {c.min():7.1f} {np.median(c):7.1f} {c.max():7.1f}   wall {np.median(wall[label]):7.1f}"
              f"   increments {extra:+7.1f}" + (f" ({extra / nodes:.1f}/node)" if nodes else ""))


if __name__ == "__main__":
    main()
