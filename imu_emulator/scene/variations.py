"""`--vary KEY=DIST`: scene parameters drawn per Monte Carlo realization, and the scene file with them set.

KEY names a value of the scene file: `params.NAME`, `IMU.PATH` (IMU = an IMU's name, e.g. `imu0.gyro.bias_instability`,
`imu1.mounting_rpy_deg`) or `scene.KEY`/`trajectory.KEY`/`attitude.KEY`. DIST is `uniform(LOW, HIGH)` or
`normal(MEAN, SIGMA)`, optionally followed by a unit that [[imu]] parameters accept (`deg/h`, `ug/sqrt(Hz)`).
A parameter of three independent values ("triple": lever_arm_m, mounting_rpy_deg) draws each of the three; any
other draws one value, which the scene's own rules spread (a vector3 parameter's one value is all three axes).

A varied scene is never pasted together as text: the drawn numbers are set in the parsed TOML tables and the
whole scene goes through the scene validator (imu_emulator.scene.load.from_dict) again, with the same checks and
one-line errors as a scene file.
"""
from __future__ import annotations

import copy
import math
import re
import zlib
from dataclasses import dataclass

import numpy as np

from imu_emulator.errors import ImuEmulatorError

_DIST = re.compile(r"^\s*(uniform|normal)\s*\(\s*([^,()]+?)\s*,\s*([^,()]+?)\s*\)\s*(.*?)\s*$")
_KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*(\.[A-Za-z_][A-Za-z0-9_]*)+$")
_TOP_TABLES = ("params", "scene", "trajectory", "attitude")


class VaryError(ImuEmulatorError):
    """A --vary option that cannot be used."""


@dataclass(frozen=True)
class Variation:
    key: str            # as given, e.g. "imu0.gyro.bias_instability"
    dist: str           # "uniform" or "normal"
    a: float            # low or mean
    b: float            # high or sigma
    unit: str           # "" for a plain number in the key's own unit
    count: int = 1      # values drawn per realization (3 for a "triple" parameter)

    def label(self, j: int | None = None) -> str:
        """The summary table's column: "imu1.mounting_rpy_deg[2] [deg]"."""
        return self.key + ("" if j is None else f"[{j}]") + (f" [{self.unit}]" if self.unit else "")

    def center(self):
        """The distribution's middle (mean or midpoint), in the form draw() gives: to check a KEY before a batch."""
        middle = self.a if self.dist == "normal" else (self.a + self.b) / 2
        return [middle] * self.count if self.count > 1 else middle

    def draw(self, root_seed: int, index: int):
        """This variation's value(s) for realization `index`: a float, or a list of `count` floats. The stream
        is keyed on (root seed, realization, KEY), so adding another --vary changes no other value."""
        rng = np.random.default_rng(np.random.SeedSequence(root_seed, spawn_key=(index, zlib.crc32(self.key.encode()))))
        values = rng.uniform(self.a, self.b, self.count) if self.dist == "uniform" else \
            rng.normal(self.a, self.b, self.count)
        return [float(v) for v in values] if self.count > 1 else float(values[0])


def parse(text: str, imu_names) -> Variation:
    """KEY=DIST -> Variation; a VaryError names the option and what is wrong."""
    where = f"--vary {text!r}"
    key, sep, dist = text.partition("=")
    key = key.strip()
    if not sep or not _KEY.match(key):
        raise VaryError(f"{where}: expected KEY=DIST, e.g. imu0.gyro.bias_instability=uniform(1,5) deg/h")
    match = _DIST.match(dist)
    if not match:
        raise VaryError(f"{where}: expected uniform(LOW, HIGH) or normal(MEAN, SIGMA), optionally with a unit")
    name, a, b, unit = match.groups()
    try:
        a, b = float(a), float(b)
    except ValueError:
        raise VaryError(f"{where}: the distribution's arguments must be numbers") from None
    if not (math.isfinite(a) and math.isfinite(b)):
        raise VaryError(f"{where}: the distribution's arguments must be finite")
    if name == "uniform" and not a < b:
        raise VaryError(f"{where}: uniform(LOW, HIGH) needs LOW < HIGH")
    if name == "normal" and not b > 0:
        raise VaryError(f"{where}: normal(MEAN, SIGMA) needs SIGMA > 0")
    head, _, rest = key.partition(".")
    if head in _TOP_TABLES:
        if unit:
            raise VaryError(f"{where}: {head}.* values are plain numbers; units are for [[imu]] parameters")
        return Variation(key, name, a, b, "")
    if head not in imu_names:
        raise VaryError(f"{where}: {head!r} is neither an IMU of the scene ({', '.join(imu_names)}) nor one of "
                        f"{', '.join(_TOP_TABLES)}")
    if unit:
        from imu_emulator.scene import units
        from imu_emulator.errors import SceneError
        try:
            units.to_unit(f"1 {unit}", unit, where)
        except SceneError:
            raise VaryError(f"{where}: {unit!r} is not a unit (e.g. deg/h, ug/sqrt(Hz), deg)") from None
    return Variation(key, name, a, b, unit, count=3 if _shape(rest) == "triple" else 1)


def _shape(path: str) -> str | None:
    from imu_emulator.effects import all_params
    for _, param in all_params():
        table = param.table.partition(".")[2]
        if path in {".".join(filter(None, (table, k))) for k in (param.key, *param.aliases)}:
            return param.shape
    return None         # not a parameter: the scene validator names the key


def apply(raw: dict, variations, values: dict, imu_names) -> dict:
    """A deep copy of the parsed scene file with each variation's drawn value set at its key."""
    raw = copy.deepcopy(raw)
    for variation in variations:
        value = values[variation.key]
        if variation.unit:
            value = [f"{v!r} {variation.unit}" for v in value] if isinstance(value, list) else \
                f"{value!r} {variation.unit}"
        head, *path = variation.key.split(".")
        if head in _TOP_TABLES:
            table = raw.setdefault(head, {})
        else:
            imus = raw.get("imu")
            imus = [imus] if isinstance(imus, dict) else imus
            table = imus[list(imu_names).index(head)]
        for part in path[:-1]:
            table = table.setdefault(part, {})
            if not isinstance(table, dict):
                raise VaryError(f"--vary {variation.key}: {part} is not a table in the scene")
        table[path[-1]] = value
    return raw
