"""`imu-emulator stream`: a scene live to ports, buses, UDP or capture files at wall-clock rate."""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace

from imu_emulator.commands.shared import load_scene_with_warnings, number, start_time

# Beyond any UART or CAN bus there is, and far from where the numbers stop being exact.
_MAX_RATE = 100_000_000
# Time stamps are int64 nanoseconds (292 years); a stream longer than this is a typo.
_MAX_DURATION_S = 1e9


ORDER = 40     # place in `imu-emulator --help`


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "stream", help="stream a scene live to a pty, serial port, CAN bus, UDP or a capture file",
        description="Stream IMU samples at wall-clock rate. Without --format/--to, the scene's [[stream]] "
                    "tables say what goes where (several IMUs to several targets at once).")
    p.add_argument("scene", help="scene file (TOML)")
    p.add_argument("--format", help="wire format (see `imu-emulator formats`)")
    p.add_argument("--to", dest="target", help="target spec (see `imu-emulator targets`)")
    p.add_argument("--imu", help="IMU name (default: the scene's first)")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="encoder option, repeatable (e.g. sysid=1)")
    p.add_argument("--device", choices=("on", "off"), default="on",
                   help="on (default): formats with a device answer the driver's commands, announce themselves "
                        "and follow the output configuration they are given; off: stream blindly (one-way links)")
    p.add_argument("--link", help="pty: make a stable symlink at this path to the slave")
    p.add_argument("--pace-baud", type=number(1, _MAX_RATE, integer=True), metavar="BAUD", help="pty: deliver no faster than a UART at BAUD")
    p.add_argument("--bitrate", type=number(1, _MAX_RATE, integer=True), help="CAN nominal bit rate, bit/s (default 1000000)")
    p.add_argument("--data-bitrate", type=number(1, _MAX_RATE, integer=True), help="CAN FD data phase bit rate, bit/s")
    p.add_argument("--fd", action="store_true", help="open the CAN bus in FD mode")
    p.add_argument("--speed", type=number(1e-6, 1e6, zero=True), default=1.0,
                   help="time factor; 0 = as fast as the link takes")
    p.add_argument("--loop", action="store_true", help="repeat the scene; time keeps increasing")
    p.add_argument("--start-time", type=start_time, metavar="ISO8601|now", default=None,
                   help="the UTC instant of scene time 0: GNSS/UTC fields are it + scene time, fields counting "
                        "since power-up count from it (\"2026-03-01T12:00:00Z\"; no zone is UTC; \"now\" = the first sample is the "
                        "wall clock; default 2024-01-01T00:00:00Z, as generate)")
    p.add_argument("--epoch-time", action="store_true", help=argparse.SUPPRESS)    # deprecated: --start-time now
    p.add_argument("--duration", type=number(1e-9, _MAX_DURATION_S), metavar="SECONDS",
                   help="stop after this much scene time")
    p.add_argument("--count", type=number(1, 10**15, integer=True), help="stop after this many samples")
    p.add_argument("--allow-overload", action="store_true", help="stream even when the link budget does not fit")
    p.add_argument("--realtime", choices=("auto", "spin", "fifo", "off"), default="auto",
                   help="how the sender waits for deadlines: spin = sleep under SCHED_FIFO priority 1 to 200 us "
                        "before the deadline and spin the rest (most precise, costs up to 40 %% of a core); "
                        "fifo = sleep to the deadline under SCHED_FIFO priority 1; off = normal scheduling, plain "
                        "sleep; auto (default) = spin when 2 or more CPUs are usable, off with one (a consumer on "
                        "the only CPU must never be starved)")
    p.add_argument("--no-realtime", dest="realtime", action="store_const", const="off", help="same as --realtime off")
    p.add_argument("--quiet", action="store_true", help="no status line or summary (warnings still show)")
    p.add_argument("--stats-json", metavar="PATH", help="write the final statistics as JSON")
    p.set_defaults(func=cmd_stream)

