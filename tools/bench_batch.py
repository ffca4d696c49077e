"""Monte Carlo and long-run figures: realizations per second with 1 and 2 local workers, each worker's kernel load,
and a long `generate` to Parquet (wall time, peak RSS).

    .venv/bin/python tools/bench_batch.py [--runs 32] [--minutes 10] [--repeat 2] [--generate-hours 24]
        [--start-method fork|spawn]

Batch: a one-IMU figure-eight scene with sensor noise and bias instability at 1 kHz; `imu_emulator.analysis.batch.run`
on the CLI's local workers (analysis.batch.LocalBatchPool: a process pool, on Linux forked after this process loaded
the kernel) started before the clock starts. The first trial uses an empty kernel cache (its
kernel load is a compile); the trials alternate 1 and 2 workers so machine load falls on both alike. Wall time,
and the CPU seconds the realizations took on the workers' threads (time.thread_time), are printed per trial.
Generate: four IMUs at 1 kHz for --generate-hours to a Parquet file in --dir (deleted after; a 24 h run needs
about 20 GB there), timed in a child process whose peak RSS comes from os.wait4.
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from imu_emulator.analysis import batch  # noqa: E402

SCENE = """
[scene]
rate_hz = 1000
duration_s = {duration}
[trajectory]      # a car-sized figure eight, heading along the path
shape = "figure8"
length_m = 40.0
width_m = 16.0
frequency_hz = 0.05
[attitude]
mode = "tangent"
{imus}
[effects]
gravity = true
noise = true
bias_instability = true
"""
IMU = """[[imu]]
name = "imu{m}"
gyro = {{ noise_density = "0.01 deg/s/sqrt(Hz)", bias_instability = "3 deg/h" }}
accel = {{ noise_density = "100 ug/sqrt(Hz)" }}
"""


def scene_text(duration_s: float, imus: int) -> str:
    return SCENE.format(duration=duration_s, imus="\n".join(IMU.format(m=m) for m in range(imus)))


def batch_trial(scene: Path, runs: int, workers: int, out: Path, method: str | None) -> dict:
    # the CLI's local workers: on Linux they fork from this process after it loaded the kernel (the trial's
    # "before fork" load; a later trial finds it here), elsewhere each worker loads it ("per worker")
    cluster = batch.LocalBatchPool(workers, warm=batch.tasks_for(scene, runs, 1, out)[0], method=method)
    with cluster as executor:
        executor.submit(os.getpid).result()      # the workers start before the clock (forked: all at the first call)
        start = time.perf_counter()
        result = batch.run(scene, runs, 1, out, executor=executor)
        wall = time.perf_counter() - start
    assert result.ok, result.failures
    loads = [r["kernel_load_s"] for r in result.rows if r["kernel_load_s"] is not None]
    return {"workers": workers, "wall": wall, "rate": runs / wall, "cpu": sum(r["cpu_s"] for r in result.rows),
            "loads": loads, "preload": cluster.preload_s}


def generate_trial(hours: float, directory: Path, cache: str) -> tuple[float, int, int]:
    """Wall seconds, peak RSS (bytes) and file size of `generate` for `hours` of four IMUs at 1 kHz."""
    scene = directory / "long.toml"
    scene.write_text(scene_text(hours * 3600, 4))
    output = directory / "long.parquet"
    env = {**os.environ, "IMU_EMULATOR_CACHE": cache}
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "imu_emulator", "generate", str(scene), "-o", str(output),
                             "--quiet"], env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if status != 0:
        raise SystemExit(f"generate failed with status {status}")
    size = output.stat().st_size
    output.unlink()
    return wall, usage.ru_maxrss * 1024, size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=32)
    parser.add_argument("--minutes", type=float, default=10.0, help="duration of each realization")
    parser.add_argument("--repeat", type=int, default=2, help="trials per worker count (interleaved)")
    parser.add_argument("--start-method", choices=("fork", "spawn"), default=None, help="how the workers start "
                        "(default: the CLI's, fork on Linux); spawn: each worker loads the kernel itself, and all but the first "
                        "start once the clock runs (a pool spawns on demand)")
    parser.add_argument("--generate-hours", type=float, default=24.0, help="0 skips the long generate")
    parser.add_argument("--dir", default=None, help="where the long generate writes (default: a temporary dir)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp:
        tmp = Path(tmp)
        cache = str(tmp / "cache")
        os.environ["IMU_EMULATOR_CACHE"] = cache      # inherited by the workers: an empty cache to start
        print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start")
        if args.runs:
            scene = tmp / "batch.toml"
            scene.write_text(scene_text(args.minutes * 60, 1))
            trials = []
            for r in range(args.repeat):
                for workers in (1, 2):
                    trial = batch_trial(scene, args.runs, workers, tmp / f"out-{r}-{workers}", args.start_method)
                    trials.append(trial)
                    first = "cold cache: compile" if len(trials) == 1 else "warm cache: load"
                    print(f"{args.runs} x {args.minutes:g} min at 1 kHz, {workers} worker(s): {trial['wall']:.1f} s "
                          f"wall, {trial['rate']:.2f} realizations/s, {trial['cpu']:.1f} s worker-thread CPU; "
                          f"kernel ({first}) before fork: "
                          + ("-" if trial["preload"] is None else f"{trial['preload']:.2f} s") + ", per worker: "
                          + (", ".join(f"{s:.2f} s" for s in trial["loads"]) or "-"))
            walls = {w: statistics.median(t["wall"] for t in trials if t["workers"] == w) for w in (1, 2)}
            print(f"median wall: 1 worker {walls[1]:.1f} s, 2 workers {walls[2]:.1f} s; "
                  f"ratio 2/1 = {walls[2] / walls[1]:.2f} (goal <= 0.6)")
        print(f"load average {os.getloadavg()[0]:.1f} after the batches")
        if args.generate_hours:
            directory = Path(args.dir) if args.dir else tmp
            wall, rss, size = generate_trial(args.generate_hours, directory, cache)
            print(f"generate {args.generate_hours:g} h x 1 kHz x 4 IMUs to Parquet: {wall:.0f} s wall (compile "
                  f"included), peak RSS {rss / 2 ** 20:.0f} MiB, file {size / 2 ** 30:.1f} GiB; "
                  f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
