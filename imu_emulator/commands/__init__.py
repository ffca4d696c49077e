"""The subcommands, one module each. A module has `register(subparsers)`, which adds its sub-parser and
sets `func`; heavy imports (numba, sympy) happen inside the command function, not at import time.
A new subcommand is a module here and its name in COMMANDS (the order is the order of `--help`)."""
from __future__ import annotations

from imu_emulator.commands import align, batch, check, formats, generate, kernel, models, plot, replay, stream, targets

COMMANDS = (generate, batch, replay, stream, check, plot, formats, targets, align, kernel, models)


def register_all(subparsers) -> None:
    for module in COMMANDS:
        module.register(subparsers)