def _option_value(key: str, text: str):
    from imu_emulator.live.config import StreamError    # here: importing live costs every command start-up
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        return text
    if not math.isfinite(value):
        raise StreamError(f"--option {key}={text}: expected a finite number")
    return value


def _parse_options(pairs) -> dict:
    from imu_emulator.live.config import StreamError
    options = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise StreamError(f"--option: expected KEY=VALUE, got {pair!r}")
        options[key] = _option_value(key, value)
    return options


def _start(args) -> tuple:
    """(start, wall clock?) of --start-time and the deprecated --epoch-time (= --start-time now, said in one line)."""
    from imu_emulator.live.config import StreamError
    from imu_emulator.output.ros2.conventions import DEFAULT_START_NS
    if args.epoch_time:
        if args.start_time not in (None, "now"):
            raise StreamError("--epoch-time (deprecated) means --start-time now: give one of them")
        print("warning: --epoch-time is deprecated: use --start-time now", file=sys.stderr, flush=True)
        return DEFAULT_START_NS, True
    if args.start_time == "now":
        return DEFAULT_START_NS, True
    return (DEFAULT_START_NS if args.start_time is None else args.start_time), False


def cmd_stream(args) -> int:
    from imu_emulator.output.atomic import AtomicOutput

    # Created now, written when the stream ends: an unwritable path fails before anything streams.
    stats = AtomicOutput(args.stats_json) if args.stats_json else None
    try:
        _stream(args, stats)
    finally:
        if stats is not None:
            stats.discard()     # nothing left behind when the run failed; a no-op after it was written
    return 0


def _stream(args, stats) -> None:
    from imu_emulator.runtime.progress import CompileStatus
    from imu_emulator.runtime.simulation import Simulation
    from imu_emulator.codegen.increments import DEFAULT_NODES
    from imu_emulator.live.config import (RunOptions, StreamConfig, StreamError, needs_increments, needs_truth,
                                          streams_from_tables)
    from imu_emulator.live.streamer import run_streams
    from imu_emulator.live.transport import TargetOptions

    scene = load_scene_with_warnings(args.scene)
    if args.duration is not None and round(args.duration * scene.rate_hz) < 1:
        raise StreamError(f"--duration: {args.duration:g} s is less than one sample at {scene.rate_hz:g} Hz")
    target_options = TargetOptions(link=args.link, pace_baud=args.pace_baud, bitrate=args.bitrate,
                                   data_bitrate=args.data_bitrate, fd=args.fd, blocking=args.speed == 0)
    imu_names = tuple(imu.name for imu in scene.imus)
    if args.format or args.target:
        if not (args.format and args.target):
            raise StreamError("stream: --format and --to go together")
        configs = [StreamConfig(args.imu or imu_names[0], args.format, args.target,
                                _parse_options(args.option), target_options, args.device == "on")]
    else:
        if not scene.streams:
            raise StreamError(f"{args.scene}: no [[stream]] tables; give --format and --to")
        configs = streams_from_tables(scene.streams, imu_names, target_options)
        if args.device == "off":
            configs = [replace(c, device=False) for c in configs]
        if args.imu:
            configs = [c for c in configs if c.imu == args.imu]
            if not configs:
                raise StreamError(f"--imu: no [[stream]] for IMU {args.imu!r}")
    start_ns, wall_clock = _start(args)
    options = RunOptions(speed=args.speed, loop=args.loop, epoch_time=wall_clock, start_ns=start_ns,
                         duration_s=args.duration,
                         count=args.count, quiet=args.quiet, allow_overload=args.allow_overload,
                         realtime=args.realtime, stats_json=stats)
    truth = needs_truth(configs)
    increments = DEFAULT_NODES if needs_increments(configs) else 0
    with CompileStatus(scene, attitude=True, truth=truth, quiet=args.quiet, increments=increments):
        sim = Simulation(scene, truth=truth, increments=increments)
    run_streams(scene, sim, configs, options)
