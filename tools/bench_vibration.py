"""Random vibration's cost: M samples/s of the circle scene (1 kHz, lever arm) with a linear PSD on 3 axes at
psd_lines = 256 (--lines), and the kinematics alone, for this checkout and another one (--against: e.g. an
export of an older commit: 1483ea4's PSD was a direct-form FIR of psd_lines taps per axis, before the FFT
convolution), interleaved.

    .venv/bin/python tools/bench_vibration.py --against /tmp/psd-base [--rounds 5] [--seconds 60]

(e.g. `git archive 1483ea4 | tar -x -C /tmp/psd-base` for the direct FIR)

Each measurement is a child process (the two checkouts are two versions of one package): it builds and warms the
simulation (compile or cache load, not timed), then times --seconds of samples in process CPU time
(time.process_time_ns) and wall time. The variants take turns within each round, so load from other processes
falls on all of them alike: compare the ratios. Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
PSD = [["20 Hz", "0.001 g^2/Hz"], ["80 Hz", "0.01 g^2/Hz"], ["450 Hz", "0.01 g^2/Hz"]]
BLOCK = 65536


def child(seconds: float, psd: bool, lines: int) -> None:
    sys.path.insert(0, os.getcwd())
    from imu_emulator import scene_from_dict
    from imu_emulator.runtime.simulation import Simulation
    scene = scene_from_dict({
        "scene": {"rate_hz": 1000, "duration_s": seconds, "seed": 1},
        "trajectory": {"shape": "circle", "radius_m": 5.0, "frequency_hz": 1.0},
        "attitude": {"mode": "tangent"},
        "imu": [{"name": "imu0", "lever_arm_m": [0.1, -0.05, 0.02],
                 **({"vibration": {"psd": PSD, "psd_lines": lines}} if psd else {})}],
        "effects": {"gravity": True, "lever_arm": True, **({"vibration": True} if psd else {})}})
    sim = Simulation(scene, attitude=False)
    n = scene.n_samples
    out = sim.block(0, BLOCK)     # compile or load, warm: not timed
    cpu0, wall0 = time.process_time_ns(), time.perf_counter_ns()
    for k0 in range(BLOCK, BLOCK + n, BLOCK):
        sim.block(k0, BLOCK, out=out)
    print(json.dumps({"cpu": (time.process_time_ns() - cpu0) / n, "wall": (time.perf_counter_ns() - wall0) / n}))


def measure(checkout: Path, seconds: float, psd: bool, lines: int) -> dict:
    result = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", str(seconds),
                             "--lines", str(lines)] + (["--psd"] if psd else []), cwd=checkout,
                            capture_output=True, text=True, check=True,
                            env={**os.environ, "PYTHONPATH": str(checkout)})
    return json.loads(result.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--against", type=Path, help="another checkout to compare (e.g. the commit before)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=60.0, help="scene seconds timed per run (1 kHz)")
    parser.add_argument("--lines", type=int, default=256, help="psd_lines: taps of each axis's filters")
    parser.add_argument("--child", type=float, help=argparse.SUPPRESS)
    parser.add_argument("--psd", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        return child(args.child, args.psd, args.lines)
    psd_label = f"+ PSD 3 axes x {args.lines}"
    checkouts = [("this checkout", ROOT)] + ([("--against", args.against.resolve())] if args.against else [])
    variants = [(f"{name}: {what}", path, psd) for name, path in checkouts
                for what, psd in (("kinematics only", False), (psd_label, True))]
    for _, path, psd in variants:       # compile each once, untimed
        measure(path, 1.0, psd, args.lines)
    cpu = {label: [] for label, *_ in variants}
    wall = {label: [] for label, *_ in variants}
    for _ in range(args.rounds):
        for label, path, psd in variants:
            got = measure(path, args.seconds, psd, args.lines)
            cpu[label].append(got["cpu"])
            wall[label].append(got["wall"])
    print(f"load: {os.getloadavg()}; {os.cpu_count()} CPUs; {args.rounds} interleaved rounds of {args.seconds:g} s "
          "at 1 kHz (ns/sample: process CPU min / median / max, wall median; M samples/s from the CPU median)")
    for label, *_ in variants:
        c = np.array(cpu[label])
        print(f"  {label:40} {c.min():8.1f} {np.median(c):8.1f} {c.max():8.1f}   wall {np.median(wall[label]):8.1f}"
              f"   {1e3 / np.median(c):7.3f} M/s")
    extra = {}
    for name, _ in checkouts:
        extra[name] = np.median(cpu[f"{name}: {psd_label}"]) - np.median(cpu[f"{name}: kinematics only"])
        print(f"  {name}: the PSD's own cost {extra[name]:.1f} ns/sample = {1e3 / extra[name]:.2f} M samples/s")
    if args.against:
        # per round, so that a load change between rounds falls on both sides of each ratio
        ratios = [(cpu[f"--against: {psd_label}"][r] - cpu["--against: kinematics only"][r])
                  / (cpu[f"this checkout: {psd_label}"][r] - cpu["this checkout: kinematics only"][r])
                  for r in range(args.rounds)]
        print(f"  the PSD's own cost, --against / this checkout: {extra['--against'] / extra['this checkout']:.2f} "
              f"(of the medians; per round min / median / max {min(ratios):.2f} / {np.median(ratios):.2f} / "
              f"{max(ratios):.2f})")


if __name__ == "__main__":
    main()
