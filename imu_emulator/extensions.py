"""Extension points find their own modules: effects, output formats, transport kinds, commands, and
firmware_protocols' wire formats and devices. Each is a package whose every module (a name starting with "_" is
a helper) declares one record; nobody keeps a list, so adding one is adding its module.

A module that fails to import is an error naming it, never a silent skip: a missing third-party package is named
as such, so a user can tell an optional dependency from a bug. A leaf: it imports nothing of the packages it scans.
"""
from __future__ import annotations

import importlib
from types import ModuleType


def modules(package: ModuleType | str, skip: tuple[str, ...] = ()) -> list[ModuleType]:
    """Every module of `package` (not starting with "_", not in `skip`), imported, in name order."""
    import pkgutil      # here: importing a package that scans lazily (firmware_protocols) stays cheap
    if isinstance(package, str):
        package = importlib.import_module(package)
    names = sorted(info.name for info in pkgutil.iter_modules(package.__path__))
    return [load(f"{package.__name__}.{name}") for name in names if not name.startswith("_") and name not in skip]


def load(name: str) -> ModuleType:
    """Import one extension module; any failure is an ImportError whose one-line message names it."""
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        missing = exc.name or str(exc)
        if missing.split(".")[0] in ("firmware_protocols", "imu_emulator"):
            raise ImportError(f"{name} imports {missing}, which does not exist") from exc
        raise ImportError(f"{name} needs the package {missing.split('.')[0]!r}, which is not installed") from exc
    except Exception as exc:
        detail = str(exc).strip().splitlines()
        why = f"{type(exc).__name__}: {detail[0]}" if detail else type(exc).__name__
        raise ImportError(f"{name} failed to import: {why}") from exc


def declared(package: ModuleType | str, attribute: str, record: type, named: bool = True) -> list:
    """The `attribute` record (of type `record`) every module of `package` declares. A module without one, or
    (with `named`) whose record's `name` is not the module's own name, is an ImportError naming the module."""
    found = []
    for module in modules(package):
        value = getattr(module, attribute, None)
        short = module.__name__.rpartition(".")[2]
        if not isinstance(value, record) or (named and value.name != short):
            name = f"name={short!r}, ..." if named else "..."
            raise ImportError(f"{module.__name__} must define {attribute} = {record.__name__}({name})")
        found.append(value)
    return found
