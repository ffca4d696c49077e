"""The registry finds its formats and devices instead of keeping lists: a module dropped into
firmware_protocols/wire_formats (or devices/) is registered without editing anything else, helpers named "_..." are
left alone, and a module that fails to import is an error naming it (never a silent skip)."""
from __future__ import annotations

import importlib
import sys
import textwrap

import pytest

import firmware_protocols.devices
import firmware_protocols.wire_formats
from firmware_protocols import registry

PACKAGES = {"wire_formats": firmware_protocols.wire_formats, "devices": firmware_protocols.devices}

TINY_FORMAT = '''
from firmware_protocols.registry import FormatInfo, register


class TinyEncoder:
    bytes_per_sample = 1

    def encode(self, samples):
        return bytes(len(samples))


register(FormatInfo(name="test-tiny", kind="serial", description="a format no list names", encoder=TinyEncoder,
                    decoder=object, bytes_per_sample=1))
'''

TINY_DEVICE = '''
from firmware_protocols.registry import attach_device


def tiny_device(rate_hz):
    return ("tiny device", rate_hz)


attach_device("test-tiny", tiny_device)
'''


@pytest.fixture
def extra_folders(tmp_path, monkeypatch):
    """A scratch folder added to each scanned package's __path__, and a registry of its own that starts from the
    real one (loaded first, so no real module registers into the copy); all undone afterwards."""
    registry.formats()
    folders = {}
    for key, package in PACKAGES.items():
        folders[key] = tmp_path / key
        folders[key].mkdir()
        monkeypatch.setattr(package, "__path__", [*package.__path__, str(folders[key])])
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(registry, "_loaded", False)
    before = set(sys.modules)
    yield folders
    for name in set(sys.modules) - before:
        parent, _, child = name.rpartition(".")
        if parent in (p.__name__ for p in PACKAGES.values()):
            del sys.modules[name]
            if hasattr(sys.modules[parent], child):
                delattr(sys.modules[parent], child)


def write(folder, name: str, source: str) -> None:
    (folder / f"{name}.py").write_text(textwrap.dedent(source))
    importlib.invalidate_caches()


def test_a_format_and_its_device_dropped_into_the_folders_are_found(extra_folders):
    write(extra_folders["wire_formats"], "tiny", TINY_FORMAT)
    write(extra_folders["devices"], "tiny", TINY_DEVICE)
    known = registry.formats()
    assert "test-tiny" in known and "mavlink-highres" in known
    assert registry.create_device("test-tiny", 100.0) == ("tiny device", 100.0)


def test_helpers_named_with_an_underscore_are_not_scanned(extra_folders):
    write(extra_folders["wire_formats"], "_helper", "raise RuntimeError('a helper must not be imported by the scan')")
    assert "mavlink-highres" in registry.formats()
    assert "firmware_protocols.wire_formats._helper" not in sys.modules


@pytest.mark.parametrize("package", sorted(PACKAGES))
def test_a_module_that_fails_to_import_is_an_error_naming_it(extra_folders, package):
    write(extra_folders[package], "broken", "raise RuntimeError('half-written module')\n")
    with pytest.raises(ImportError) as caught:
        registry.formats()
    message = str(caught.value)
    assert message == f"firmware_protocols.{package}.broken failed to import: RuntimeError: half-written module"
    assert "\n" not in message


def test_a_missing_third_party_package_is_named_with_the_module_that_needs_it(extra_folders):
    write(extra_folders["wire_formats"], "needs_pkg", "import surely_not_an_installed_package.sub\n")
    with pytest.raises(ImportError, match=r"^firmware_protocols\.wire_formats\.needs_pkg needs the package "
                                          r"'surely_not_an_installed_package', which is not installed$"):
        registry.formats()


def test_an_import_of_a_module_of_ours_that_is_gone_is_named(extra_folders):
    write(extra_folders["wire_formats"], "stale", "from firmware_protocols.no_such_module import Encoder\n")
    with pytest.raises(ImportError, match=r"^firmware_protocols\.wire_formats\.stale imports "
                                          r"firmware_protocols\.no_such_module, which does not exist$"):
        registry.formats()
