"""What the flicker poles' step grid costs: bias_instability alone and the full error model with the flicker
poles stepped at least FLICKER_STEPS_PER_TAU times per tau, for several values, interleaved in one process.

    .venv/bin/python tools/bench_bias_instability.py [--rounds 9] [--seconds 120] [--steps 100,20]

100 is the old rule (every pole at least 100 steps per tau: the 0.1 s pole steps every sample at 1 kHz); the
module's value is what ships. Each variant compiles into a cache directory of its own (the kernel's cache key
hashes the module's bytes, not the patched value). Timed in thread CPU time beside wall time; the machine is
shared, so compare the ratios within one run. Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from bench_effects import FULL, circle, interleave, report  # noqa: E402

from imu_emulator.runtime import kernels  # noqa: E402
from imu_emulator.effects import bias_instability  # noqa: E402
from imu_emulator.runtime.simulation import Simulation  # noqa: E402

BLOCK = 65536


def build(effects, steps: int, seconds: float, cache: Path):
    """A Simulation whose kernel was generated with FLICKER_STEPS_PER_TAU = steps."""
    shipped = bias_instability.FLICKER_STEPS_PER_TAU
    os.environ["IMU_EMULATOR_CACHE"] = str(cache / f"steps{steps}")
    kernels._loaded.clear()
    bias_instability.FLICKER_STEPS_PER_TAU = steps
    try:
        scene = circle(effects, seconds)
        sim = Simulation(scene, attitude=False)
    finally:
        bias_instability.FLICKER_STEPS_PER_TAU = shipped
    return sim, sim.block(0, BLOCK), scene.n_samples


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--seconds", type=float, default=120.0)
    parser.add_argument("--steps", default=f"100,{bias_instability.FLICKER_STEPS_PER_TAU}")
    args = parser.parse_args()
    steps = [int(x) for x in args.steps.split(",")]
    with tempfile.TemporaryDirectory(prefix="bench-bi-") as tmp:
        variants = [("kinematics only", [], steps[0])]
        for n in steps:
            variants += [(f"+ bias_instability, {n}/tau", ["bias_instability"], n),
                         (f"full error model, {n}/tau", FULL, n)]
        sims = [(label, *build(effects, n, args.seconds, Path(tmp))) for label, effects, n in variants]
        cpu, wall = interleave(sims, args.rounds)
    report(sims, cpu, wall, f"circle scene, 1 kHz, lever arm, {args.seconds:g} s per run, {args.rounds} interleaved "
           "rounds (ns/sample; thread CPU min / median / max, wall median)", "over kinematics")

if __name__ == "__main__":
    main()
