"""`imu-emulator generate`: the samples of a scene to a file."""
from __future__ import annotations

import argparse
import sys

from imu_emulator.progress import Progress


def register(subparsers) -> None:
    gen = subparsers.add_parser("generate", help="write the samples of a scene to CSV or NPZ")
    gen.add_argument("scene", help="scene file (TOML)")
    gen.add_argument("-o", "--output", required=True, help="output file, .csv, .npz or .mcap (ROS 2 bag)")
    gen.add_argument("--truth", action="store_true", help="add position, velocity, attitude and body rates")
    gen.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    gen.add_argument("--block", type=int, default=65536, help=argparse.SUPPRESS)
    gen.set_defaults(func=cmd_generate)


def cmd_generate(args) -> int:
    from imu_emulator.output import check_path, open_writer
    from imu_emulator.scene import load_scene
    from imu_emulator.simulation import Simulation

    check_path(args.output)
    scene = load_scene(args.scene)
    for warning in scene.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    # a ROS Imu message has an orientation field: fill it from the sensor frame's attitude
    sim = Simulation(scene, attitude=args.output.lower().endswith(".mcap"), truth=args.truth)
    writer = open_writer(args.output, scene.imu_names, args.truth)
    progress = Progress(args.quiet)
    total = sim.n_samples
    try:
        for k0 in range(0, total, args.block):
            writer.write(sim.block(k0, min(args.block, total - k0)))
            progress(min(k0 + args.block, total), total)
    finally:
        progress.close()
        writer.close()
    if not args.quiet:
        print(f"wrote {total} samples x {len(scene.imus)} IMU(s) to {args.output}", file=sys.stderr)
    return 0
