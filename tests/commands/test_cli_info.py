"""`--version` and `formats --details`: what a newcomer asks the tool before running anything."""
import subprocess
import sys
from importlib.metadata import version

import pytest

import firmware_protocols as fp
from firmware_protocols.registry import device_option_defaults, option_defaults
from imu_emulator.cli import main
from imu_emulator.commands.formats import device_option_rows, option_rows
from tests.support.paths import REPO



def test_version_is_the_installed_distributions():
    out = subprocess.run([sys.executable, "-m", "imu_emulator", "--version"], capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 0
    assert out.stdout.split() == ["imu-emulator", version("imu-emulator")]


def test_package_version_is_the_metadatas_and_says_when_there_is_none(monkeypatch):
    import importlib.metadata

    import imu_emulator
    assert imu_emulator.__version__ == version("imu-emulator")

    def not_installed(name):
        raise importlib.metadata.PackageNotFoundError(name)
    monkeypatch.setattr(importlib.metadata, "version", not_installed)
    assert imu_emulator.__version__ == "unknown (not installed)"


@pytest.mark.parametrize("name", list(fp.formats()))
def test_details_list_exactly_what_the_encoder_accepts(name):
    """Every declared option is a keyword of the encoder with the default the listing prints; every keyword of the
    encoder left out of the listing is one this format refuses (e.g. `id` for a message without an id field)."""
    info = fp.get(name)
    accepted = option_defaults(info)
    assert set(info.options) <= set(accepted)
    rows = {option: default for option, default, _ in option_rows(info)}
    assert set(rows) == set(info.options)
    for option in info.options:
        default = accepted[option]
        shown = (tuple(default.axes), tuple(default.signs)) if hasattr(default, "axes") else default
        assert rows[option] == repr(shown)
        # the printed default is one the encoder accepts explicitly
        fp.create_encoder(name, **{option: default})
    for option in set(accepted) - set(info.options):
        with pytest.raises(ValueError):
            fp.create_encoder(name, **{option: 1})
    # signature parameters are the only keywords: anything else is refused
    with pytest.raises(TypeError):
        fp.create_encoder(name, no_such_option=1)


def test_details_command_prints_every_option(capsys):
    assert main(["formats", "--details"]) == 0
    out = capsys.readouterr().out
    for name, info in fp.formats().items():
        assert name in out
        for option, default, text in option_rows(info):
            assert f"    {option} " in out and default in out and text in out


@pytest.mark.parametrize("name", [name for name, info in fp.formats().items() if info.device is not None])
def test_details_list_the_device_options_the_device_takes(name, capsys):
    """Every option only the device takes (its declaration's device_options) is listed under the format with the
    default of the device class's signature; the device accepts it with that default, and refuses a name it does not
    declare, so the listing is what `--option` on a stream with the device can give."""
    info = fp.get(name)
    accepted = device_option_defaults(info)
    assert info.device_options and set(info.device_options) <= set(accepted)
    assert main(["formats", "--details", name]) == 0
    out = capsys.readouterr().out
    assert "device options" in out
    for option, default, text in device_option_rows(info):
        assert default == repr(accepted[option])
        assert any(line.split()[:3] == [option, "default", default.split()[0]] and line.rstrip().endswith(text)
                   for line in out.splitlines()), option
        info.device(200.0, **{option: accepted[option]})       # the printed default, given explicitly
    with pytest.raises(TypeError):
        info.device(200.0, no_such_option=1)


def test_details_of_one_format_and_of_an_unknown_one(capsys):
    assert main(["formats", "--details", "j1939"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0].startswith("j1939") and "mavlink" not in out and "latency_s" in out
    assert main(["formats", "--details", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: formats --details: unknown format 'nope'") and err.count("\n") == 1
