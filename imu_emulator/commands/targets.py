"""`imu-emulator targets`: the kinds of stream target."""
from __future__ import annotations


ORDER = 80     # place in `imu-emulator --help`


def register(subparsers) -> None:
    p = subparsers.add_parser("targets", help="list stream target kinds")
    p.set_defaults(func=cmd_targets)


def cmd_targets(args) -> int:
    from imu_emulator.live.transport import TARGET_KINDS     # here: every command's start-up imports this module
    for kind in TARGET_KINDS.values():
        print(f"{kind.syntax:34} {kind.carries + ' formats':15} {kind.help}")
    return 0
