"""Cost of fitting and evaluating sampled series (imu_emulator.numerics.derivatives) on a long log: 150 001 and
600 001 samples at 1 kHz with ECEF-sized coordinates, each interpolating method fitted and evaluated (derivatives
0-3) at 10 000 points. Prints CPU and wall seconds (best of --repeats) and the ratio 600 k / 150 k: 4 means linear.
Prints figures, asserts nothing (tests/numerics/test_derivatives.py checks the values at this size).
`smooth` and spline5c's rounding rule are timed by tools/smoothing_scan.py --timing.

    .venv/bin/python tools/bench_derivatives.py [--repeats 3]
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from imu_emulator.numerics.derivatives import METHODS, SampledSeries

SIZES = (150_001, 600_001)


def track(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The spec's small loop at 1 kHz, 6.4e6 m from the origin."""
    t = 1e-3 * np.arange(n)
    w = 2 * np.pi
    y = np.column_stack([0.8 * np.cos(w * t), 0.8 * np.sin(w * t), 0.3 * np.cos(3 * w * t)]) + 6.4e6
    return t, y


def cost(method: str, t: np.ndarray, y: np.ndarray, repeats: int) -> tuple[float, float]:
    cpu, wall = [], []
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        SampledSeries(t, y, method, 3).evaluate(t[1000:11000] + 2e-4, 3)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    return min(cpu), min(wall)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}; best of {args.repeats}")
    print(f"{'method':<10} " + " ".join(f"{n:>9} cpu s {n:>9} wall s" for n in SIZES) + "  cpu ratio")
    for method in (m for m in METHODS if m not in ("smooth", "spline5c")):
        figures = [cost(method, *track(n), args.repeats) for n in SIZES]
        cells = " ".join(f"{c:>15.3f} {w:>16.3f}" for c, w in figures)
        print(f"{method:<10} {cells}  {figures[1][0] / max(figures[0][0], 1e-9):9.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
