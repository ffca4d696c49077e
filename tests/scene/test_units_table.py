"""Every unit of the scene's unit table (imu_emulator.scene.units.UNITS), its prefixed, plural and root forms,
against pint's own default registry: the table replaced pint at run time (start-up), pint stays the oracle here.

Where the datasheet symbol means something else to pint, the test spells pint's name for the datasheet's meaning:
"g" is standard gravity (pint: gram), "dps"/"dph" degrees per second/hour (pint has neither), "degC" a temperature
difference (pint: an offset unit, delta_degC), gauss through pint's "Gaussian" context (pint's gauss is the CGS unit
of another dimension; the context converts with CODATA's mu0, 7e-11 relative from the defined 1e-4 T)."""
import math
import re

import pint
import pytest

from imu_emulator.errors import SceneError
from imu_emulator.scene.units import DIMENSIONS, UNITS, to_unit, unit
from tests.support.paths import REPO

REG = pint.UnitRegistry()

PINT_SPELLING = {"g": "standard_gravity", "g0": "standard_gravity", "dps": "degree / second",
                 "dph": "degree / hour", "degC": "delta_degC", "°C": "delta_degC"}
GAUSSIAN = {"G", "gauss", "mG"}
# Our dimensions in pint's base dimensions (pint counts angle as dimensionless)
IN_PINT = {"length": {"[length]": 1}, "time": {"[time]": 1}, "angle": {}, "temperature": {"[temperature]": 1},
           "tesla": {"[mass]": 1, "[current]": -1, "[time]": -2},
           "pascal": {"[mass]": 1, "[length]": -1, "[time]": -2}}

# Forms built from the table by its rules, with pint's spelling of the same thing
DERIVED = {
    "cm": "cm", "mm": "mm", "km": "km", "kft": "kft", "ms": "ms", "us": "us", "µs": "µs", "μs": "μs", "ns": "ns",
    "kHz": "kHz", "mrad": "mrad", "urad": "urad", "mdeg": "millidegree", "nT": "nT", "uT": "uT", "mT": "mT",
    "ug": "1e-6 standard_gravity", "µg": "1e-6 standard_gravity", "mg": "1e-3 standard_gravity",
    "mdps": "1e-3 degree / second", "mG": "milligauss", "mbar": "mbar", "kPa": "kPa", "millisecond": "millisecond", "kilometer": "kilometer",
    "hours": "hour", "minutes": "minute", "seconds": "second", "degrees": "degree", "radians": "radian",
    "knots": "knot", "meters": "meter",
    "rtHz": "hertz ** 0.5", "rt-Hz": "hertz ** 0.5", "rth": "hour ** 0.5", "rt-hr": "hour ** 0.5",
}


def _pint_base(spelling: str, name: str):
    quantity = REG.Quantity(spelling) if any(c in spelling for c in " */") or spelling[0].isdigit() \
        else REG.Quantity(1, spelling)
    if name in GAUSSIAN:
        return quantity.to("tesla", "Gaussian").magnitude, IN_PINT["tesla"]
    base = quantity.to_base_units()
    return base.magnitude, {k: v for k, v in base.dimensionality.items() if v}


def _ours_in_pint(q) -> dict:
    dims: dict[str, float] = {}
    for name, exponent in zip(DIMENSIONS, q.dims):
        for base, power in IN_PINT[name].items():
            dims[base] = dims.get(base, 0) + power * exponent
    return {k: v for k, v in dims.items() if v}


@pytest.mark.parametrize("name, spelling", [(n, PINT_SPELLING.get(n, n)) for n in sorted(UNITS)]
                         + sorted(DERIVED.items()))
def test_unit_against_pint(name, spelling):
    factor, dims = _pint_base(spelling, name)
    q = unit(name.replace("rt-", "rt"))
    assert q.factor == pytest.approx(factor, rel=1e-9 if name in GAUSSIAN else 1e-12)
    assert _ours_in_pint(q) == pytest.approx(dims)


