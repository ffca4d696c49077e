"""The documentation site builds with `mkdocs build --strict` (a broken link, a missing page or an unknown generated
table fails it), and its generated tables, read back from the built HTML, list what the program registers at the
time of the test: every effect and each of its parameters, every companion sensor parameter, every wire format,
device, stream target, output format and sensor preset. The registries are asked here, not through the hook."""
import html
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.paths import REPO
from tests.support.timing import scaled

pytestmark = pytest.mark.subprocess

ROOT = REPO

pytest.importorskip("mkdocs", reason="the docs extra: pip install '.[docs]'")


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                            cwd=ROOT, capture_output=True, text=True, timeout=scaled(600),
                            env={**__import__("os").environ, "NO_MKDOCS_2_WARNING": "1"})
    assert result.returncode == 0, result.stderr[-4000:]
    return out


def _cells(site: Path, page: str, column: int = 0) -> list[str]:
    """The text of one column of every table row of a built page (tags stripped, entities decoded)."""
    text = (site / page / "index.html").read_text()
    cells = []
    for row in re.findall(r"<tr>(.*?)</tr>", text, re.S):
        found = re.findall(r"<td[^>]*>(.*?)</td>", row, re.S)
        if len(found) > column:
            cells.append(html.unescape(re.sub(r"<[^>]+>", "", found[column])).strip())
    return cells


def test_every_registered_effect_and_parameter_is_in_the_effects_table(site):
    from imu_emulator.effects import EFFECTS
    effects = _cells(site, "sensor-errors", 0)
    parameters = _cells(site, "sensor-errors", 2)
    assert set(EFFECTS) <= set(effects), set(EFFECTS) - set(effects)
    for effect in EFFECTS.values():
        for param in effect.params:
            assert any(f"[{param.table}] {param.key}" in cell for cell in parameters), (effect.name, param.key)


def test_every_companion_parameter_is_in_the_companions_table(site):
    from imu_emulator.companions import COMPANIONS
    rows = set(zip(_cells(site, "companions", 0), _cells(site, "companions", 1)))
    for companion in COMPANIONS.values():
        for key in [p.key for p in companion.params] + list(companion.extra):
            assert (f"[imu.{companion.name}]", key) in rows, (companion.name, key)


def test_every_wire_format_device_and_target_is_listed(site):
    import firmware_protocols
    from imu_emulator.live.transport import TARGET_KINDS
    known = firmware_protocols.formats()
    formats = _cells(site, "wire-formats", 0)
    # the formats table, the axes table and the options table each name formats in their first column
    assert formats.count("mavlink-highres") >= 2
    for name, info in known.items():
        assert formats.count(name) >= 2, name           # in the formats table and in the axes table
    devices = [name for name, info in known.items() if info.device is not None]
    assert devices and all(name in formats for name in devices)
    page = (site / "wire-formats" / "index.html").read_text()
    for name in devices:
        for preset in known[name].presets:
            assert html.escape(f"preset={preset}") in page or f"preset={preset}" in page, (name, preset)
    assert {kind.syntax for kind in TARGET_KINDS.values()} <= set(_cells(site, "streaming", 0))


def test_output_formats_and_presets_are_listed(site):
    from imu_emulator.output.formats import FORMATS
    from imu_emulator.scene import presets
    suffixes = " ".join(_cells(site, "outputs", 1))
    assert all(suffix in suffixes for suffix in FORMATS)
    assert set(presets.names()) <= set(_cells(site, "sensor-errors", 0))


def test_the_api_reference_documents_the_public_api(site):
    import firmware_protocols
    import imu_emulator
    page = (site / "api" / "index.html").read_text()
    ids = set(re.findall(r'id="([\w.]+)"', page))
    for name in ("load_scene", "simulate", "Simulation", "SampleBlock"):
        assert name in imu_emulator.__all__
        assert any(i.endswith("." + name) for i in ids), name
    for name in ("Samples", "create_encoder", "create_decoder", "formats"):
        assert name in firmware_protocols.__all__
        assert any(i.endswith("." + name) for i in ids), name


def test_no_page_links_outside_the_repository():
    # ../shared/specs and the like exist only on the development machines: a reader of the site cannot follow them.
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        text = path.read_text()
        assert "shared/specs" not in text and "](../../" not in text, path


def test_a_page_asking_for_an_unknown_table_fails_the_build_naming_it():
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import docs_tables
    finally:
        sys.path.remove(str(ROOT / "tools"))
    with pytest.raises(ValueError, match=r"guide\.md: unknown generated table 'efects'"):
        docs_tables.fill("text\n<!-- generated: efects -->\n", "guide.md")
    # a cell holding '|' stays one cell: the escaped bar is what Markdown tables take
    assert docs_tables._table(("a", "b"), [("x|y", "z")]).splitlines()[-1] == "| x\\|y | z |"
