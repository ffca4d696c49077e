"""The subcommands, one module each, found by scanning this package: a module that defines `register(subparsers)`
is a command (others, like shared.py, are helpers). `register` adds its sub-parser and sets `func`; `ORDER` is its
place in `--help`. Heavy imports (numba, sympy, numpy) happen inside the command function, not at import time:
every command's start-up imports every module here."""
from __future__ import annotations

import sys
from types import ModuleType

from imu_emulator import extensions


def find_commands(package) -> tuple[ModuleType, ...]:
    """The command modules of `package` in their declared order. A module that fails to import, a command
    without an integer ORDER, or two with the same, is an error naming the module(s)."""
    found = []
    for module in extensions.modules(package):
        if not callable(getattr(module, "register", None)):
            continue
        if not isinstance(getattr(module, "ORDER", None), int):
            raise ImportError(f"{module.__name__} must define ORDER = <int>, its place in --help")
        found.append(module)
    found.sort(key=lambda module: module.ORDER)
    for before, after in zip(found, found[1:]):
        if before.ORDER == after.ORDER:
            raise ImportError(f"{before.__name__} and {after.__name__} both declare ORDER = {after.ORDER}")
    return tuple(found)


#: the command modules, in the order of `--help`
COMMANDS = find_commands(sys.modules[__name__])


def register_all(subparsers) -> None:
    for module in COMMANDS:
        module.register(subparsers)
