"""What the companions' new-reading flags (Samples.mag_new, baro_new) cost the encoders that follow them.

    .venv/bin/python tools/bench_new_readings.py [--rounds 7] [--per-round 1000] [--block 100000]

For mavlink-hil-sensor (fields_updated bits), mavlink-scaled-pressure, dronecan-gnss-compass-baro and
dronecan-static-pressure (messages only
on new readings): the same samples encoded without flags (every sample new, the behaviour without a companion)
and with a 100 Hz magnetometer's and a 50 Hz barometer's flags on a 400 Hz IMU, interleaved round by round in
one process. One sample at a time as devices encode (firmware_protocols.devices.base.single), and a whole block
as file and pty streams do. Process CPU per sample, min/median over the rounds. Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import firmware_protocols as fp  # noqa: E402
from firmware_protocols.devices.base import single  # noqa: E402
from tools.bench_encode import make_samples  # noqa: E402

FORMATS = ("mavlink-hil-sensor", "mavlink-scaled-pressure", "dronecan-gnss-compass-baro", "dronecan-static-pressure")


def flagged(block: fp.Samples) -> fp.Samples:
    k = np.arange(len(block))
    out = block.slice(0, len(block))
    out.mag_new, out.baro_new = (k % 4 == 0).astype(float), (k % 8 == 0).astype(float)   # 100 / 50 Hz of 400 Hz
    return out


def per_sample_us(encoder, block: fp.Samples) -> float:
    cpu = time.process_time_ns()
    for i in range(len(block)):
        encoder.encode(single(block, i))
    return (time.process_time_ns() - cpu) / len(block) / 1e3


def block_us(encoder, block: fp.Samples) -> float:
    cpu = time.process_time_ns()
    encoder.encode(block)
    return (time.process_time_ns() - cpu) / len(block) / 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--per-round", type=int, default=1000)
    parser.add_argument("--block", type=int, default=100_000)
    args = parser.parse_args()
    rng = np.random.default_rng(1)
    small = make_samples(args.per_round, rng)
    small.differential_pressure_pa = rng.uniform(0, 500, args.per_round)
    big = make_samples(args.block, rng)
    variants = {"no flags": (small, big), "flags": (flagged(small), flagged(big))}
    print(f"{'format':28s} {'variant':9s} {'per sample µs CPU':>20s} {'block µs CPU/sample':>22s}  (min/median)")
    for name in FORMATS:
        times = {v: ([], []) for v in variants}
        encoders = {v: fp.create_encoder(name) for v in variants}
        for v, (one, many) in variants.items():       # warm: compile or load the machine code first
            encoders[v].encode(single(one, 0))
            encoders[v].encode(many.slice(0, 10))
        for _ in range(args.rounds):
            for v, (one, many) in variants.items():
                times[v][0].append(per_sample_us(encoders[v], one))
                times[v][1].append(block_us(encoders[v], many))
        for v in variants:
            single_t, block_t = times[v]
            print(f"{name:28s} {v:9s} {min(single_t):9.2f}/{statistics.median(single_t):<9.2f}"
                  f" {min(block_t):11.3f}/{statistics.median(block_t):<9.3f}")
        ratio = [f / n for f, n in zip(times["flags"][0], times["no flags"][0])]
        print(f"{'':28s} flags / no flags per sample: min {min(ratio):.2f}, median {statistics.median(ratio):.2f}")


if __name__ == "__main__":
    main()
