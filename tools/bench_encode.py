"""Encoding speed of every registered wire format: batch (packets/s over N samples) and single sample.

    .venv/bin/python tools/bench_encode.py [--samples 3600000] [--formats mavlink-highres,dronecan-rawimu]
    .venv/bin/python tools/bench_encode.py --per-sample [--formats ...]

--per-sample: one sample at a time as devices encode (a view of row i of a block, firmware_protocols.devices.base
.single), the encoders' functions run as machine code (imu_emulator.native.lazy) and through numba's dispatcher,
interleaved in one process: thread CPU and wall time per sample, min/median of 7 rounds of 1000 samples each.

Prints figures; asserts nothing. Samples are random but in range, with every optional field given.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import firmware_protocols as fp  # noqa: E402


def make_samples(n: int, rng) -> fp.Samples:
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    return fp.Samples(
        time_ns=np.arange(n, dtype=np.int64) * 1_000_000 + 1_234_567_000,
        accel=rng.uniform(-20, 20, (n, 3)), gyro=rng.uniform(-5, 5, (n, 3)), mag=rng.uniform(-0.6, 0.6, (n, 3)),
        quat=q, euler=rng.uniform(-1.5, 1.5, (n, 3)), temperature_c=rng.uniform(-10, 60, n),
        pressure_pa=rng.uniform(9e4, 1.05e5, n), delta_theta=rng.uniform(-0.01, 0.01, (n, 3)),
        delta_velocity=rng.uniform(-0.05, 0.05, (n, 3)))


def count(result) -> tuple[int, str]:
    if isinstance(result, fp.SerialBatch):
        return len(result.data), "bytes"
    return len(result), "frames"


def per_sample(names: list[str], rounds: int = 7, per_round: int = 1000) -> None:
    import statistics
    from firmware_protocols.devices.base import single
    from imu_emulator.native import lazy
    block = make_samples(per_round, np.random.default_rng(1))
    print(f"{'format':24s} {'path':13s} {'CPU µs/sample':>20s} {'wall µs/sample':>20s}   (min/median)")
    for name in names:
        encoder = fp.create_encoder(name)
        times = {True: [], False: []}
        for native in (True, False):      # compile or load both first
            lazy.NATIVE = native
            encoder.encode(single(block, 0))
        for _ in range(rounds):
            for native in (True, False):
                lazy.NATIVE = native
                cpu, wall = time.thread_time_ns(), time.perf_counter_ns()
                for i in range(per_round):
                    encoder.encode(single(block, i))
                times[native].append(((time.thread_time_ns() - cpu) / per_round / 1e3,
                                      (time.perf_counter_ns() - wall) / per_round / 1e3))
        for native in (True, False):
            cpu = [c for c, _ in times[native]]
            wall = [w for _, w in times[native]]
            path = "machine code" if native else "numba"
            print(f"{name:24s} {path:13s} {min(cpu):9.1f}/{statistics.median(cpu):<9.1f}"
                  f" {min(wall):9.1f}/{statistics.median(wall):<9.1f}")
    lazy.NATIVE = True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--samples", type=int, default=3_600_000)
    parser.add_argument("--formats", default="", help="comma-separated names (default: all)")
    parser.add_argument("--single-repeat", type=int, default=20000)
    parser.add_argument("--per-sample", action="store_true", help="machine code against numba, one sample at a time")
    args = parser.parse_args()
    if args.per_sample:
        per_sample([n for n in args.formats.split(",") if n] or list(fp.formats()))
        return

    rng = np.random.default_rng(1)
    big = make_samples(args.samples, rng)
    one = big.slice(0, 1)
    names = [n for n in args.formats.split(",") if n] or list(fp.formats())
    print(f"{'format':24s} {'kind':6s} {'batch packets/s':>16s} {'output':>16s} {'single sample':>14s}")
    for name in names:
        encoder = fp.create_encoder(name)
        encoder.encode(big.slice(0, 1000))            # compile / warm up
        start = time.perf_counter()
        result = encoder.encode(big)
        elapsed = time.perf_counter() - start
        size, unit = count(result)
        encoder.encode(one)
        singles = []
        for _ in range(5):
            start = time.perf_counter()
            for _ in range(args.single_repeat // 5):
                encoder.encode(one)
            singles.append((time.perf_counter() - start) / (args.single_repeat // 5))
        print(f"{name:24s} {fp.get(name).kind:6s} {args.samples / elapsed / 1e6:13.2f} M/s "
              f"{size / elapsed / 1e6:9.1f} M{unit}/s {min(singles) * 1e6:11.2f} µs")


if __name__ == "__main__":
    main()
