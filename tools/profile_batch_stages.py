"""Where a one-worker batch's CPU goes (issue 25), stage by stage: the same batch (`drone_imu`, --vary of two sensor
parameters, warm kernel cache) run through the Python API in a fresh process per trial, in this process
(`--workers 0`), on the command's process pool (LocalBatchPool) and on a Dask LocalCluster (LocalBatchCluster,
the command's with --dashboard, here without the dashboard), interleaved 0, pool, dask, 0, ... Per stage the
driver's CPU (getrusage RUSAGE_SELF deltas), then the reaped worker's (RUSAGE_CHILDREN) split into the
realizations' own thread CPU (their cpu_s) and the rest (start, event loop, heartbeats, pipes, exit). The first
round only fills the cache and is not shown. Median per stage; prints figures, asserts nothing.

    PYTHONPATH=. python tools/profile_batch_stages.py [--scene examples/drone_imu.toml] [--runs 96] [--rounds 3]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

MODES = ("0", "pool", "dask")


def _cpu(who=resource.RUSAGE_SELF) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


def trial(mode: str, scene: str, runs: int, out: str) -> dict:
    """One batch in this (fresh) process: seconds of CPU per stage."""
    stages = {}
    mark = _cpu()

    def stage(name):
        nonlocal mark
        now = _cpu()
        stages[name] = now - mark
        mark = now
    from imu_emulator import load_scene
    from imu_emulator.analysis import batch
    imu = load_scene(scene).imu_names[0]
    vary = [f"{imu}.gyro.noise_density=uniform(0.001,0.01)", f"{imu}.accel.bias=normal(0,0.05)"]
    tasks = batch.tasks_for(scene, runs, 1, out, vary=vary)
    stage("driver: imports, tasks")
    if mode == "0":
        result = batch.run(scene, runs, 1, out, vary=vary)
        stage("driver: realizations (kernel load included), summary")
    else:
        if mode == "dask":
            import distributed  # noqa: F401
            stage("driver: import distributed")
            local = batch.LocalBatchCluster(1, warm=tasks[0])
        else:
            local = batch.LocalBatchPool(1, warm=tasks[0])
        executor = local.__enter__()
        stage("driver: kernel load, start")
        result = batch.run(scene, runs, 1, out, executor=executor, vary=vary)
        stage("driver: during the run, summary")
        local.__exit__(None, None, None)
        stage("driver: close")
        own = sum(row["cpu_s"] for row in result.rows)
        stages["worker: realizations"] = own
        stages["worker: the rest"] = _cpu(resource.RUSAGE_CHILDREN) - own
    assert result.ok, result.failures
    stages["all"] = _cpu() + _cpu(resource.RUSAGE_CHILDREN)
    return stages


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default=str(ROOT / "examples" / "drone_imu.toml"))
    parser.add_argument("--runs", type=int, default=96)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--trial", nargs=3, metavar=("MODE", "OUT", "RUNS"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.trial:
        mode, out, runs = args.trial
        print(json.dumps(trial(mode, args.scene, int(runs), out)))
        return
    from tools.bench_parametric import machine
    print(machine())
    found: dict[str, list[dict]] = {mode: [] for mode in MODES}
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "IMU_EMULATOR_CACHE": str(Path(tmp) / "cache"), "PYTHONPATH": str(ROOT)}
        for r in range(args.rounds + 1):
            for mode in MODES:
                done = subprocess.run([sys.executable, __file__, "--scene", args.scene, "--trial", mode,
                                       str(Path(tmp) / f"{mode}-{r}"), str(args.runs)],
                                      env=env, capture_output=True, text=True, check=True)
                if r:
                    found[mode].append(json.loads(done.stdout.splitlines()[-1]))
    for mode, trials in found.items():
        print(f"{mode}: median CPU s (min-max) over {len(trials)} trials")
        for name in trials[0]:
            values = [t[name] for t in trials]
            print(f"  {name:56} {statistics.median(values):5.2f} ({min(values):.2f}-{max(values):.2f})")
    alls = {mode: statistics.median(t["all"] for t in trials) for mode, trials in found.items()}
    print(f"all / --workers 0: pool {alls['pool'] / alls['0']:.2f}, dask {alls['dask'] / alls['0']:.2f}")
    print(machine())


if __name__ == "__main__":
    main()
