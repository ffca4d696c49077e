"""What scale-out costs (issue 25): one batch run with --workers 0 (this process), on one local Dask worker
process and on two, in a warm kernel cache; CPU time of everything (this process, the scheduler in it, and the
worker and nanny processes, counted when they are reaped: resource.getrusage(RUSAGE_CHILDREN)), wall time, and
each worker's first kernel load (the summary's kernel_load_s). The variants alternate (0, 1, 2, 0, 1, 2, ...):
on a shared machine only ratios inside one run mean something.

    PYTHONPATH=. python tools/bench_batch_workers.py [--scene examples/drone_imu.toml] [--runs 32] [--rounds 2]
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def one(scene: str, runs: int, workers: int, out: Path, vary: list[str]) -> dict:
    from imu_emulator.analysis import batch
    batch.KERNEL_LOADS.clear()
    cpu, children, wall = time.process_time(), _children_cpu(), time.perf_counter()
    if workers == 0:     # as a fresh worker would: the kernel loaded from the cache, not kept from a round before
        from imu_emulator.runtime import kernels
        kernels._loaded.clear()
        result = batch.run(scene, runs, 1, out, executor=None, vary=vary)
    else:
        from distributed import Client, LocalCluster
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                Client(cluster) as client:
            client.wait_for_workers(workers)
            result = batch.run(scene, runs, 1, out, executor=client, vary=vary)
    wall = time.perf_counter() - wall
    cpu = (time.process_time() - cpu) + (_children_cpu() - children)
    loads = [r["kernel_load_s"] for r in result.rows if r["kernel_load_s"] is not None]
    return {"wall": wall, "cpu": cpu, "loads": loads, "failed": len(result.failures),
            "workers": len({r["worker"] for r in result.rows})}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default=str(ROOT / "examples" / "drone_imu.toml"))
    parser.add_argument("--runs", type=int, default=32)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    from tools.bench_parametric import machine
    from imu_emulator import load_scene
    imu = load_scene(args.scene).imu_names[0]
    vary = [f"{imu}.gyro.noise_density=uniform(0.001,0.01)", f"{imu}.accel.bias=normal(0,0.05)"]
    print(machine())
    print(f"scene {args.scene}, {args.runs} realizations, --vary {' --vary '.join(vary)}")
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["IMU_EMULATOR_CACHE"] = str(Path(tmp) / "cache")
        warm = one(args.scene, 1, 0, Path(tmp) / "warm", vary)     # compiles into the cache
        print(f"warm-up (compile): {warm['wall']:.1f} s wall")
        found: dict[int, list[dict]] = {0: [], 1: [], 2: []}
        for r in range(args.rounds):
            for workers in found:
                found[workers].append(one(args.scene, args.runs, workers, Path(tmp) / f"out-{r}-{workers}", vary))
        for workers, results in found.items():
            cpu = statistics.median(x["cpu"] for x in results)
            wall = statistics.median(x["wall"] for x in results)
            loads = [s for x in results for s in x["loads"]]
            print(f"--workers {workers}: {wall:6.1f} s wall, {cpu:6.1f} s CPU (medians of {len(results)}); "
                  f"kernel loads per run {[len(x['loads']) for x in results]}, load s "
                  f"{', '.join(f'{s:.2f}' for s in loads) or '-'}; failed {sum(x['failed'] for x in results)}")
        base_cpu = statistics.median(x["cpu"] for x in found[0])
        print(f"CPU: 1 Dask worker / --workers 0 = {statistics.median(x['cpu'] for x in found[1]) / base_cpu:.2f}; "
              f"wall: 2 workers / 1 worker = "
              f"{statistics.median(x['wall'] for x in found[2]) / statistics.median(x['wall'] for x in found[1]):.2f}")
    print(machine())


if __name__ == "__main__":
    main()
