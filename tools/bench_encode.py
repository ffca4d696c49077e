"""Encoding speed of every registered wire format: batch (packets/s over N samples) and single sample.

    .venv/bin/python tools/bench_encode.py [--samples 3600000] [--formats mavlink-highres,dronecan-rawimu]

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--samples", type=int, default=3_600_000)
    parser.add_argument("--formats", default="", help="comma-separated names (default: all)")
    parser.add_argument("--single-repeat", type=int, default=20000)
    args = parser.parse_args()

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
