"""Parameter values as datasheets print them ("0.2 deg/sqrt(h)", "120 ug/sqrt(Hz)", "500 ppm") -> SI floats.

A small grammar over a fixed table of units (UNITS), rather than pint: importing pint (and through it dask, babel,
scipy) doubled the start-up of a warm `generate` of a scene written with units (tools/bench_startup_against.py),
and the table is all a scene needs. tests/scene/test_units_table.py checks every entry's factor and dimension against
pint's own registry, so pint stays the oracle without being imported here.

Datasheets and pint disagree on one symbol: "g" is standard gravity here (so "ug", "mg" are micro-g and milli-g),
never gram. Angle is a dimension of its own, so "5 m/s" given for a gyro key is an error rather than silently
rad/s. Plain numbers are taken in the key's own unit (SI unless the key's name says otherwise, e.g.
mounting_rpy_deg).
"""
from __future__ import annotations

import math
import re
from functools import lru_cache

import numpy as np

from imu_emulator.errors import SceneError

# The dimensions a value may carry, in this order in a _Quantity's exponents. Angle counts as one (unlike in SI and
# pint) so that a gyro key refuses metres per second; "tesla" stands for magnetic flux density as a whole and
# "pascal" for pressure (the barometer's keys), neither spelled out in mass.
DIMENSIONS = ("length", "time", "angle", "temperature", "tesla", "pascal")
_DEG = math.pi / 180
_G0 = 9.80665                 # standard gravity, m/s^2 (CGPM 1901; pint's standard_gravity)


def _dims(**exponents) -> tuple:
    return tuple(float(exponents.get(name, 0)) for name in DIMENSIONS)


# name -> (factor to SI, dimension exponents). Aliases share an entry; each is checked against pint by the test.
_TABLE = {
    ("m", "meter", "metre"): (1.0, _dims(length=1)),
    ("ft", "foot", "feet"): (0.3048, _dims(length=1)),                    # international foot (1959)
    ("s", "sec", "second"): (1.0, _dims(time=1)),
    ("min", "minute"): (60.0, _dims(time=1)),
    ("h", "hr", "hour"): (3600.0, _dims(time=1)),
    ("day",): (86400.0, _dims(time=1)),
    ("yr", "year"): (365.25 * 86400.0, _dims(time=1)),                     # Julian year, as pint's
    ("Pa", "pascal"): (1.0, _dims(pascal=1)),
    ("hPa", "hectopascal"): (100.0, _dims(pascal=1)),
    ("bar",): (1e5, _dims(pascal=1)),
    ("Hz", "hertz"): (1.0, _dims(time=-1)),
    ("rad", "radian"): (1.0, _dims(angle=1)),
    ("deg", "degree", "°"): (_DEG, _dims(angle=1)),
    ("dps",): (_DEG, _dims(angle=1, time=-1)),                             # degree per second
    ("dph",): (_DEG / 3600, _dims(angle=1, time=-1)),                      # degree per hour
    ("g", "g0"): (_G0, _dims(length=1, time=-2)),                          # standard gravity, never gram
    ("knot", "kn", "kt"): (1852 / 3600, _dims(length=1, time=-1)),         # nautical mile (1852 m) per hour
    ("K", "kelvin", "degC", "°C"): (1.0, _dims(temperature=1)),            # temperature differences: K = degC
    ("T", "tesla"): (1.0, _dims(tesla=1)),
    ("G", "gauss"): (1e-4, _dims(tesla=1)),                                # not "Gs": pint's gigasecond
    ("%", "percent"): (1e-2, _dims()),
    ("ppm",): (1e-6, _dims()),
    ("dimensionless",): (1.0, _dims()),                                   # the unit of ratios' keys
    ("pi", "π"): (math.pi, _dims()),
}
UNITS = {name: entry for names, entry in _TABLE.items() for name in names}
# Prefixes go before any unit of the table ("mg", "ug", "mdps", "kHz", "cm", "nT"); their long forms before
# long names ("millisecond"). "rt" (also "rt-") before a unit is its square root, as in "deg/s/rt-Hz".
PREFIXES = {"m": 1e-3, "u": 1e-6, "µ": 1e-6, "μ": 1e-6, "n": 1e-9, "k": 1e3, "c": 1e-2,
            "milli": 1e-3, "micro": 1e-6, "nano": 1e-9, "kilo": 1e3, "centi": 1e-2}
