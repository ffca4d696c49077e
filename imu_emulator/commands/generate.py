"""`imu-emulator generate`: the samples of a scene to a file."""
from __future__ import annotations

import argparse
import signal
import sys
import threading

from imu_emulator.commands.shared import add_increments_option, load_scene_with_warnings, number, start_time
from imu_emulator.runtime.progress import CompileStatus, Progress


ORDER = 10     # place in `imu-emulator --help`


def register(subparsers) -> None:
    gen = subparsers.add_parser("generate", help="write the samples of a scene to Parquet, CSV, NPZ or MCAP")
    gen.add_argument("scene", help="scene file (TOML)")
    gen.add_argument("-o", "--output", required=True, help="output file: .parquet or .csv (written block by "
                     "block: memory stays flat for any duration), .npz (held whole: runs that fit in memory) or "
                     ".mcap (ROS 2 bag)")
    gen.add_argument("--truth", action="store_true", help="add position, velocity, attitude and body rates "
                     "(and each IMU's realized bias when a bias effect is on)")
    add_increments_option(gen)
    gen.add_argument("--start-time", type=start_time, default=None, metavar="ISO8601|now",
                     help="the UTC instant of scene time 0: a ROS 2 bag's stamps are it + scene time, as stream's "
                     "wire times (\"2026-03-01T12:00:00Z\"; no zone is UTC; now = the wall clock at start; default "
                     "2024-01-01T00:00:00Z, never 0, which ROS treats as unset)")
    gen.add_argument("--ros-axes", choices=("rep103", "scene"), default="rep103",
                     help="a ROS 2 bag's axes: REP 103 (bodies forward-left-up, world ENU, whatever the scene's "
                     "frame; default) or the scene's own, with frame ids saying so (<imu>_frd, world_ned)")
    gen.add_argument("--quiet", action="store_true", help="no progress bar or summary (warnings still show)")
    gen.add_argument("--allow-large", action="store_true", help="write a CSV larger than the free disk space")
    gen.add_argument("--block", type=number(1, 10_000_000, integer=True), default=65536, help=argparse.SUPPRESS)
    gen.set_defaults(func=cmd_generate)


def _resolved(start):
    """--start-time's value as Unix ns: "now" is the wall clock as the run begins."""
    if start == "now":
        import time
        return time.time_ns()
    return start


def cmd_generate(args) -> int:
    from imu_emulator.output.formats import check_path

    check_path(args.output)
    scene = load_scene_with_warnings(args.scene)
    stopped, restore = _exit_cleanly_on(signal.SIGTERM, signal.SIGHUP, signal.SIGINT)
    try:
        return _generate(args, scene, stopped)
    finally:
        restore()   # a caller in the same process (the Python API, tests) gets its own handlers back


def _generate(args, scene, stopped) -> int:
    from imu_emulator.output.formats import check_output, format_of, open_writer
    from imu_emulator.output.columns import scene_companions
    from imu_emulator.output.formats.mcap import placements
    from imu_emulator.runtime.samples import counts_text
    from imu_emulator.runtime.simulation import Simulation

    # The output file is created before the kernel compiles: an unwritable path fails at once. It appears
    # at its path only when every block is written (a failed run leaves nothing behind).
    from imu_emulator.codegen.plan import EffectPlan
    bias_truth = EffectPlan(scene).bias_truth    # the realized-bias columns, known before compiling
    from imu_emulator.scene.earth import model_on
    from imu_emulator.effects.noise import variances
    record = format_of(args.output)
    conventions = None
    if model_on(scene):        # earth_truth (frames, rotations) only for scenes on the Earth
        from imu_emulator.motion.earth_truth import conventions as earth_conventions
        conventions = earth_conventions(scene)
    with open_writer(args.output, scene.imu_names, args.truth, bias_truth=bias_truth,
                     temperature="temperature" in scene.effects, increments=bool(args.increments),
                     metadata=record.run_metadata(scene) if record.run_metadata else None, conventions=conventions,
                     covariances=variances(scene), frame=scene.frame,
                     attitude_reference=scene.attitude_reference, effects=scene.effects,
                     companions=scene_companions(scene), start_ns=_resolved(args.start_time), ros_axes=args.ros_axes,
                     placements=placements(scene)) as writer:
        check_output(scene, args.output, args.truth, args.allow_large, increments=bool(args.increments))
        attitude = record.attitude    # a ROS Imu message has an orientation field: the sensor frame's attitude
        with CompileStatus(scene, attitude=attitude, truth=args.truth, quiet=args.quiet, increments=args.increments):
            sim = Simulation(scene, attitude=attitude, truth=args.truth, increments=args.increments)
        progress = Progress(args.quiet)
        total = sim.n_samples
        try:
            for k0 in range(0, total, args.block):
                writer.write(sim.block(k0, min(args.block, total - k0)))
                stopped()
                progress(min(k0 + args.block, total), total)
        finally:
            progress.close()
    if not args.quiet:
        print(f"wrote {total} samples x {len(scene.imus)} IMU(s) to {args.output}", file=sys.stderr)
        counted = counts_text(sim.counts())
        if counted:
            print(counted, file=sys.stderr)
    return 0


def _exit_cleanly_on(*signals):
    """Interrupt, kill and hang-up signals unwind the run, so the unfinished output file is removed. Returns a
    check for the block loop (an exception raised in a signal handler can be swallowed by C code that
    was running, seen while the CSV rows were formatted, so the signal is also remembered and raised there)
    and a function that puts the previous handlers back."""
    received = []

    def leave(signum, frame):
        received.append(signum)
        raise SystemExit(128 + signum)

    def check():
        if received:
            raise SystemExit(128 + received[0])

    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in signals:
            previous[sig] = signal.signal(sig, leave)

    def restore():
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return check, restore
