"""What scale-out costs (issue 25): the `batch` command run with --workers 0 (in its own process), 1 and 2 (its
local workers: a process pool, or a Dask LocalCluster in trees up to 1483ea4), each a fresh process as a user
runs it, in a warm kernel cache. CPU is the whole process
tree's (the command, the scheduler and client in it, its worker processes, reaped before it exits: os.wait4's
rusage), so imports, cluster start-up, event loops and kernel loads all count. Each worker's first kernel load
comes from the summary's kernel_load_s, the load done once in the command before its workers fork from its
final line. With --base DIR (another checkout, e.g. `git worktree add /tmp/base 1483ea4`) both trees run,
interleaved (base 0, 1, 2, this 0, 1, 2, base 0, ...): on a shared machine only ratios inside one run mean
something. --idle instead prints what an idle one-worker Dask cluster (the command's with --dashboard) costs
per second, Dask's defaults against analysis.batch.LOCAL_DASK_CONFIG.

    PYTHONPATH=. python tools/bench_batch_workers.py [--scene examples/drone_imu.toml] [--runs 96] [--rounds 3]
        [--duration S] [--base DIR] [--idle]
"""
from __future__ import annotations

import argparse
import csv
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

WORKERS = (0, 1, 2)


def one(tree: Path, scene: Path, runs: int, workers: int, out: Path, vary: list[str]) -> dict:
    """One `batch` command in a child process: its tree's CPU and wall seconds, kernel loads."""
    command = [sys.executable, "-m", "imu_emulator", "batch", str(scene), "--runs", str(runs), "-o", str(out),
               "--workers", str(workers), "--seed", "1"]
    for v in vary:
        command += ["--vary", v]
    env = {**os.environ, "PYTHONPATH": str(tree)}
    wall = time.perf_counter()
    proc = subprocess.Popen(command, env=env, cwd=tree, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    stderr = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - wall
    if status != 0:
        raise SystemExit(f"{tree}: batch --workers {workers} failed ({status}):\n{stderr}")
    with open(out / "summary.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    shared = re.search(r"kernel loaded in ([0-9.]+) s before the workers forked", stderr)
    return {"cpu": usage.ru_utime + usage.ru_stime, "wall": wall,
            "loads": [float(r["kernel_load_s"]) for r in rows if r["kernel_load_s"] not in ("", None)],
            "shared": float(shared.group(1)) if shared else None,
            "workers": len({r["worker"] for r in rows}), "failed": sum(r["status"] == "failed" for r in rows)}


def _spread(values) -> str:
    return f"{min(values):5.2f}/{statistics.median(values):5.2f}/{max(values):5.2f}"


def compare(args, scene: Path, vary: list[str], tmp: Path) -> None:
    trees = ([("base", Path(args.base).resolve())] if args.base else []) + [("this", ROOT)]
    for name, tree in trees:      # compile into the shared cache (a tree whose kernel source differs compiles its own)
        one(tree, scene, 1, 0, tmp / f"warm-{name}", vary)
    found: dict[tuple[str, int], list[dict]] = {(name, w): [] for name, _ in trees for w in WORKERS}
    for r in range(args.rounds):
        for name, tree in trees:
            for w in WORKERS:
                found[name, w].append(one(tree, scene, args.runs, w, tmp / f"out-{name}-{r}-{w}", vary))
    print("tree  workers  CPU s min/med/max     wall s min/med/max   kernel loads per worker (s)  "
          "load before fork (s)")
    for (name, w), results in found.items():
        loads = [f"{s:.2f}" for x in results for s in x["loads"]]
        shared = [f"{x['shared']:.2f}" for x in results if x["shared"] is not None]
        print(f"{name:5} {w:7}  {_spread([x['cpu'] for x in results])}  {_spread([x['wall'] for x in results])}  "
              f"{' '.join(loads) or '-':28} {' '.join(shared) or '-'}"
              + (f"  FAILED {sum(x['failed'] for x in results)}" if any(x["failed"] for x in results) else ""))

    def med(name, w, what):
        return statistics.median(x[what] for x in found[name, w])
    for name, _ in trees:
        print(f"{name}: CPU 1 worker / --workers 0 = {med(name, 1, 'cpu') / med(name, 0, 'cpu'):.2f} (goal <= 1.15), "
              f"2 workers / --workers 0 = {med(name, 2, 'cpu') / med(name, 0, 'cpu'):.2f}; "
              f"wall 2 workers / 1 = {med(name, 2, 'wall') / med(name, 1, 'wall'):.2f}")
    if args.base:
        print("CPU this / base: " + ", ".join(f"--workers {w} {med('this', w, 'cpu') / med('base', w, 'cpu'):.2f}"
                                              for w in WORKERS))


def _cpu_self() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def idle(seconds: float, rounds: int) -> None:
    """CPU per second of an idle one-worker cluster, Dask's defaults (spawned worker) against ours."""
    from imu_emulator.analysis import batch
    ours = dict(batch.LOCAL_DASK_CONFIG)
    for _ in range(rounds):
        for label, settings in (("Dask defaults", {}), ("LOCAL_DASK_CONFIG", ours)):
            batch.LOCAL_DASK_CONFIG.clear()
            batch.LOCAL_DASK_CONFIG.update(settings)
            with batch.LocalBatchCluster(1) as client:
                client.wait_for_workers(1)
                time.sleep(1.0)      # past start-up
                driver, worker = _cpu_self(), client.run(time.process_time)
                time.sleep(seconds)
                driver, worker = _cpu_self() - driver, [b - a for a, b in zip(worker.values(),
                                                                               client.run(time.process_time).values())]
            print(f"idle {label:17}: driver {driver / seconds * 1e3:5.1f} ms CPU/s, worker "
                  f"{worker[0] / seconds * 1e3:5.1f} ms CPU/s")
    batch.LOCAL_DASK_CONFIG.clear()
    batch.LOCAL_DASK_CONFIG.update(ours)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default=str(ROOT / "examples" / "drone_imu.toml"))
    parser.add_argument("--runs", type=int, default=96)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--duration", type=float, default=None, help="each realization's seconds (default: the "
                        "scene's)")
    parser.add_argument("--base", default=None, help="another checkout to compare with, interleaved")
    parser.add_argument("--idle", action="store_true", help="only the idle cluster's CPU per second")
    args = parser.parse_args()
    from imu_emulator import load_scene
    from tools.bench_parametric import machine
    print(machine())
    if args.idle:
        idle(5.0, args.rounds)
        print(machine())
        return
    imu = load_scene(args.scene).imu_names[0]
    vary = [f"{imu}.gyro.noise_density=uniform(0.001,0.01)", f"{imu}.accel.bias=normal(0,0.05)"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        scene = Path(args.scene).resolve()
        if args.duration is not None:     # a copy (a scene with relative data paths: use it as it is)
            text = re.sub(r"(?m)^duration_s\s*=.*$", f"duration_s = {args.duration!r}", scene.read_text())
            scene = tmp / scene.name
            scene.write_text(text)
        os.environ["IMU_EMULATOR_CACHE"] = str(tmp / "cache")
        print(f"scene {args.scene}{'' if args.duration is None else f' ({args.duration:g} s)'}, {args.runs} "
              f"realizations, --vary {' --vary '.join(vary)}; CPU of the whole process tree")
        compare(args, scene, vary, tmp)
    print(machine())


if __name__ == "__main__":
    main()