# Plurals of the long names ("hours", "degrees", "knots"), as pint reads them
_PLURAL = {name + "s": name for name in UNITS if len(name) > 3 and name.isalpha() and name != "feet"}
# Each unit's canonical word (the first of its aliases): "30 deg" in a key of unit "degree" cancels exactly
_CANONICAL = {name: names[0] for names in _TABLE for name in names}
_SHORT_PREFIX = {"µ": "u", "μ": "u", "milli": "m", "micro": "u", "nano": "n", "kilo": "k", "centi": "c"}


class _Quantity:
    """A number and its units, as canonical unit words with exponents: units are cancelled by name before any
    factor is applied, as pint does, so that "30 deg" read in degrees is exactly 30 and "0.2 %" in percent 0.2."""
    __slots__ = ("magnitude", "units")

    def __init__(self, magnitude: float, units: dict):
        self.magnitude, self.units = magnitude, units

    def __mul__(self, other):
        if isinstance(other, _Quantity):
            return _Quantity(self.magnitude * other.magnitude, _merged(self.units, other.units, 1))
        return _Quantity(self.magnitude * other, self.units)

    __rmul__ = __mul__

    def __truediv__(self, other):
        if isinstance(other, _Quantity):
            return _Quantity(self.magnitude / other.magnitude, _merged(self.units, other.units, -1))
        return _Quantity(self.magnitude / other, self.units)

    def __rtruediv__(self, other):
        return _Quantity(other / self.magnitude, {name: -e for name, e in self.units.items()})

    def __pow__(self, exponent):
        return _Quantity(_power(self.magnitude, exponent), {name: e * exponent for name, e in self.units.items()})

    @property
    def dims(self) -> tuple:
        """Exponents of DIMENSIONS (sums of small integers and halves: exact in binary floating point)."""
        total = [0.0] * len(DIMENSIONS)
        for name, e in self.units.items():
            for i, d in enumerate(_entry(name)[1]):
                total[i] += d * e
        return tuple(total)

    @property
    def factor(self) -> float:
        """The value in SI: the magnitude times the units' factors (numerator and denominator apart, one
        rounding each)."""
        numerator = denominator = 1.0
        for name, e in sorted(self.units.items()):
            f = _entry(name)[0]
            if e > 0:
                numerator *= _power(f, e)
            else:
                denominator *= _power(f, -e)
        return self.magnitude * (numerator / denominator)

    def dimensionless(self) -> bool:
        return not any(self.dims)


def _merged(a: dict, b: dict, sign: int) -> dict:
    units = dict(a)
    for name, e in b.items():
        units[name] = units.get(name, 0.0) + sign * e
        if not units[name]:
            del units[name]
    return units


def _entry(name: str) -> tuple[float, tuple]:
    """(factor to SI, dimension exponents) of a canonical word: a unit of the table, or a prefix and one."""
    if name in UNITS:
        return UNITS[name]
    factor, dims = UNITS[name[1:]]
    return PREFIXES[name[0]] * factor, dims


def _power(base: float, exponent: float) -> float:
    if base < 0 and exponent != int(exponent):
        raise ValueError("square root of a negative number")
    try:
        return base ** exponent
    except ZeroDivisionError:
        raise ValueError("division by zero") from None
    except OverflowError:
        return math.inf


@lru_cache(maxsize=256)
def unit(name: str) -> _Quantity:
    """A unit word -> its _Quantity (a ValueError names an unknown one as written)."""
    found = _canonical(name)
    if found is None:
        raise ValueError(f"unknown unit {name!r}")
    canonical, exponent = found
    return _Quantity(1.0, {canonical: exponent})


def _canonical(name: str) -> tuple[str, float] | None:
    """A unit word -> (canonical word, exponent): "degrees" -> ("deg", 1), "rtHz" -> ("Hz", 0.5), "µg" -> ("ug", 1)."""
    if name in UNITS:
        return _CANONICAL[name], 1.0
    if name in _PLURAL:
        return _CANONICAL[_PLURAL[name]], 1.0
    if name.startswith("rt") and len(name) > 2:
        root = _canonical(name[2:])
        return None if root is None else (root[0], root[1] * 0.5)
    for prefix in sorted(PREFIXES, key=len, reverse=True):
        rest = name[len(prefix):]
        if name.startswith(prefix) and (rest in UNITS or rest in _PLURAL):
            return _SHORT_PREFIX.get(prefix, prefix) + _canonical(rest)[0], 1.0
    return None


