"""Cost of each sensor-error effect alone and of the full error model, on the circle scene at 1 kHz with a
lever arm, and the cost of one counter-based normal; with --vibration, the vibration variants only (sines,
linear PSD, angular PSD, angular PSD with the attitude output) against the kinematics alone.

    .venv/bin/python tools/bench_effects.py [--rounds 7] [--seconds 60] [--vibration]

Variants are interleaved (A, B, C, A, B, C, ...) and timed in thread CPU time (time.thread_time_ns) beside
wall time, because the machine is shared: compare the ratios, not one run's absolute figures. Prints figures;
asserts nothing.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from imu_emulator import scene_from_dict  # noqa: E402
from imu_emulator.runtime.simulation import Simulation  # noqa: E402

BLOCK = 65536
GYRO = {"noise_density": "0.007 deg/s/sqrt(Hz)", "bias_instability": "10 deg/h", "random_walk": "0.5 deg/h/sqrt(h)",
        "bias": ["0.1 deg/s", 0, 0], "turn_on_bias_sd": "0.2 deg/s",
        "scale_factor": "500 ppm", "misalignment": "1 mrad", "g_sensitivity": "0.1 deg/s/g",
        "nonlinearity": "1e-4 s/deg", "bias_tc": "0.01 deg/s/K", "scale_tc": "30 ppm/K",
        "range": "2000 deg/s", "resolution": "0.061 deg/s"}
ACCEL = {"noise_density": "120 ug/sqrt(Hz)", "bias_instability": "30 ug", "random_walk": "0.01 m/s^2/sqrt(h)",
         "bias": "2 mg", "turn_on_bias_sd": "5 mg",
         "scale_factor": "0.1 %", "misalignment": "1 mrad", "nonlinearity": "10 ug/g^2",
         "bias_tc": "0.1 mg/K", "scale_tc": "100 ppm/K", "range": "16 g", "resolution": "0.488 mg"}
IMU = {"temperature_c": "20 + 0.001*t", "warmup_rise_c": 15.0, "warmup_tau_s": 300.0}
#: vibration variants: three sinusoidal lines (two linear, one angular), or a random PSD on three axes
SINES = {"sines": [{"axis": "x", "amplitude": "0.5 g", "frequency": "120 Hz"},
                   {"axis": "z", "amplitude": "0.3 g", "frequency": "47 Hz", "phase": "30 deg"},
                   {"axis": "y", "amplitude": "2 deg/s", "frequency": "90 Hz"}]}
PSD = {"psd": [["20 Hz", "0.001 g^2/Hz"], ["80 Hz", "0.01 g^2/Hz"], ["450 Hz", "0.01 g^2/Hz"]]}
ANGULAR_PSD = {"angular_psd": [["20 Hz", "1e-3 (deg/s)^2/Hz"], ["450 Hz", "1e-3 (deg/s)^2/Hz"]]}
DETERMINISTIC = ["scale_factor", "misalignment", "g_sensitivity", "nonlinearity", "temperature", "range", "resolution"]
#: the issue's full error model: noise + bias instability + random walk + scale/misalignment + range + resolution
FULL = ["noise", "bias_instability", "random_walk", "scale_factor", "misalignment", "range", "resolution"]


def circle(effects, seconds: float, vibration=None):
    return scene_from_dict({
        "scene": {"rate_hz": 1000, "duration_s": seconds, "seed": 1},
        "trajectory": {"shape": "circle", "radius_m": 5.0, "frequency_hz": 1.0},
        "attitude": {"mode": "tangent"},
        "imu": [{"name": "imu0", "lever_arm_m": [0.1, -0.05, 0.02], "gyro": GYRO, "accel": ACCEL, **IMU,
                 **({"vibration": vibration} if vibration else {})}],
        "effects": {"gravity": True, "lever_arm": True, **{name: True for name in effects}},
    })


_run_at: dict[int, int] = {}   # id(sim) -> the run sample its state is at (time_run continues the run)


def first_block(sim: Simulation, n: int):
    """The warm-up block (compiles, loads), of the size time_run reuses as its output buffers."""
    out = sim.block(0, min(BLOCK, n))
    _run_at[id(sim)] = len(out.t_s)
    return out


def time_run(sim: Simulation, n: int, out) -> tuple[int, int]:
    """Thread CPU ns and wall ns for the whole scene, output buffers reused and the run's sample count continued
    (as streaming does: no state reset, no fresh arrays; a scene shorter than BLOCK used to allocate its block
    every run, and restart the state, both timed)."""
    start = _run_at.get(id(sim), 0)
    cpu0, wall0 = time.thread_time_ns(), time.perf_counter_ns()
    for k0 in range(0, n, BLOCK):
        size = min(BLOCK, n - k0)
        sim.block(k0, size, out=out if size == len(out.t_s) else None, run_sample=start + k0)
    _run_at[id(sim)] = start + n
    return time.thread_time_ns() - cpu0, time.perf_counter_ns() - wall0


def time_interleaved(scenes, rounds: int) -> tuple[dict, dict]:
    """[(label, scene)] -> ({label: [thread CPU ns/sample per round]}, {label: [wall ns/sample]}), the variants
    run in turn within each round."""
    sims = []
    for label, scene in scenes:
        sim = Simulation(scene, attitude=False)
        sims.append((label, sim, first_block(sim, scene.n_samples), scene.n_samples))
    return interleave(sims, rounds)


def rows(cpu: dict, wall: dict, width: int):
    """(label, "  label  min median max   wall median", CPU median) per variant, for the tables printed."""
    for label in cpu:
        c = np.array(cpu[label])
        yield label, (f"  {label:{width}} {c.min():7.1f} {np.median(c):7.1f} {c.max():7.1f}   "
                      f"wall {np.median(wall[label]):7.1f}"), float(np.median(c))


def normal_cost(rounds: int) -> list[float]:
    from imu_emulator.numerics.counter_rng import normals
    key = np.uint64(12345)
    normals(key, 0, 10)
    n = 5_000_000
    costs = []
    for _ in range(rounds):
        cpu0 = time.thread_time_ns()
        normals(key, 0, n)
        costs.append((time.thread_time_ns() - cpu0) / n)
    return costs


def interleave(sims, rounds: int):
    """Thread CPU and wall ns/sample of each (label, sim, out, n), the variants taking turns every round."""
    cpu = {label: [] for label, *_ in sims}
    wall = {label: [] for label, *_ in sims}
    for _ in range(rounds):
        for label, sim, out, n in sims:
            c, w = time_run(sim, n, out)
            cpu[label].append(c / n)
            wall[label].append(w / n)
    return cpu, wall


def report(sims, cpu, wall, header: str, against: str) -> None:
    """One line per variant: CPU min / median / max, wall median, M samples/s, and the difference from the first."""
    base = np.median(cpu[sims[0][0]])
    print(header)
    for label, *_ in sims:
        c = np.array(cpu[label])
        print(f"  {label:40} {c.min():7.1f} {np.median(c):7.1f} {c.max():7.1f}   wall {np.median(wall[label]):7.1f}"
              f"   {1e3 / np.median(c):6.2f} M/s   {against} {np.median(c) - base:+7.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--seconds", type=float, default=60.0, help="scene length per timed run (1 kHz)")
    parser.add_argument("--vibration", action="store_true", help="only the vibration variants")
    args = parser.parse_args()
    if args.vibration:
        return bench_vibration(args)

    variants = [("kinematics only (gravity + lever arm)", []), ("+ noise", ["noise"]),
                ("+ bias_instability", ["bias_instability"]), ("+ random_walk", ["random_walk"]),
                ("+ bias", ["bias"]), ("stochastic (noise, BI, RW, bias)", ["noise", "bias_instability", "random_walk", "bias"]),
                *((f"+ {name}", [name]) for name in DETERMINISTIC),
                ("full error model (issue 9 §6)", FULL), ("every error effect", [*FULL, "bias", *DETERMINISTIC[2:5]]),
                ("+ vibration, 3 sines", ["vibration"], SINES), ("+ vibration, PSD 3 x 256 taps", ["vibration"], PSD)]
    sims = []
    for label, effects, *vibration in variants:
        scene = circle(effects, args.seconds, *vibration)
        sim = Simulation(scene, attitude=False)
        out = first_block(sim, scene.n_samples)
        sims.append((label, sim, out, scene.n_samples))
    cpu, wall = interleave(sims, args.rounds)
    report(sims, cpu, wall, f"circle scene, 1 kHz, lever arm, {args.seconds:g} s per run, {args.rounds} interleaved "
           "rounds (ns/sample; thread CPU min / median / max, wall median; Msamples/s from the CPU median)",
           "effect cost")
    nc = normal_cost(args.rounds)
    print(f"one counter-based normal (normals() loop, thread CPU): min {min(nc):.2f} median {np.median(nc):.2f} ns")


def bench_vibration(args) -> None:
    """The vibration variants alone: the cost per sample of its sines, linear PSD and angular PSD (3 axes x 256
    filter taps each), and of the attitude output turned by the angular vibration."""
    variants = [("kinematics only (gravity + lever arm)", None, False),
                ("kinematics, attitude output", None, True),
                ("+ vibration, 3 sines (2 linear, 1 angular)", SINES, False),
                ("+ vibration, linear PSD 3 x 256 taps", PSD, False),
                ("+ vibration, angular PSD 3 x 256 taps", ANGULAR_PSD, False),
                ("+ vibration, angular PSD, attitude output", ANGULAR_PSD, True)]
    sims = []
    for label, vib, attitude in variants:
        scene = circle(["vibration"] if vib else [], args.seconds, vib)
        sim = Simulation(scene, attitude=attitude)
        sims.append((label, sim, first_block(sim, scene.n_samples), scene.n_samples))
    cpu, wall = interleave(sims, args.rounds)
    report(sims, cpu, wall, f"vibration on the circle scene, 1 kHz, lever arm, {args.seconds:g} s per run, "
           f"{args.rounds} interleaved rounds (ns/sample; thread CPU min / median / max, wall median; Msamples/s "
           "from the CPU median)", "vs kinematics")
    tap = (np.median(cpu[sims[4][0]]) - np.median(cpu[sims[0][0]])) / (3 * 256)
    print(f"angular PSD per filter tap and sample (thread CPU median; 2 multiply-adds each): {tap:.2f} ns")


if __name__ == "__main__":
    main()
