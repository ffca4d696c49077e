"""`imu-emulator kernel`: the generated kernel source of a scene (what the effects compile to), or the table
of effects and their parameters."""
from __future__ import annotations

import sys

from imu_emulator.commands.shared import add_increments_option


ORDER = 100     # place in `imu-emulator --help`


def register(subparsers) -> None:
    p = subparsers.add_parser("kernel", help="print the generated kernel source of a scene, or the effects table")
    p.add_argument("scene", nargs="?", help="scene file (TOML)")
    p.add_argument("--truth", action="store_true", help="the kernel with truth outputs, as generate --truth uses")
    p.add_argument("--no-attitude", action="store_true", help="the kernel without quaternion output, as generate uses")
    add_increments_option(p)
    p.add_argument("--effects", action="store_true", help="print the table of effects and parameters instead")
    p.set_defaults(func=cmd_kernel)


def cmd_kernel(args) -> int:
    from imu_emulator.errors import ImuEmulatorError
    if args.effects:
        from imu_emulator.effects import documentation_table
        print(documentation_table())
        return 0
    if not args.scene:
        raise ImuEmulatorError("kernel: give a scene file (or --effects)")
    from imu_emulator.codegen.generate import generate_source
    from imu_emulator.scene.load import load_scene
    scene = load_scene(args.scene)
    for warning in scene.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    sys.stdout.write(generate_source(scene, attitude=not args.no_attitude, truth=args.truth,
                                     increments=args.increments))
    return 0