# The longest text read as a value with units, and the deepest nesting of parentheses and sqrt(): datasheet
# forms are a few words long; the bounds keep a scene file from making the parser work for minutes.
MAX_TEXT = 100
MAX_DEPTH = 4
# Exponents are small integers ("m/s^2", "(deg/s)**2", "s^-1"): "9**9**9" would be a 369-million-digit number.
MAX_EXPONENT = 4
_TOKEN = re.compile(r"\s*(?:(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|(?P<word>[A-Za-zµμ°%][A-Za-z0-9_µμ°%]*)"
                    r"|(?P<op>\*\*|[*/^()√-]))")


_SUPERSCRIPT = re.compile(r"(⁻?)([¹²³⁴])")
_ROOT = re.compile(r"(?<!\w)rt-(?=[A-Za-z])")      # "rt-Hz" is the word "rtHz", not "rt" minus "Hz"


def _tokens(text: str) -> list[tuple[str, str]]:
    tokens, at = [], 0
    text = _SUPERSCRIPT.sub(lambda m: "^" + "-" * bool(m.group(1)) + str("¹²³⁴".index(m.group(2)) + 1), text.rstrip())
    text = _ROOT.sub("rt", text)
    while at < len(text):
        match = _TOKEN.match(text, at)
        if not match:
            raise ValueError(f"unexpected {text[at:].lstrip()[:1]!r}")
        kind = match.lastgroup
        tokens.append((kind, match.group(kind)))
        at = match.end()
    return tokens


class _Reader:
    """A value with units by a small grammar over the unit table (never an expression evaluator: pint's evaluated
    arbitrary arithmetic such as "10**10**10"):
        product := power (("*" | "/" | juxtaposition) power)*
        power   := atom (("^" | "**") ["-"] INTEGER)?          (|INTEGER| <= MAX_EXPONENT)
        atom    := ["-"] NUMBER | WORD | "(" product ")" | "sqrt" "(" product ")" | "√" atom
    Juxtaposition multiplies ("0.1 %/(2000 deg/s)"), and * / juxtaposition associate left to right, as in pint."""

    def __init__(self, text: str):
        self.tokens, self.at, self.depth = _tokens(text), 0, 0

    def peek(self):
        return self.tokens[self.at] if self.at < len(self.tokens) else (None, None)

    def take(self, value=None):
        kind, token = self.peek()
        if kind is None or (value is not None and token != value):
            raise ValueError(f"expected {value!r}" if value else "unexpected end")
        self.at += 1
        return kind, token

    def read(self):
        value = self.product()
        if self.at != len(self.tokens):
            raise ValueError(f"unexpected {self.peek()[1]!r}")
        return value

    def product(self):
        value = self.power()
        while True:
            kind, token = self.peek()
            if token in ("*", "/"):
                self.at += 1
                right = self.power()
                value = value * right if token == "*" else value / right
            elif kind in ("number", "word") or token in ("(", "√"):
                value = value * self.power()
            else:
                return value

    def power(self):
        value = self.atom()
        if self.peek()[1] in ("^", "**"):
            self.at += 1
            sign = -1 if self.peek()[1] == "-" and self.take("-") else 1
            kind, token = self.take()
            if kind != "number" or not token.isdigit() or int(token) > MAX_EXPONENT:
                raise ValueError(f"exponents are integers up to {MAX_EXPONENT}, got {token!r}")
            value = _raised(value, sign * int(token))
        return value

    def atom(self):
        kind, token = self.take()
        if token == "-":
            kind, token = self.take()
            if kind != "number":
                raise ValueError("'-' only before a number")
            return -float(token)
        if kind == "number":
            return float(token)
        if token == "sqrt" and self.peek()[1] == "(":
            return _raised(self.nested(lambda: self.take("(") and self.closed()), 0.5)
        if token == "√":
            return _raised(self.nested(self.atom), 0.5)
        if token == "(":
            return self.nested(self.closed)
        if kind == "word":
            return unit(token)
        raise ValueError(f"unexpected {token!r}")

    def closed(self):
        value = self.product()
        self.take(")")
        return value

    def nested(self, read):
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise ValueError(f"more than {MAX_DEPTH} nested parentheses")
        value = read()
        self.depth -= 1
        return value


def _raised(value, exponent):
    return value ** exponent if isinstance(value, _Quantity) else _power(value, exponent)


@lru_cache(maxsize=1024)
def quantity(text: str) -> _Quantity:
    """Text -> _Quantity, bounded in length, nesting and exponents; a ValueError gives the reason. Cached: a scene
    repeats its units ("0.3 deg" nine times in a misalignment matrix) and the key's unit is read for every value."""
    if len(text) > MAX_TEXT:
        raise ValueError(f"longer than {MAX_TEXT} characters")
    try:
        value = _Reader(text).read()
    except ZeroDivisionError:
        raise ValueError("division by zero") from None
    return value if isinstance(value, _Quantity) else _Quantity(value, {})


