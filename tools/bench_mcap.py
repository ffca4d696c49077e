"""CPU time per sensor_msgs/Imu message written to MCAP: the per-message path (mcap-ros2-support's Writer, one
`write_message` with a dict per message, as imu_emulator wrote bags before issue 25) against the block path
(imu_emulator.output.formats.mcap: whole blocks of messages as numpy rows of CDR records, zstd chunks).

    .venv/bin/python tools/bench_mcap.py [--samples 60000] [--imus 1] [--rounds 5] [--variants block]

Both write the same random samples (sensor-frame attitude included) to an in-memory file; the variants are
interleaved in one process (A, B, A, B, ...) and timed with thread CPU time (the work is single-threaded) beside
wall time; prints min/median per message, messages per CPU second and the ratio, with the CPU model and the load
average, as figures are only comparable on a named machine under a stated load. Asserts nothing.
"""
from __future__ import annotations

import argparse
import io
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from imu_emulator.output.base import Contents  # noqa: E402
from imu_emulator.output.columns import Layout  # noqa: E402
from imu_emulator.runtime.samples import SampleBlock  # noqa: E402


def make_block(n: int, n_imu: int, rng) -> SampleBlock:
    q = rng.normal(size=(n_imu, n, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return SampleBlock(k0=0, t_s=np.arange(n) / 1000.0, accel=rng.normal(size=(n_imu, n, 3)),
                       gyro=rng.normal(size=(n_imu, n, 3)), quat=q)


def per_message(block: SampleBlock, names) -> int:
    """The pre-issue-25 path: one dict and one write_message per message (mcap-ros2-support)."""
    from mcap_ros2.writer import Writer
    from imu_emulator.output.ros2.messages import DEFINITIONS, IMU
    out = io.BytesIO()
    writer = Writer(out)
    schema = writer.register_msgdef(IMU, DEFINITIONS[IMU])
    start = 1_704_067_200 * 10**9
    ns = block.time_ns() + start
    covariance = [0.0] * 9
    for m, name in enumerate(names):
        topic = f"/imu/{name}"
        for j in range(len(block)):
            w, a, q = block.gyro[m, j], block.accel[m, j], block.quat[m, j]
            t = int(ns[j])
            writer.write_message(topic, schema, {
                "header": {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9}, "frame_id": name},
                "orientation": {"x": float(q[1]), "y": float(q[2]), "z": float(q[3]), "w": float(q[0])},
                "orientation_covariance": covariance,
                "angular_velocity": {"x": float(w[0]), "y": float(w[1]), "z": float(w[2])},
                "angular_velocity_covariance": covariance,
                "linear_acceleration": {"x": float(a[0]), "y": float(a[1]), "z": float(a[2])},
                "linear_acceleration_covariance": covariance}, log_time=t, publish_time=t)
    writer.finish()
    return len(out.getvalue())


def block_path(block: SampleBlock, names, truth_block=None) -> int:
    """imu_emulator's writer, fed the block in pieces of `--block` samples as `generate` does."""
    from imu_emulator.output.formats.mcap import McapWriter
    from imu_emulator.output import atomic

    class Memory:                       # AtomicOutput stand-in: the file in memory
        def __init__(self, path, mode):
            self.file = io.BytesIO()

        def close(self):
            pass

        def discard(self):
            pass

    original = atomic.AtomicOutput
    from imu_emulator.output.formats import mcap as mcap_module
    mcap_module.AtomicOutput = Memory
    try:
        writer = McapWriter(Path("bench.mcap"), Contents(list(names), Layout(), frame="NED"))
        for k0 in range(0, len(block), BLOCK):
            writer.write(block.view(k0, min(len(block), k0 + BLOCK)))
        writer._bag.finish()
        return len(writer._out.file.getvalue())
    finally:
        mcap_module.AtomicOutput = original


BLOCK = 65536


def main() -> None:
    global BLOCK
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=60_000)
    parser.add_argument("--imus", type=int, default=1)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--block", type=int, default=65536, help="samples per writer.write (generate's default)")
    parser.add_argument("--variants", default="per-message,block", help="comma-separated: per-message, block")
    args = parser.parse_args()
    BLOCK = args.block
    names = [f"imu{i}" for i in range(args.imus)]
    block = make_block(args.samples, args.imus, np.random.default_rng(25))
    messages = args.samples * args.imus
    variants = {name: {"per-message": per_message, "block": block_path}[name] for name in args.variants.split(",")}
    for run in variants.values():                   # warm: imports, numba's cached functions
        run(make_block(100, args.imus, np.random.default_rng(0)), names)
    cpu = {name: [] for name in variants}
    wall = {name: [] for name in variants}
    sizes = {}
    for _ in range(args.rounds):
        for name, run in variants.items():
            c, w = time.thread_time_ns(), time.perf_counter_ns()
            sizes[name] = run(block, names)
            cpu[name].append((time.thread_time_ns() - c) / messages / 1000)
            wall[name].append((time.perf_counter_ns() - w) / messages / 1000)
    model = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")),
                 "unknown CPU")
    print(f"CPU: {model}, {os.cpu_count()} logical; load average before/after: {os.getloadavg()}")
    print(f"{messages} sensor_msgs/Imu messages ({args.imus} IMU(s) x {args.samples} samples), "
          f"{args.rounds} interleaved rounds, block {args.block}")
    print(f"{'path':12s} {'CPU us/msg min/median':>24s} {'wall us/msg min/median':>24s} {'msgs per CPU s':>16s} "
          f"{'file bytes':>12s}")
    for name in variants:
        best = min(cpu[name])
        print(f"{name:12s} {best:11.3f} {statistics.median(cpu[name]):11.3f}  "
              f"{min(wall[name]):11.3f} {statistics.median(wall[name]):11.3f}  {1e6 / best:16,.0f} {sizes[name]:12d}")
    if len(variants) == 2:
        ratios = [a / b for a, b in zip(cpu["per-message"], cpu["block"])]
        print(f"per-message / block CPU ratio per round: min {min(ratios):.1f}, median {statistics.median(ratios):.1f}")


if __name__ == "__main__":
    main()
