"""Benchmark: what one VectorNav binary packet costs to encode for a single sample, as the device does it just
before each sample's deadline, for the layouts the drivers configure: ArduPilot's IMU packet (measurements
only), the ROS 1 node's output 1 and the ROS 2 node's output 1 (quantities computed from the samples: ECEF,
body and NED rotations, UTC, status words). Layouts are timed interleaved, `--repeats` rounds of `--count`
encodes each, in process CPU time, so load hits all alike; prints the median and every round, the CPU model
and the load average.

    .venv/bin/python tools/bench_vectornav_fields.py [--count 2000] [--repeats 5]
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from firmware_protocols.base import Samples
from firmware_protocols.devices.base import single
from firmware_protocols.wire_formats.vectornav_binary import BinaryEncoder, _layout_from_selection

LAYOUTS = {
    "ardupilot-imu": "common:timestartup,angularrate,accel,imu,magpres",
    "ros1-output1": _layout_from_selection({0: 0x578, 1: 0x4C, 4: 0x100, 5: 0x69F}),
    "ros2-output1": _layout_from_selection({0: 0x7FFF, 3: 0x210, 5: 0x0C}),
}


def samples(n: int) -> Samples:
    rng = np.random.default_rng(1)
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    llh = np.column_stack((47.4 + rng.uniform(-1, 1, n), 8.5 + rng.uniform(-1, 1, n), rng.uniform(0, 2000, n)))
    return Samples(np.arange(n, dtype=np.int64) * 2_500_000, rng.normal(size=(n, 3)), rng.normal(size=(n, 3)),
                   mag=rng.normal(size=(n, 3)), quat=quat, euler=rng.normal(size=(n, 3)),
                   delta_theta=rng.normal(size=(n, 3)), delta_velocity=rng.normal(size=(n, 3)),
                   position_llh=llh, velocity_ned=rng.normal(size=(n, 3)),
                   attitude_sigma_rad=np.full((n, 3), 0.01), position_sigma_m=np.ones((n, 3)),
                   velocity_sigma_mps=np.full((n, 3), 0.1), ins_mode=np.full(n, 2.0), gnss_fix=np.full(n, 3.0))


def cpu_model() -> str:
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    block = samples(args.count)
    encoders = {name: BinaryEncoder(layout) for name, layout in LAYOUTS.items()}
    for encoder in encoders.values():             # compile (or load the cache) outside the timing
        encoder.encode(single(block, 0))
    print(f"{cpu_model()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    rounds = {name: [] for name in encoders}
    for _ in range(args.repeats):
        for name, encoder in encoders.items():
            start = time.process_time()
            for i in range(args.count):
                encoder.encode(single(block, i))
            rounds[name].append((time.process_time() - start) / args.count * 1e6)
    for name, values in rounds.items():
        layout = LAYOUTS[name] if isinstance(LAYOUTS[name], str) else "header " + LAYOUTS[name].header.hex()
        print(f"{name:14} {layout:58} median {np.median(values):6.1f} us CPU per packet "
              f"({', '.join(f'{v:.1f}' for v in values)})")
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
