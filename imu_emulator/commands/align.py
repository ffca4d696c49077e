"""`imu-emulator align`: relative orientation, time offset (and drift) and lever arm of two IMUs, from their
records (imu_emulator.analysis.alignment)."""
from __future__ import annotations

import json
import math
from pathlib import Path

from imu_emulator.errors import ImuEmulatorError


ORDER = 90     # place in `imu-emulator --help`


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "align", help="relative orientation and time offset of two IMUs from their data",
        description="Estimate the rotation C that maps B's measurements into A's frame (with A mounted like the "
                    "body, B's mounting_rpy_deg), B's clock minus A's clock, the gyro bias difference and, with "
                    "--lever-arm, B's position relative to A; with 1-sigma uncertainties and an observability "
                    "verdict. Inputs: the emulator's Parquet/CSV/NPZ outputs or plain logs with columns "
                    "t,ax,ay,az,gx,gy,gz (s, m/s^2, rad/s), each on its own clock and at its own rate.")
    p.add_argument("a", help="record of IMU A (the reference frame)")
    p.add_argument("b", help="record of IMU B (may be the same file as A)")
    p.add_argument("--imu-a", help="IMU name in A's file, when it holds several")
    p.add_argument("--imu-b", help="IMU name in B's file, when it holds several")
    p.add_argument("--lever-arm", action="store_true",
                   help="also fit the accelerometers: lever arm and accelerometer bias difference")
    p.add_argument("--drift", action="store_true", help="also estimate a linear drift between the two clocks")
    p.add_argument("--max-offset-s", type=float, help="search the time offset within +-this (default: half the "
                                                      "shorter record)")
    p.add_argument("--json", metavar="OUT", help="also write the results as JSON to OUT")
    p.set_defaults(func=cmd_align)


def cmd_align(args) -> int:
    from imu_emulator.analysis.alignment import AlignOptions, align
    from imu_emulator.analysis.imulog import pick, read_logs

    if args.max_offset_s is not None and not (math.isfinite(args.max_offset_s) and args.max_offset_s > 0):
        raise ImuEmulatorError(f"--max-offset-s: expected a positive number of seconds, got {args.max_offset_s}")
    if args.json is not None and not Path(args.json).parent.exists():
        raise ImuEmulatorError(f"--json {args.json}: directory {Path(args.json).parent} does not exist")
    logs_a = read_logs(args.a)
    same = Path(args.a).resolve() == Path(args.b).resolve()
    logs_b = logs_a if same else read_logs(args.b)
    name_a, name_b = args.imu_a, args.imu_b
    named = [n for n in logs_a if n is not None]
    if same and name_a is None and name_b is None and len(named) == 2:
        name_a, name_b = named          # one file with two IMUs: the first is A, the second B
    a = pick(logs_a, name_a, Path(args.a).name, "--imu-a")
    b = pick(logs_b, name_b, Path(args.b).name, "--imu-b")
    if a is b:
        raise ImuEmulatorError(f"A and B are the same record ({a.label}): name two IMUs with --imu-a and --imu-b")
    result = align(a, b, AlignOptions(lever_arm=args.lever_arm, drift=args.drift, max_offset_s=args.max_offset_s))
    print(report(result, a.label, b.label))
    if args.json is not None:     # after the report: results a bad path cannot keep are shown all the same
        from imu_emulator.output.atomic import AtomicOutput
        with AtomicOutput(args.json) as out:
            out.write(json.dumps(result.to_json(), indent=2) + "\n")
    return 0


def _fixed(value: float, digits: int) -> str:
    """value with `digits` decimals, and no sign on a value that rounds to zero there (-1e-13 s is 0.000000,
    not -0.000000: a sign the digits cannot back)."""
    text = f"{value:.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def report(result, label_a: str, label_b: str) -> str:
    obs, sig = result.observable, result.sigma
    lines = [f"B = {label_b} relative to A = {label_a}: {result.n_rows} samples over {result.overlap_s:.3f} s "
             f"(common base: {result.base}'s stamps)"]
    angles = []
    for i, name in enumerate(("roll", "pitch", "yaw")):
        angles.append(f"{name} {_fixed(result.euler_deg[i], 6)} ± {sig['euler_deg'][i]:.2g}°" if obs[name]
                      else f"{name} unobservable")
    lines.append("rotation B -> A (z-y-x, = B's mounting_rpy_deg when A is unrotated): " + ", ".join(angles))
    w, x, y, z = result.quaternion_wxyz
    lines.append(f"quaternion (w, x, y, z): {w:.9f}, {x:.9f}, {y:.9f}, {z:.9f}")
    lines.append("DCM: " + "; ".join(" ".join(f"{v:+.9f}" for v in row) for row in result.C))
    offset = (f"{_fixed(result.time_offset_s * 1e3, 6)} ± {sig['time_offset_s'] * 1e3:.2g} ms" if obs["time_offset_s"]
              else "unobservable")
    coarse = "not searched" if result.coarse_offset_s is None else f"coarse {result.coarse_offset_s * 1e3:.3f} ms"
    lines.append(f"time offset t_B - t_A: {offset} ({coarse})"
                 + (f" at t_A = {result.time_reference_s:.6f} s" if result.drift_ppm is not None else ""))
    if result.drift_ppm is not None:
        drift = (f"{result.drift_ppm:.3f} ± {sig['clock_drift_ppm']:.2g} ppm" if obs["clock_drift_ppm"]
                 else "unobservable")
        lines.append(f"clock drift d(t_B - t_A)/dt_A: {drift}")
    lines.append("gyro bias difference b_A - C b_B: "
                 + ", ".join(f"{v:+.3e}" for v in result.gyro_bias_diff) + " rad/s")
    if result.lever_arm_m is not None:
        parts = [f"{'xyz'[i]} {v:+.6f} ± {sig['lever_arm_m'][i]:.2g}" if obs["lever_arm_m"][i]
                 else f"{'xyz'[i]} unobservable" for i, v in enumerate(result.lever_arm_m)]
        lines.append("lever arm (B's position relative to A, A's frame, m): " + ", ".join(parts))
        lines.append("accel bias difference C b_B - b_A: "
                     + ", ".join(f"{v:+.3e}" for v in result.accel_bias_diff) + " m/s^2")
    lines.append("residual RMS: " + ", ".join(f"{k} {v:.3g}" for k, v in result.residual_rms.items()))
    for reason in result.reasons:
        lines.append(f"unobservable: {reason}")
    for note in result.notes:
        lines.append(f"note: {note}")
    return "\n".join(lines)
