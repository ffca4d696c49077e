"""Presets: parameter sets of real parts, one TOML file each (`model = "NAME"` in [[imu]] loads one; keys given
beside it override). A file holds `part`, `source` (datasheet, revision, page; what could not be verified is
marked so in the file) and [gyro] / [accel] tables with the keys and datasheet units of a scene's [imu.gyro] /
[imu.accel]. Presets set parameters only; the scene's [effects] still says which effects run."""
from __future__ import annotations

import sys
from functools import lru_cache
from pathlib import Path

from imu_emulator.errors import SceneError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

DIRECTORY = Path(__file__).parent


def names() -> list[str]:
    return sorted(p.stem for p in DIRECTORY.glob("*.toml"))


@lru_cache(maxsize=None)
def _read(name: str) -> dict:
    return tomllib.loads((DIRECTORY / f"{name}.toml").read_text())


def load(name, where: str) -> dict:
    """The preset's tables {"gyro": {...}, "accel": {...}} (copies), or an error naming `where`."""
    if not isinstance(name, str) or name not in names():
        raise SceneError(f"{where}: unknown model {name!r} (known: {', '.join(names())}; see `imu-emulator models`)")
    data = _read(name)
    return {table: dict(data.get(table, {})) for table in ("gyro", "accel")}


def describe(name: str) -> dict:
    """part, source and the tables, for `imu-emulator models`."""
    data = _read(name)
    return {"part": data["part"], "source": data["source"], "gyro": data.get("gyro", {}), "accel": data.get("accel", {})}


def datasheet_lines(name: str, triad: str) -> tuple[float, float]:
    """(N, B) of a preset's triad in SI (noise density, bias instability; B = 0 when the datasheet gives none):
    the Allan-deviation lines N/sqrt(tau) and 0.664 B that its generated output should show."""
    from imu_emulator.scene.units import to_unit
    table = describe(name)[triad]
    unit, n_unit = ("rad/s", "rad/s/sqrt(Hz)") if triad == "gyro" else ("m/s^2", "m/s^2/sqrt(Hz)")
    noise = table.get("noise_density", table.get("arw", table.get("vrw")))
    b = table.get("bias_instability")
    return to_unit(noise, n_unit, name), (to_unit(b, unit, name) if b else 0.0)
