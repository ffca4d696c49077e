"""`--vary KEY=DIST`, `KEY+=DIST`, `KEY*=DIST`: scene parameters drawn per Monte Carlo realization, and the scene
file with them set.

`=` sets the value to the draw; `+=` adds the draw to the scene's own value (a mounting known to half a degree:
`imu1.mounting_rpy_deg+=normal(0,0.5) deg` keeps the scene's (180, 0, 90) and perturbs it); `*=` multiplies the
scene's value by the draw, a plain number (`normal(1,0.01)`: a 1 % spread). The scene's value is the validated
one (its own key, its datasheet preset or the parameter's default), in the key's unit; a draw with a unit is
converted to that unit before it is added. `+=`/`*=` take parameters of one value or three (scalar, per-axis,
triple) and plain numbers of the scene's tables.

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
    op: str = "="       # "=" sets, "+=" perturbs, "*=" scales the scene's value
    base: object = None  # += and *=: the scene's value in the key's unit (a float, or a tuple of 3)
    to_key_unit: float = 1.0  # +=: the draw's unit in the key's unit ("deg/h" for a rad/s key: pi/180/3600)

    @property
    def name(self) -> str:
        """The draw's name in the batch's records: KEY for `=` (as before operators existed), KEY+= / KEY*=."""
        return self.key if self.op == "=" else self.key + self.op

    def label(self, j: int | None = None) -> str:
        """The summary table's column: "imu1.mounting_rpy_deg+=[2] [deg]"."""
        return self.name + ("" if j is None else f"[{j}]") + (f" [{self.unit}]" if self.unit else "")

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


def parse(text: str, scene, raw: dict | None = None) -> Variation:
    """KEY=DIST, KEY+=DIST or KEY*=DIST -> Variation, for `scene` (the validated base Scene: its IMUs' names and,
    for += and *=, its values) parsed from the scene file `raw` (the numbers of its top tables); a VaryError names
    the option and what is wrong."""
    where = f"--vary {text!r}"
    key, op, dist = _split(text)
    if not op or not _KEY.match(key):
        raise VaryError(f"{where}: expected KEY=DIST, KEY+=DIST or KEY*=DIST, e.g. "
                        "imu0.gyro.bias_instability=uniform(1,5) deg/h")
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
    if op == "*=" and unit:
        raise VaryError(f"{where}: *= scales the scene's value by a plain number (e.g. normal(1,0.01)), "
                        f"not by {unit!r}")
    imu_names = scene.imu_names
    head, _, rest = key.partition(".")
    if head in _TOP_TABLES:
        if unit:
            raise VaryError(f"{where}: {head}.* values are plain numbers; units are for [[imu]] parameters")
        base = None if op == "=" else _table_number(raw or {}, key, where)
        return Variation(key, name, a, b, "", op=op, base=base)
    if head not in imu_names:
        raise VaryError(f"{where}: {head!r} is neither an IMU of the scene ({', '.join(imu_names)}) nor one of "
                        f"{', '.join(_TOP_TABLES)}")
    param = _param(rest)
    scale = 1.0
    if unit:
        from imu_emulator.scene import units
        try:
            units.quantity(unit)
        except ValueError as exc:
            raise VaryError(f"{where}: {unit!r} is not a unit: {exc} (e.g. deg/h, ug/sqrt(Hz), deg)") from None
        if param is not None and op == "+=":
            from imu_emulator.errors import SceneError
            try:
                scale = units.to_unit(f"1 {unit}", param.unit, where)
            except SceneError as exc:
                raise VaryError(str(exc)) from None
    count = 3 if param is not None and param.shape == "triple" else 1
    if op == "=":
        return Variation(key, name, a, b, unit, count=count)
    if param is None:
        raise VaryError(f"{where}: {rest!r} is not a parameter of an [[imu]] table ({op} needs the scene's value)")
    if param.shape not in ("scalar", "vector3", "triple"):
        raise VaryError(f"{where}: {op} works on parameters of one value or three; {rest} is a {param.shape} "
                        f"parameter (set it with =)")
    base = scene.imus[list(imu_names).index(head)].values[param.path]
    return Variation(key, name, a, b, unit, count=count, op=op, base=base, to_key_unit=scale)


def _split(text: str) -> tuple[str, str, str]:
    """KEY, operator, DIST: the operator is the first "=" with the character before it ("+=", "*=")."""
    key, sep, dist = text.partition("=")
    if not sep:
        return key.strip(), "", dist
    op = "="
    if key.endswith(("+", "*")):
        op, key = key[-1] + "=", key[:-1]
    return key.strip(), op, dist


def _table_number(raw: dict, key: str, where: str) -> float:
    """The number at `key` of the scene file's [params]/[scene]/[trajectory]/[attitude] table (+= and *=)."""
    value = raw
    for part in key.split("."):
        value = value.get(part) if isinstance(value, dict) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise VaryError(f"{where}: {key} is not a number in the scene file ({key} needs one to add to or scale)")
    return float(value)


def _param(path: str):
    """The effects' parameter that `path` (as in an [[imu]] table: "gyro.noise_density", an alias, "lever_arm_m")
    names, or None (the scene validator then names the key)."""
    from imu_emulator.effects import all_params
    for _, param in all_params():
        table = param.table.partition(".")[2]
        if path in {".".join(filter(None, (table, k))) for k in (param.key, *param.aliases)}:
            return param
    return None


def apply(raw: dict, variations, values: dict, imu_names) -> dict:
    """A deep copy of the parsed scene file with each variation's value set at its key: the draw (=), the scene's
    value plus the draw in the key's unit (+=) or times the draw (*=). `values` holds the draws by Variation.name."""
    raw = copy.deepcopy(raw)
    for variation in variations:
        value = _value(variation, values[variation.name])
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


def _value(variation: Variation, drawn):
    """What goes into the scene file for one variation's draw (a number or text with its unit; a list of three)."""
    if variation.op == "=":
        if variation.unit:
            return [f"{v!r} {variation.unit}" for v in drawn] if isinstance(drawn, list) else \
                f"{drawn!r} {variation.unit}"
        return drawn
    base = variation.base
    if isinstance(base, tuple):
        # a per-axis parameter adds its one draw to each axis; a triple adds one draw per element
        draws = drawn if isinstance(drawn, list) else [drawn] * len(base)
        return [_combine(variation, b, d) for b, d in zip(base, draws)]
    return _combine(variation, base, drawn)


def _combine(variation: Variation, base: float, drawn: float) -> float:
    return base + drawn * variation.to_key_unit if variation.op == "+=" else base * drawn
