"""This tree's kernels against another revision's (default `main`), interleaved: the full error model and the
kinematics alone, on the circle scene at 1 kHz with a lever arm (tools/bench_effects.py's scene).

    .venv/bin/python tools/bench_against.py [--ref main] [--rounds 9] [--seconds 60]

The other revision is exported with `git archive` into a temporary directory (nothing in a worktree is touched).
Each tree runs in a worker process of its own (both import `imu_emulator`) with its own kernel cache; the parent
asks them in turn for one timed run, so load on the shared machine hits both alike. A run is timed in thread CPU
time (time.thread_time_ns) beside wall time, in two ways:
  - "steady": the run continues the simulation's run-sample count (as a looped stream does), so only the
    kernel and the per-block Python work are timed;
  - "restart": every run starts at sample 0, so the state's reset (the initial draws) is timed too, once per run.
Prints figures; asserts nothing. Compare the ratios: the machine is shared. Per mode it also prints each tree's
full-model cost over its kinematics-only cost (same round), a figure that does not depend on the machine's speed.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
VARIANTS = ("kinematics only", "full error model")
MODES = ("steady", "restart")


def worker(tree: str, seconds: float) -> None:
    """Load `tree`'s package, build the variants, then answer "VARIANT MODE" lines with "cpu_ns wall_ns n"."""
    sys.path.insert(0, tree)
    import imu_emulator   # noqa: F401  (first, so bench_effects' own path insert cannot shadow it)
    from imu_emulator.runtime.simulation import Simulation
    if not imu_emulator.__file__.startswith(tree):
        raise SystemExit(f"error: imported {imu_emulator.__file__}, not the tree {tree}")
    sys.path.insert(1, str(ROOT / "tools"))
    from bench_effects import BLOCK, FULL, circle

    sims = {}
    for label, effects in zip(VARIANTS, ([], FULL)):
        scene = circle(effects, seconds)
        sim = Simulation(scene, attitude=False)
        sims[label] = (sim, sim.block(0, min(BLOCK, scene.n_samples)), scene.n_samples)
    # the run sample each simulation's state is at (the warm-up block's end)
    after = {label: len(out.t_s) for label, (_, out, _) in sims.items()}
    print("ready", flush=True)
    for line in sys.stdin:
        label, mode = line.strip().rsplit(" ", 1)
        sim, out, n = sims[label]
        start = 0 if mode == "restart" else after[label]
        after[label] = start + n
        cpu0, wall0 = time.thread_time_ns(), time.perf_counter_ns()
        for k0 in range(0, n, BLOCK):
            size = min(BLOCK, n - k0)
            sim.block(k0, size, out=out if size == len(out.t_s) else None, run_sample=start + k0)
        print(time.thread_time_ns() - cpu0, time.perf_counter_ns() - wall0, n, flush=True)


def export(ref: str, into: Path) -> Path:
    archive = into / "tree.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(archive), ref], check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(into / "tree", filter="data")
    return into / "tree"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ref", default="main", help="the git revision to compare with")
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--seconds", type=float, default=60.0, help="scene length per timed run (1 kHz)")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        return worker(args.worker, args.seconds)

    with tempfile.TemporaryDirectory(prefix="bench-against-") as tmp:
        trees = {"this tree": str(ROOT), args.ref: str(export(args.ref, Path(tmp)))}
        workers = {}
        for name, tree in trees.items():
            env = dict(os.environ, IMU_EMULATOR_CACHE=str(Path(tmp) / ("cache-" + str(len(workers)))))
            workers[name] = subprocess.Popen(
                [sys.executable, __file__, "--worker", tree, "--seconds", str(args.seconds)],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
        for proc in workers.values():
            if proc.stdout.readline().strip() != "ready":
                raise SystemExit("error: a worker failed to start")
        cpu = {(w, v, m): [] for w in workers for v in VARIANTS for m in MODES}
        wall = {key: [] for key in cpu}
        for _ in range(args.rounds):
            for mode in MODES:
                for variant in VARIANTS:
                    for name, proc in workers.items():
                        proc.stdin.write(f"{variant} {mode}\n")
                        proc.stdin.flush()
                        c, w, n = (int(x) for x in proc.stdout.readline().split())
                        cpu[name, variant, mode].append(c / n)
                        wall[name, variant, mode].append(w / n)
        for proc in workers.values():
            proc.stdin.close()
            proc.wait()

    print(f"circle scene, 1 kHz, lever arm, {args.seconds:g} s per run, {args.rounds} interleaved rounds; "
          "ns/sample in thread CPU min / median / max, wall median; M samples/s from the CPU median")
    for mode in MODES:
        for variant in VARIANTS:
            for name in workers:
                c = np.array(cpu[name, variant, mode])
                print(f"  {mode:8} {variant:18} {name:10} {c.min():7.1f} {np.median(c):7.1f} {c.max():7.1f}   "
                      f"wall {np.median(wall[name, variant, mode]):7.1f}   {1e3 / np.median(c):6.2f} M/s")
            ours, theirs = (np.array(cpu[name, variant, mode]) for name in workers)
            ratios = ours / theirs
            print(f"  {mode:8} {variant:18} ratio this tree / {args.ref}: per-round ratios min {ratios.min():.3f} "
                  f"median {np.median(ratios):.3f} max {ratios.max():.3f}")
        for name in workers:   # the error model's cost in units of the kinematics': independent of the machine's speed
            full, kinematics = (np.array(cpu[name, variant, mode]) for variant in VARIANTS[::-1])
            print(f"  {mode:8} {name:10} full / kinematics only: per-round median {np.median(full / kinematics):.3f}")


if __name__ == "__main__":
    main()