@pytest.mark.parametrize("text, key_unit, expected", [
    # the units users wrote that the table did not have (issue 25), each as a datasheet prints it
    ("2 cm", "m", 0.02),
    ("1000 ft", "m", 304.8),
    ("5 dph", "rad/s", 5 * math.pi / 180 / 3600),
    ("0.004 deg/s/rt-Hz", "rad/s/sqrt(Hz)", 0.004 * math.pi / 180),
    ("0.15 deg/rt-hr", "rad/s/sqrt(Hz)", 0.15 * math.pi / 180 / 60),
    ("20 knot", "m/s", 20 * 1852 / 3600),
    ("0.5 gauss", "T", 0.5e-4),
    ("0.25 deg/sqrt(h)", "rad/s/sqrt(Hz)", 0.25 * math.pi / 180 / 60),
])
def test_new_units_in_values(text, key_unit, expected):
    assert to_unit(text, key_unit, "k") == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("text, named", [("5 furlongs", "'furlongs'"), ("0.1 deg/s/rt-Hertz", "'rtHertz'"),
                                         ("3 Gs", "'Gs'"), ("2 mph", "'mph'")])
def test_unknown_unit_is_named_in_one_line(text, named):
    with pytest.raises(SceneError, match=r"^imu\[0\]\.gyro\.bias: cannot read ") as info:
        to_unit(text, "rad/s", "imu[0].gyro.bias")
    assert f"unknown unit {named}" in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("text, reason", [("1 deg/0", "division by zero"), ("1 0^-1 deg", "division by zero"),
                                          ("sqrt(-4) deg", "square root of a negative number")])
def test_arithmetic_errors_are_one_line(text, reason):
    with pytest.raises(SceneError, match=reason):
        to_unit(text, "rad", "k")


def test_every_parameters_unit_reads():
    """The keys' own units (the effects' records) go through the same table: a unit missing from it would fail
    every scene that gives that key as text."""
    from imu_emulator.effects import all_params
    from imu_emulator.scene.units import quantity
    for _, param in all_params():
        for alternative in param.unit.split("|"):
            quantity(alternative)


# The unit context the scene's parser used while it ran on pint (commit 35a2177, imu_emulator/scene/units.py)
PINT_CONTEXT = """
pi = 3.1415926535897932384626433832795028841971693993751 = π
milli- = 1e-3 = m-
micro- = 1e-6 = u- = µ- = μ-
nano- = 1e-9 = n-
kilo- = 1e3 = k-
meter = [length] = m
second = [time] = s = sec
radian = [angle] = rad
minute = 60 * second = min
hour = 60 * minute = h = hr
hertz = 1 / second = Hz
degree = pi / 180 * radian = deg = °
degree_per_second = degree / second = dps
standard_gravity = 9.80665 * meter / second ** 2 = g = g0
percent = 0.01 = %
kelvin = [temperature] = K = degC
ppm = 1e-6
"""
ROOT = REPO
PROSE = {"6 s per 60 000"}      # a comment's words in quotes, not a value


def _documented_values() -> list[str]:
    """Every quoted "NUMBER unit..." of the README, the docs site's pages and the tables it generates from the
    effect and companion records, the example scenes and the presets."""
    from imu_emulator.companions import documentation_table as companion_table
    from imu_emulator.effects import documentation_table as effect_table
    files = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "examples").glob("*.toml")),
             *sorted((ROOT / "imu_emulator" / "scene" / "presets").glob("*.toml"))]
    texts = [path.read_text() for path in files] + [effect_table(), companion_table()]
    found = set()
    for text in texts:
        found |= set(re.findall(r'"(-?[0-9][0-9.eE+-]* *[^"0-9 ,=][^"]*)"', text))
    return sorted(found - PROSE)


def _pint_text(text: str) -> str:
    text = text.replace("²", "**2").replace("√", "sqrt")
    text = re.sub(r"sqrt\(([^()]*)\)", r"(\1)**0.5", text)
    return re.sub(r"sqrt(\w+)", r"(\1)**0.5", text)


def test_documented_values_read_bit_for_bit_as_with_pint():
    """Each documented value in each key unit it has the dimension of: the same double as pint's evaluation in the
    old unit context (so the switch changed no output byte), and read wherever pint read it."""
    from imu_emulator.effects import all_params
    reg = pint.UnitRegistry(None)
    reg.load_definitions(PINT_CONTEXT.strip().splitlines())
    key_units = sorted({a for _, p in all_params() for a in p.unit.split("|")})
    compared = 0
    for text in _documented_values():
        for key_unit in key_units:
            try:
                expected = float((reg.Quantity(_pint_text(text)) / reg.Quantity(_pint_text(key_unit)))
                                 .to(reg.dimensionless).magnitude)
            except (pint.DimensionalityError, pint.UndefinedUnitError, ValueError, TypeError):
                expected = None
            if expected is None:
                continue
            assert to_unit(text, key_unit, "k") == expected, (text, key_unit)
            compared += 1
    assert compared > 50