def to_unit(value, unit: str, where: str) -> float:
    """A number (already in `unit`) or a string with units -> float in `unit`. Errors name `where`.
    `unit` may name alternatives "A|B" (e.g. "rad|1": a misalignment as an angle or as a cross-axis ratio,
    equal for small angles): a string is converted to the first alternative of its dimension, plain numbers
    are taken in A."""
    if "|" in unit:
        return _to_any_unit(value, unit.split("|"), where)
    if isinstance(value, bool) or not isinstance(value, (int, float, str, np.integer, np.floating)):
        raise SceneError(f"{where}: expected a number or a string with units, got {value!r}")
    if isinstance(value, str):
        try:
            ratio = quantity(value.strip()) / quantity(unit)
        except (ValueError, ZeroDivisionError) as exc:
            # the reason from the grammar or the table (an unknown unit, named); the text itself may be long
            shown = repr(value) if len(value) <= 60 else repr(value[:40]) + f"... ({len(value)} characters)"
            raise SceneError(f"{where}: cannot read {shown} as a value with units: {exc} (e.g. '5 deg/h', "
                             f"'120 ug/sqrt(Hz)'; expected a value in {unit})") from None
        if not ratio.dimensionless():
            raise SceneError(f"{where}: {value!r} has the wrong dimension (expected a value in {unit})")
        number = float(ratio.factor)
    else:
        number = float(value)
    if not math.isfinite(number):
        raise SceneError(f"{where}: must be finite, got {value!r} (TOML reads numbers beyond 1.8e308 as inf)")
    return number


def _to_any_unit(value, alternatives: list[str], where: str) -> float:
    if not isinstance(value, str):
        return to_unit(value, alternatives[0], where)
    for alternative in alternatives[:-1]:
        try:
            return to_unit(value, alternative, where)
        except SceneError as exc:
            if "wrong dimension" not in str(exc):
                raise
    try:
        return to_unit(value, alternatives[-1], where)
    except SceneError as exc:
        if "wrong dimension" not in str(exc):
            raise
        raise SceneError(f"{where}: {value!r} has the wrong dimension (expected a value in "
                         f"{' or '.join(alternatives)})") from None


def _matrix(value, unit: str, where: str):
    if len(value) != 3 or not all(isinstance(row, (list, tuple)) and len(row) == 3 for row in value):
        raise SceneError(f"{where}: expected one value, three, or a 3x3 list of lists")
    return tuple(tuple(to_unit(v, unit, f"{where}[{i}][{j}]") for j, v in enumerate(row))
                 for i, row in enumerate(value))


def parse(value, unit: str, shape: str, where: str):
    """A parameter of `shape` -> float ("scalar"), tuple of 3 floats ("vector3": one value is broadcast to
    the three axes; "triple": exactly three values) or 3 tuples of 3 floats ("matrix3": one value fills every element), each in `unit`."""
    if shape == "scalar":
        return to_unit(value, unit, where)
    if shape == "triple":
        if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 3:
            raise SceneError(f"{where}: expected a list of three numbers, got {value!r}")
        return tuple(to_unit(v, unit, f"{where}[{i}]") for i, v in enumerate(value))
    if shape == "vector3":
        if isinstance(value, (list, tuple)):
            if len(value) != 3:
                raise SceneError(f"{where}: expected one value or a list of three, got {len(value)} values")
            return tuple(to_unit(v, unit, f"{where}[{i}]") for i, v in enumerate(value))
        number = to_unit(value, unit, where)
        return (number, number, number)
    if shape == "matrix3":
        if isinstance(value, (list, tuple)):
            if len(value) != 3 or not all(isinstance(row, (list, tuple)) and len(row) == 3 for row in value):
                raise SceneError(f"{where}: expected one value or a 3x3 list of lists")
            return tuple(tuple(to_unit(v, unit, f"{where}[{i}][{j}]") for j, v in enumerate(row))
                         for i, row in enumerate(value))
        number = to_unit(value, unit, where)
        return tuple(tuple(number for _ in range(3)) for _ in range(3))
    if shape == "expression":
        # a number or an expression in t (imu_emulator.numerics.expressions), in `unit`; kept as its checked text
        from imu_emulator.numerics import expressions
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise SceneError(f"{where}: expected a number or an expression in t, got {value!r}")
        text = str(float(value)) if not isinstance(value, str) else value.strip()
        expressions.check(text, where, set())
        return text
    if shape in ("diagonal3", "crossaxis"):
        # diagonal3: one value or three fill the diagonal (e.g. g-sensitivity of each axis to its own axis);
        # crossaxis: one value fills the off-diagonal, three fill row i's off-diagonal elements (axis i's
        # sensitivity to both other axes); either: a 3x3 list is taken as it is
        if isinstance(value, (list, tuple)) and value and isinstance(value[0], (list, tuple)):
            return _matrix(value, unit, where)
        diagonal = shape == "diagonal3"
        if isinstance(value, (list, tuple)):
            if len(value) != 3:
                raise SceneError(f"{where}: expected one value, three, or a 3x3 list of lists")
            row = [to_unit(v, unit, f"{where}[{i}]") for i, v in enumerate(value)]
        else:
            row = [to_unit(value, unit, where)] * 3
        return tuple(tuple(row[i] if (i == j) == diagonal else 0.0 for j in range(3)) for i in range(3))
    if shape == "sines":
        return _sines(value, unit, where)
    if shape == "psd":
        return _psd(value, unit, where)
    raise ValueError(shape)


