"""`imu-emulator` command line: one module per subcommand under imu_emulator/commands/."""
from __future__ import annotations

import argparse
import os
import sys

from imu_emulator.commands import register_all
from imu_emulator.errors import ImuEmulatorError


class _Parser(argparse.ArgumentParser):
    """Usage mistakes are bad input like any other: one `error:` line naming the option, exit code 2."""

    def error(self, message):
        self.exit(2, f"error: {message} (see `{self.prog} --help`)\n")


class _VersionAction(argparse.Action):
    """--version, reading the installed version only when asked (importlib.metadata costs ~10 ms of start-up)."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help="show the version and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        import imu_emulator
        print(f"{parser.prog} {imu_emulator.__version__}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="imu-emulator", description="Turn a described motion into IMU output.")
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", required=True)
    register_all(sub)
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
    except BrokenPipeError:
        # The reader of our stdout went away (`imu-emulator models | head`): not an error of ours. Point
        # stdout at /dev/null so the interpreter's final flush does not raise again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
