"""Extension points are folders their registry scans, not lists someone keeps: a module added to the folder is
found, and one that fails to import is an error naming it (never a silent skip)."""
import importlib
import pkgutil
import shutil
import sys

import pytest

from imu_emulator.errors import TargetError
from imu_emulator.live import transport
from imu_emulator.live.transport import TARGET_KINDS, find_kinds, kinds, link_capacity, open_target, parse_target

_LOOP_KIND = '''
from imu_emulator.live.transport.base import LinkCapacity
from imu_emulator.live.transport.spec import TargetKind, TargetSpec


class LoopTransport:
    def __init__(self, path):
        self.path = path


KIND = TargetKind(name="loop", order=99, syntax="loop:NAME", help="a test's loop", carries="serial",
                  parse=lambda text, rest: TargetSpec("loop", text, path=rest),
                  open=lambda spec, format_kind, options: LoopTransport(spec.path),
                  capacity=lambda spec, format_kind, options: LinkCapacity(bytes_per_s=1000.0))
'''


def _package(tmp_path, monkeypatch, name: str, modules: dict[str, str], copy_of=None):
    """A package `name` under tmp_path holding copies of `copy_of`'s modules and `modules` (name -> source)."""
    folder = tmp_path / name
    if copy_of is not None:
        shutil.copytree(copy_of.__path__[0], folder, ignore=shutil.ignore_patterns("__pycache__"))
    else:
        folder.mkdir()
        (folder / "__init__.py").write_text("")
    for module, source in modules.items():
        (folder / f"{module}.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.invalidate_caches()
    return importlib.import_module(name)


_TEST_PACKAGES = ("extra_kinds", "broken_kinds", "extra_commands", "extra_commands2", "broken_commands")


@pytest.fixture(autouse=True)
def _forget_test_packages():
    before = set(sys.modules)
    yield
    for name in set(sys.modules) - before:
        if name.split(".")[0] in _TEST_PACKAGES:
            del sys.modules[name]


def test_every_module_of_kinds_is_a_target_kind():
    modules = {m.name for m in pkgutil.iter_modules(kinds.__path__) if not m.name.startswith("_")}
    assert set(TARGET_KINDS) == modules >= {"pty", "serial", "can", "udp", "file"}
    orders = [kind.order for kind in TARGET_KINDS.values()]     # `targets` lists them in the declared order
    assert orders == sorted(orders) and len(set(orders)) == len(orders)


def test_a_target_kind_added_to_the_folder_is_found_and_used(tmp_path, monkeypatch):
    package = _package(tmp_path, monkeypatch, "extra_kinds", {"loop": _LOOP_KIND}, copy_of=kinds)
    found = find_kinds(package)
    assert list(found) == [*TARGET_KINDS, "loop"]
    monkeypatch.setitem(transport.TARGET_KINDS, "loop", found["loop"])
    spec = parse_target("loop:bench")
    assert (spec.kind, spec.path) == ("loop", "bench")
    assert link_capacity(spec, "serial").bytes_per_s == 1000.0
    assert open_target(spec, "serial").path == "bench"
    with pytest.raises(TargetError, match="a loop target carries serial formats, not can formats"):
        open_target(spec, "can")
    with pytest.raises(TargetError, match=r"loop: expected loop:NAME"):
        parse_target("loop")


@pytest.mark.parametrize("source, message", [
    ("import no_such_module_anywhere\n", r"broken_kinds\.bad needs the package 'no_such_module_anywhere', "
                                        r"which is not installed"),
    ("def oops(:\n", r"broken_kinds\.bad failed to import: SyntaxError"),
    ("KIND = None\n", r"broken_kinds\.bad must define KIND = TargetKind\(name='bad'"),
])
def test_a_target_kind_module_that_fails_is_an_error_naming_it(tmp_path, monkeypatch, source, message):
    package = _package(tmp_path, monkeypatch, "broken_kinds", {"bad": source})
    with pytest.raises(ImportError, match=message):
        find_kinds(package)


def test_a_transport_module_that_fails_to_import_when_opened_is_an_error_naming_its_kind(tmp_path, monkeypatch):
    source = _LOOP_KIND.replace("open=lambda spec, format_kind, options: LoopTransport(spec.path)",
                                "open=lambda spec, format_kind, options: __import__('no_such_transport_module')")
    package = _package(tmp_path, monkeypatch, "extra_kinds", {"loop": source})
    monkeypatch.setitem(transport.TARGET_KINDS, "loop", find_kinds(package)["loop"])
    with pytest.raises(ImportError, match=r"target kind 'loop' \(extra_kinds\.loop\) cannot import its transport: "
                                          r".*no_such_transport_module"):
        open_target(parse_target("loop:x"), "serial")


_COMMAND = '''
ORDER = {order}


def register(subparsers):
    p = subparsers.add_parser("{name}", help="a test's command")
    p.set_defaults(func=lambda args: 0)
'''


def test_every_command_module_is_registered_in_its_declared_order():
    from imu_emulator import commands
    from imu_emulator.cli import build_parser
    modules = {m.name for m in pkgutil.iter_modules(commands.__path__)}
    assert {module.__name__.rpartition(".")[2] for module in commands.COMMANDS} == modules - {"shared"}
    orders = [module.ORDER for module in commands.COMMANDS]
    assert orders == sorted(orders)
    names = [module.__name__.rpartition(".")[2] for module in commands.COMMANDS]
    assert "{" + ",".join(names) + "}" in build_parser().format_usage()


def test_a_command_added_to_the_folder_is_found(tmp_path, monkeypatch):
    from imu_emulator import commands
    from imu_emulator.commands import find_commands
    package = _package(tmp_path, monkeypatch, "extra_commands",
                       {"hello": _COMMAND.format(order=35, name="hello"), "helper": "VALUE = 1\n"})
    found = [module.__name__ for module in find_commands(package)]
    assert found == ["extra_commands.hello"]        # a module without register() is a helper
    package = _package(tmp_path, monkeypatch, "extra_commands2", {"hello": _COMMAND.format(order=35, name="hello")},
                       copy_of=commands)
    names = [module.__name__.rpartition(".")[2] for module in find_commands(package)]
    assert names[:4] == ["generate", "batch", "replay", "hello"]      # ORDER 35: between replay (30) and stream (40)


@pytest.mark.parametrize("modules, message", [
    ({"bad": "import no_such_module_anywhere\n"}, r"broken_commands\.bad needs the package "
                                                  r"'no_such_module_anywhere', which is not installed"),
    ({"bad": "def register(subparsers):\n    pass\n"}, r"broken_commands\.bad must define ORDER"),
    ({"one": _COMMAND.format(order=5, name="one"), "two": _COMMAND.format(order=5, name="two")},
     r"broken_commands\.one and broken_commands\.two both declare ORDER = 5"),
])
def test_a_command_module_that_fails_is_an_error_naming_it(tmp_path, monkeypatch, modules, message):
    from imu_emulator.commands import find_commands
    package = _package(tmp_path, monkeypatch, "broken_commands", modules)
    with pytest.raises(ImportError, match=message):
        find_commands(package)