def _sines(value, unit: str, where: str):
    """Sinusoidal lines: a list of tables {axis = "x"|"y"|"z", amplitude, frequency, phase (optional)}; the
    amplitude's unit alternatives ("m/s^2|rad/s") say its kind: a string converts to the first alternative of
    its dimension, a plain number is in the first unless `kind` names another ("angular").
    -> tuple of (axis index, kind index, amplitude, frequency in Hz, phase in rad)."""
    kinds = unit.split("|")
    if not isinstance(value, (list, tuple)):
        raise SceneError(f"{where}: expected a list of tables {{axis, amplitude, frequency}}, got {value!r}")
    lines = []
    for i, line in enumerate(value):
        at = f"{where}[{i}]"
        if not isinstance(line, dict):
            raise SceneError(f"{at}: expected a table {{axis, amplitude, frequency}}, got {line!r}")
        unknown = set(line) - {"axis", "amplitude", "frequency", "phase", "kind"}
        if unknown or not {"axis", "amplitude", "frequency"} <= set(line):
            raise SceneError(f"{at}: expected keys axis, amplitude, frequency (phase, kind optional), got "
                             f"{sorted(line)}")
        if line["axis"] not in ("x", "y", "z"):
            raise SceneError(f"{at}.axis: expected \"x\", \"y\" or \"z\", got {line['axis']!r}")
        names = ("linear", "angular")[: len(kinds)]
        kind = line.get("kind")
        if kind is not None and kind not in names:
            raise SceneError(f"{at}.kind: expected one of {', '.join(names)}, got {kind!r}")
        amplitude = line["amplitude"]
        if kind is not None:
            index = names.index(kind)
            number = to_unit(amplitude, kinds[index], f"{at}.amplitude")
        elif isinstance(amplitude, str):
            number = to_unit(amplitude, unit, f"{at}.amplitude")
            index = next(j for j, k in enumerate(kinds) if _fits(amplitude, k))
        else:
            index, number = 0, to_unit(amplitude, kinds[0], f"{at}.amplitude")
        frequency = to_unit(line["frequency"], "Hz", f"{at}.frequency")
        if not frequency > 0:
            raise SceneError(f"{at}.frequency: must be positive, got {line['frequency']!r}")
        phase = to_unit(line.get("phase", 0.0), "rad", f"{at}.phase")
        lines.append(("xyz".index(line["axis"]), index, number, frequency, phase))
    return tuple(lines)


def _fits(value: str, unit: str) -> bool:
    try:
        to_unit(value, unit, "")
        return True
    except SceneError:
        return False


def _psd(value, unit: str, where: str):
    """A power spectral density table: a list of [frequency, level] breakpoints, frequencies increasing and
    positive, levels positive (interpolated log-log between them, as vibration specifications are drawn).
    -> tuple of (frequency in Hz, level in `unit`)."""
    if not isinstance(value, (list, tuple)) or (value and len(value) < 2):
        raise SceneError(f"{where}: expected a list of at least two [frequency, level] pairs, got {value!r}")
    table = []
    for i, pair in enumerate(value):
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise SceneError(f"{where}[{i}]: expected a [frequency, level] pair, got {pair!r}")
        f = to_unit(pair[0], "Hz", f"{where}[{i}][0]")
        level = to_unit(pair[1], unit, f"{where}[{i}][1]")
        if not (f > 0 and level > 0) or (table and not f > table[-1][0]):
            raise SceneError(f"{where}[{i}]: frequencies must increase and be positive, levels positive, "
                             f"got {pair!r}")
        table.append((f, level))
    return tuple(table)
