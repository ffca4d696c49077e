"""Cost of each Earth effect (issue 10) on the circle scene at 1 kHz: flat constant gravity against WGS-84
gravity, earth_rate, coriolis and all three, and a lever arm on the flat and on the all-Earth scene (the IMU
has one; it costs only where the lever_arm effect is on). Any one of them brings in the shared geometry (geodetic
position by fixed-point iteration, the local NED rotation), so each figure includes it once.

    .venv/bin/python tools/bench_earth.py [--rounds 7] [--seconds 60]

Variants are interleaved and timed in thread CPU time (time.thread_time_ns) beside wall time, as
tools/bench_effects.py does (its timing loop is reused): compare the ratios on a shared machine. Prints
figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench_effects import rows, time_interleaved  # noqa: E402

from imu_emulator import scene_from_dict  # noqa: E402

VARIANTS = [("flat: constant gravity", {}, "constant"),
            ("gravity_model = wgs84", {}, "wgs84"),
            ("+ earth_rate (constant g)", {"earth_rate": True}, "constant"),
            ("+ coriolis (constant g)", {"coriolis": True}, "constant"),
            ("all: wgs84 + earth_rate + coriolis", {"earth_rate": True, "coriolis": True}, "wgs84"),
            # the lever arm reads d/dt omega_ib when earth_rate or coriolis is on (earth_motion.inertial_rate_lines)
            ("flat + lever_arm", {"lever_arm": True}, "constant"),
            ("all + lever_arm", {"earth_rate": True, "coriolis": True, "lever_arm": True}, "wgs84")]


def circle(effects: dict, gravity_model: str, seconds: float):
    return scene_from_dict({
        "scene": {"rate_hz": 1000, "duration_s": seconds, "frame": "NED", "gravity_model": gravity_model,
                  "origin": {"lat_deg": 47.4, "lon_deg": 8.5, "height_m": 500.0}},
        "trajectory": {"shape": "circle", "radius_m": 5.0, "frequency_hz": 1.0},
        "attitude": {"mode": "tangent"},
        "imu": [{"name": "imu0", "lever_arm_m": [0.1, -0.05, 0.02]}],
        "effects": {"gravity": True, **effects},
    })


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--seconds", type=float, default=60.0, help="scene length per timed run (1 kHz)")
    args = parser.parse_args()
    cpu, wall = time_interleaved([(label, circle(effects, model, args.seconds)) for label, effects, model in VARIANTS],
                                 args.rounds)
    base = np.median(cpu[VARIANTS[0][0]])
    print(f"circle scene, NED at 47.4 N, 1 kHz, {args.seconds:g} s per run, {args.rounds} interleaved rounds "
          f"(ns/sample; thread CPU min / median / max, wall median)")
    for label, row, median in rows(cpu, wall, 36):
        print(f"{row}   cost {median - base:+7.1f}   ratio {median / base:5.2f}")


if __name__ == "__main__":
    main()
