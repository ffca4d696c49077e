"""CPU time of each companion sensor's numpy model per IMU sample (imu_emulator.companions), on synthetic truth: a
vehicle at 30 m/s (a new magnetic-field cell every ~0.4 s), an IMU at 1 kHz, blocks of 4096 samples (as `generate`'s
blocks are, smaller than its default). The sensors run interleaved, round by round, so load on the machine hits
them alike; figures are process CPU time (time.process_time), with the CPU and load named.

    .venv/bin/python tools/bench_companions.py [--rounds 5] [--samples 200000]
"""
from __future__ import annotations

import argparse
import os
import platform
import time
from types import SimpleNamespace

import numpy as np

from imu_emulator.companions import COMPANIONS, Truth
from imu_emulator.companions.gnss import offset_llh
from imu_emulator.scene.companions import companion_specs

KEYS = {"magnetometer": {"rate_hz": 100, "noise_density": 1e-4}, "barometer": {"rate_hz": 50, "noise": 1.0},
        "gnss": {"rate_hz": 10, "position_noise": 0.3, "position_markov": 1.0, "latency_s": 0.05},
        "ins": {"attitude_error": 0.01, "position_error": 1.0, "velocity_error": 0.05}}
IMU_VALUES = {"imu.temperature_c": "25.0", "imu.warmup_rise_c": 0.0, "imu.warmup_tau_s": 600.0,
              "imu.temperature_ref_c": 25.0}


def truth(s: np.ndarray, rate: float) -> Truth:
    n = len(s)
    llh = offset_llh(np.tile([47.4, 8.5, 500.0], (n, 1)), np.column_stack([30.0 * s / rate, 0 * s, 0 * s]))
    return Truth(s=s, t=s / rate, rate_hz=rate, llh=llh, v_ned=np.tile([30.0, 0, 0], (n, 1)),
                 c_ns=np.tile(np.eye(3), (n, 1, 1)), c_nb=np.tile(np.eye(3), (n, 1, 1)), omega_b=np.zeros((n, 3)),
                 values=IMU_VALUES)


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            return next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        return platform.processor() or platform.machine()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--samples", type=int, default=200_000)
    args = parser.parse_args()
    rate, block = 1000.0, 4096
    scene = SimpleNamespace(seed=1, t0_s=0.0, rate_hz=rate)
    values = companion_specs(KEYS, "bench")
    blocks = [truth(np.arange(k, min(k + block, args.samples)), rate) for k in range(0, args.samples, block)]
    cpu = {name: [] for name in COMPANIONS}
    for _ in range(args.rounds):
        for name in COMPANIONS:      # interleaved: every sensor once per round
            runner = COMPANIONS[name].start(scene, 0, values[name])
            start = time.process_time()
            for t in blocks:
                runner.block(t)
            cpu[name].append(time.process_time() - start)
    print(f"CPU {_cpu()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}; "
          f"{args.samples} samples at {rate:g} Hz in blocks of {block}, {args.rounds} rounds")
    for name, times in cpu.items():
        per = np.array(times) / args.samples * 1e9
        print(f"  {name:13} median {np.median(per):7.0f} ns/sample CPU (min {per.min():.0f}, max {per.max():.0f})")


if __name__ == "__main__":
    main()
