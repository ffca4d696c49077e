"""The docs site's generated tables, read from the registries the program itself uses, and the MkDocs hook that
puts them into the pages (mkdocs.yml `hooks:`).

A page asks for a table with a line `<!-- generated: NAME -->`; NAME is a key of TABLES. The tables are made at
build time, so a registered effect, wire format, device, target, output format or preset is documented the moment
it exists, and an unknown NAME fails the build naming the page. `python tools/docs_tables.py NAME` prints one.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

# The hook runs inside mkdocs, whose working directory need not be the repository: the package is found beside
# this file's folder, as the tests find it.
ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

MARKER = re.compile(r"^<!-- generated: ([a-z_-]+) -->$", re.M)


def _cell(text) -> str:
    # A '|' inside a cell would end it; a newline would end the row.
    return " ".join(str(text).split()).replace("|", "\\|")


def _table(header: tuple[str, ...], rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def effects() -> str:
    from imu_emulator.effects import documentation_table
    return documentation_table()


def companions() -> str:
    from imu_emulator.companions import documentation_table
    return documentation_table()


def wire_formats() -> str:
    import firmware_protocols
    from imu_emulator.commands.formats import size_per_sample
    rows = []
    for name, info in firmware_protocols.formats().items():
        presets = ", ".join(f"`preset={p}`" for p in info.presets) or "—"
        rows.append((f"`{name}`", info.kind, size_per_sample(info), info.description,
                     "yes" if info.device is not None else "—", presets))
    return _table(("format", "link", "per sample (default options)", "what", "device", "presets"), rows)


def wire_axes() -> str:
    from firmware_protocols.axes import declarations
    rows = [(f"`{name}`", body or "undeclared", reference or "none (no attitude)", source or "—")
            for name, (body, reference, source) in declarations().items()]
    return _table(("format", "body axes", "reference", "source"), rows)


def wire_options() -> str:
    import firmware_protocols
    from imu_emulator.commands.formats import device_option_rows, option_rows
    rows = []
    for name, info in firmware_protocols.formats().items():
        rows += [(f"`{name}`", "encoder", f"`{option}`", f"`{default}`", text)
                 for option, default, text in option_rows(info)]
        rows += [(f"`{name}`", "device", f"`{option}`", f"`{default}`", text)
                 for option, default, text in device_option_rows(info)]
    return _table(("format", "taken by", "option", "default", "what"), rows)


def devices() -> str:
    import firmware_protocols
    rows = []
    for name, info in firmware_protocols.formats().items():
        if info.device is None:
            continue
        presets = "; ".join(f"`preset={p}`: {text}" for p, (_, text) in info.presets.items()) or "—"
        rows.append((f"`{name}`", ", ".join(f"`{o}`" for o in info.device_options) or "—", presets))
    return _table(("format", "device-only options", "presets"), rows)


def targets() -> str:
    from imu_emulator.live.transport import TARGET_KINDS
    return _table(("target", "carries", "what"),
                  [(f"`{k.syntax}`", f"{k.carries} formats", k.help) for k in TARGET_KINDS.values()])


def outputs() -> str:
    from imu_emulator.output.formats import by_name
    return _table(("format", "suffix", "what"),
                  [(name, ", ".join(f"`{s}`" for s in record.suffixes), record.description)
                   for name, record in by_name().items()])


def models() -> str:
    from imu_emulator.commands.models import FIGURES, _figure
    from imu_emulator.scene import presets
    rows = []
    for name in presets.names():
        info = presets.describe(name)
        cells = ["; ".join(f for f in (_figure(info[triad], keys) for t, *keys in FIGURES if t == triad)
                           if f != "—") for triad in ("gyro", "accel")]
        rows.append((f"`{name}`", info["part"], *cells, info["source"]))
    return _table(("model", "part", "gyro", "accel", "source"), rows)


def ardupilot_params() -> str:
    # tools/interop is scripts, not a package: its module is loaded from its file, as its own scripts run it.
    import importlib.util
    spec = importlib.util.spec_from_file_location("ardupilot_params", ROOT / "tools" / "interop" / "ardupilot_params.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module      # its dataclasses look their module up there
    spec.loader.exec_module(module)
    devices = {name: (unit.what, unit.format, unit.options) for name, unit in module.DEVICES.items()}
    devices["json"] = ("ArduPilot's own EKF3 on the emulator's IMU (JSON physics backend)", "ardupilot-json", ())
    rows = []
    for name, (what, fmt, options) in devices.items():
        # the compass calibration depends on the scene (minus its hard iron): said once, not as made-up numbers
        if name == "json":
            # the loop rate follows the scene's: shown for the scene the SITL reports fly, and said
            from imu_emulator.scene.load import load_scene
            rate = load_scene(ROOT / "examples" / "sitl_flight.toml").rate_hz
            params = module.device_params(name, json_imu_hz=rate)
            cells = [f"`{k} {v:g}`" for k, v in params.items()]
            cells.append(f"(`SCHED_LOOP_RATE` = half the scene's rate, {rate:g} Hz in `examples/sitl_flight.toml`)")
        else:
            params = {k: v for k, v in module.device_params(name, compass_offsets_mgauss=(1.0, 1.0, 1.0)).items()
                      if not k.startswith("COMPASS_OFS_")}
            cells = [f"`{k} {v:g}`" for k, v in params.items()]
            cells.append("`COMPASS_OFS_X/Y/Z` = minus the scene's magnetometer hard iron, in mGauss")
        emulator = f"`--format {fmt}`" + "".join(f" `--option {o}`" for o in options)
        rows.append((f"`{name}`", what, emulator, ", ".join(cells)))
    return _table(("device", "what", "emulator", "ArduPilot parameters"), rows)


TABLES = {"effects": effects, "companions": companions, "wire-formats": wire_formats, "wire-axes": wire_axes,
          "wire-options": wire_options, "devices": devices, "targets": targets, "outputs": outputs,
          "models": models, "ardupilot-params": ardupilot_params}


def fill(markdown: str, where: str) -> str:
    def table(match):
        name = match.group(1)
        if name not in TABLES:
            raise ValueError(f"{where}: unknown generated table {name!r}; known: {', '.join(TABLES)}")
        return TABLES[name]()
    return MARKER.sub(table, markdown)


def on_page_markdown(markdown, page, config, files):     # the MkDocs hook
    return fill(markdown, page.file.src_path)


if __name__ == "__main__":
    if len(sys.argv) != 2 or sys.argv[1] not in TABLES:
        sys.exit(f"usage: {sys.argv[0]} {'|'.join(TABLES)}")
    print(TABLES[sys.argv[1]]())
