"""`imu-emulator` command line: generate samples to a file, stream them live, list formats and targets."""
from __future__ import annotations

import argparse
import importlib
import sys
import time

from imu_emulator.errors import ImuEmulatorError


class Progress:
    """A progress bar on stderr for long runs; silent for short ones and with --quiet."""

    def __init__(self, quiet: bool, min_seconds: float = 1.0):
        self.quiet = quiet or not sys.stderr.isatty()
        self.start = time.monotonic()
        self.min_seconds = min_seconds
        self.shown = False

    def __call__(self, done: int, total: int) -> None:
        if self.quiet or time.monotonic() - self.start < self.min_seconds:
            return
        width = 40
        filled = int(width * done / max(total, 1))
        sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} samples")
        sys.stderr.flush()
        self.shown = True

    def close(self) -> None:
        if self.shown:
            sys.stderr.write("\n")


def cmd_generate(args) -> int:
    from imu_emulator.output import Writer, check_path
    from imu_emulator.scene import load_scene
    from imu_emulator.simulate import Simulation

    check_path(args.output)
    scene = load_scene(args.scene)
    for warning in scene.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    sim = Simulation(scene, attitude=False, truth=args.truth)
    writer = Writer(args.output, scene.imu_names, args.truth)
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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="imu-emulator", description="Turn a described motion into IMU output.")
    sub = parser.add_subparsers(dest="command", required=True)
    gen = sub.add_parser("generate", help="write the samples of a scene to CSV or NPZ")
    gen.add_argument("scene", help="scene file (TOML)")
    gen.add_argument("-o", "--output", required=True, help="output file, .csv or .npz")
    gen.add_argument("--truth", action="store_true", help="add position, velocity, attitude and body rates")
    gen.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    gen.add_argument("--block", type=int, default=65536, help=argparse.SUPPRESS)
    gen.set_defaults(func=cmd_generate)
    try:
        stream_cli = importlib.import_module("imu_emulator.stream_cli")
    except ModuleNotFoundError as exc:  # the streaming layer is optional only while it is being built
        if exc.name != "imu_emulator.stream_cli":
            raise
    else:
        stream_cli.register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ImuEmulatorError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
