"""What several subcommands share (not a subcommand itself): loading a scene with its warnings shown,
and argparse types that refuse non-finite or out-of-range numbers with a one-line message."""
from __future__ import annotations

import argparse
import math
import sys


def load_scene_with_warnings(path):
    """The scene, its warnings printed to stderr. Always printed, --quiet or not: each warning says that
    something the scene file asks for does not reach the output."""
    from imu_emulator.scene.load import load_scene
    scene = load_scene(path)
    for warning in scene.warnings:
        print(f"warning: {warning}", file=sys.stderr, flush=True)
    return scene


def number(low: float, high: float, integer: bool = False, zero: bool = False):
    """An argparse type: a finite number in [low, high] (an integer if `integer`); `zero` also allows 0."""
    kind = "an integer" if integer else "a number"
    shown = (lambda v: f"{v:,}") if integer else (lambda v: f"{v:g}")
    allowed = f"{kind} from {shown(low)} to {shown(high)}" + (" or 0" if zero else "")

    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {allowed}, got {text!r}") from None
        if (zero and value == 0) or (math.isfinite(value) and low <= value <= high):
            return value
        raise argparse.ArgumentTypeError(f"expected {allowed}, got {text!r}")

    return parse


def start_time(text: str):
    """An argparse type for --start-time: "now" as is (each command decides which instant that is), else ISO 8601
    as UTC Unix ns (imu_emulator.output.ros2.conventions.parse_start_time); a bad value is argparse's one line."""
    from imu_emulator.output.ros2.conventions import parse_start_time
    if text.strip().lower() == "now":
        return "now"
    try:
        return parse_start_time(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_increments_option(parser) -> None:
    """--increments [NODES]: the integrated outputs dtheta, dvel (imu_emulator.codegen.increments); 0 when not given."""
    from imu_emulator.codegen.increments import DEFAULT_NODES, MAX_NODES
    parser.add_argument("--increments", nargs="?", type=number(1, MAX_NODES, integer=True), const=DEFAULT_NODES,
                        default=0, metavar="NODES", help="add the integrated outputs dtheta and dvel over each "
                        f"sample interval (Gauss-Legendre quadrature with NODES nodes, default {DEFAULT_NODES})")
