"""The table of output formats (imu_emulator.output.formats): found by scanning the package, every suffix once,
and a module that breaks the rule is an error naming it, never a silent skip."""
import importlib
import sys

import pytest

from imu_emulator.output import formats
from imu_emulator.output.base import Format


def test_the_table_holds_every_format_once_by_suffix():
    assert set(formats.SUFFIXES) == {".csv", ".npz", ".parquet", ".mcap"}
    assert all(isinstance(record, Format) and suffix in record.suffixes
               for suffix, record in formats.FORMATS.items())
    assert formats.format_of("RUN.PARQUET").name == "Parquet" and formats.format_of("run.txt") is None


def test_check_path_names_the_suffixes_it_takes(tmp_path):
    assert formats.check_path(tmp_path / "o.csv") == tmp_path / "o.csv"
    with pytest.raises(Exception, match=r"output must end in .*\.parquet"):
        formats.check_path(tmp_path / "o.txt")


@pytest.mark.parametrize("source, message", [
    ("raise RuntimeError('boom')\n", r"imu_emulator\.output\.formats\.broken failed to import: RuntimeError: boom$"),
    ("X = 1\n", r"imu_emulator\.output\.formats\.broken must define FORMAT"),
])
def test_a_format_module_that_fails_is_an_error_naming_it(tmp_path, monkeypatch, source, message):
    (tmp_path / "broken.py").write_text(source)
    monkeypatch.setattr(formats, "__path__", [*formats.__path__, str(tmp_path)])
    try:
        with pytest.raises(ImportError, match=message):
            formats._discover()
    finally:
        sys.modules.pop("imu_emulator.output.formats.broken", None)
        importlib.invalidate_caches()
