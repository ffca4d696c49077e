"""Kernel throughput, the cost of each effect, and the whole `generate` command with a warm cache.

    .venv/bin/python tools/bench_kernel.py [--repeat 5] [--skip-generate]

Prints figures; asserts nothing (these machines are shared and noisy: compare medians across runs).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from imu_emulator import load_scene, scene_from_dict  # noqa: E402
from imu_emulator.codegen.generate import generate_source  # noqa: E402
from imu_emulator.runtime.simulation import Simulation  # noqa: E402

BLOCK = 65536


def throughput(scene, repeat: int, attitude=False) -> tuple[float, float]:
    """Median and best samples/s over the whole scene, compile excluded (one warm-up block first).
    Output buffers are reused across blocks, as the streaming path does, so page faults of fresh
    memory are not counted as kernel time."""
    sim = Simulation(scene, attitude=attitude)
    out = sim.block(0, BLOCK)
    n = scene.n_samples
    rates = []
    for _ in range(repeat):
        start = time.perf_counter()
        for k0 in range(0, n, BLOCK):
            size = min(BLOCK, n - k0)
            sim.block(k0, size, out=out if size == BLOCK else None)
        rates.append(n / (time.perf_counter() - start))
    return float(np.median(rates)), float(np.max(rates))


def circle(effects: dict, imu_extra: dict | None = None, duration=60.0):
    imu = {"name": "imu0", "lever_arm_m": [0.1, -0.05, 0.02], "mounting_rpy_deg": [0.0, 0.0, 0.0]}
    imu.update(imu_extra or {})
    return scene_from_dict({
        "scene": {"rate_hz": 1000, "duration_s": duration},
        "trajectory": {"shape": "circle", "radius_m": 5.0, "frequency_hz": 1.0},
        "attitude": {"mode": "tangent"},
        "imu": [imu],
        "effects": effects,
    })


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--skip-generate", action="store_true")
    args = parser.parse_args()

    scene = load_scene(ROOT / "examples" / "circle.toml")
    median, best = throughput(scene, args.repeat)
    print(f"kernel throughput, examples/circle.toml (gravity + lever arm, 1 kHz x 600 s = {scene.n_samples} samples,"
          f" blocks of {BLOCK}, compile excluded):")
    print(f"  median {median / 1e6:.1f} M samples/s ({1e9 / median:.1f} ns/sample), best {best / 1e6:.1f} M samples/s")
    median_att, _ = throughput(scene, args.repeat, attitude=True)
    print(f"  with attitude quaternion output: {1e9 / median_att:.1f} ns/sample")

    print("\ncost per effect (circle, tangent attitude, 1 kHz x 60 s; ns/sample, median):")
    variants = [
        ("no effects", {}, None),
        ("+ gravity", {"gravity": True}, None),
        ("+ lever_arm", {"lever_arm": True}, None),
        ("+ mounting (rpy 10, 20, 30 deg)", {"mounting": True}, {"mounting_rpy_deg": [10.0, 20.0, 30.0]}),
        ("all three", {"gravity": True, "lever_arm": True, "mounting": True}, {"mounting_rpy_deg": [10.0, 20.0, 30.0]}),
    ]
    base = None
    for label, effects, extra in variants:
        ns = 1e9 / throughput(circle(effects, extra), args.repeat)[0]
        base = ns if base is None else base
        print(f"  {label:34s} {ns:6.1f}   ({ns - base:+.1f} vs none)")

    # An effect named false must compile to exactly the code of an effect not named at all.
    off = generate_source(circle({"gravity": False, "lever_arm": False, "mounting": False}), False, False)
    none = generate_source(circle({}), False, False)
    print(f"\nswitched-off effects: generated kernel identical to no effects: {off == none} "
          f"(so their cost is nil by construction)")

    if args.skip_generate:
        return
    exe = ROOT / ".venv" / "bin" / "imu-emulator"
    command = [str(exe) if exe.exists() else "imu-emulator", "generate", str(ROOT / "examples" / "circle.toml"),
               "-o", "", "--quiet"]
    with tempfile.TemporaryDirectory() as tmp:
        command[4] = os.path.join(tmp, "circle.npz")
        subprocess.run(command, check=True)          # warms the kernel cache
        times = []
        for _ in range(args.repeat):
            start = time.perf_counter()
            subprocess.run(command, check=True)
            times.append(time.perf_counter() - start)
        size = os.path.getsize(command[4]) / 1e6
    print(f"\nwhole `imu-emulator generate examples/circle.toml -o circle.npz` (600 000 samples, {size:.0f} MB),"
          f" warm cache: median {np.median(times):.2f} s, best {min(times):.2f} s")


if __name__ == "__main__":
    main()
