"""Parameter values as datasheets print them ("0.2 deg/sqrt(h)", "120 ug/sqrt(Hz)", "500 ppm") -> SI floats.

A pint registry with an explicit, small unit context rather than pint's default one, because datasheets and
pint disagree on one symbol: "g" is standard gravity here (so "ug", "mg" are micro-g and milli-g), never gram.
Angle is a base dimension of its own, so "5 m/s" given for a gyro key is an error rather than silently rad/s.
Plain numbers are taken in the key's own unit (SI unless the key's name says otherwise, e.g. mounting_rpy_deg).
"""
from __future__ import annotations

import math
import re
from functools import lru_cache

import numpy as np

from imu_emulator.errors import SceneError

DEFINITIONS = """
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
day = 24 * hour
year = 365.25 * day = yr
hertz = 1 / second = Hz
degree = pi / 180 * radian = deg = °
degree_per_second = degree / second = dps
standard_gravity = 9.80665 * meter / second ** 2 = g = g0
percent = 0.01 = %
kelvin = [temperature] = K = degC

ppm = 1e-6
gauss = [magnetic_field] = G = Gs
tesla = 1e4 * gauss = T
pascal = [pressure] = Pa
hectopascal = 100 * pascal = hPa
bar = 1e5 * pascal
"""
# The longest text read as a value with units, and the deepest nesting of parentheses and sqrt(): datasheet
# forms are a few words long; the bounds keep a scene file from making the parser (or pint) work for minutes.
MAX_TEXT = 100
MAX_DEPTH = 4
# Exponents are small integers ("m/s^2", "(deg/s)**2", "s^-1"): "9**9**9" would be a 369-million-digit number.
MAX_EXPONENT = 4
_TOKEN = re.compile(r"\s*(?:(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|(?P<word>[A-Za-zµμ°%][A-Za-z0-9_µμ°%]*)"
                    r"|(?P<op>\*\*|[*/^()√-]))")


@lru_cache(maxsize=1)
def registry():
    import pint
    reg = pint.UnitRegistry(None)
    reg.load_definitions(DEFINITIONS.strip().splitlines())
    return reg


_SUPERSCRIPT = re.compile(r"(⁻?)([¹²³⁴])")


def _tokens(text: str) -> list[tuple[str, str]]:
    tokens, at = [], 0
    text = _SUPERSCRIPT.sub(lambda m: "^" + "-" * bool(m.group(1)) + str("¹²³⁴".index(m.group(2)) + 1), text.rstrip())
    while at < len(text):
        match = _TOKEN.match(text, at)
        if not match:
            raise ValueError(f"unexpected {text[at:].lstrip()[:1]!r}")
        kind = match.lastgroup
        tokens.append((kind, match.group(kind)))
        at = match.end()
    return tokens


class _Reader:
    """A value with units by a small grammar, evaluated with pint's unit objects but never pint's expression
    parser (which evaluates arbitrary arithmetic such as "10**10**10"):
        product := power (("*" | "/" | juxtaposition) power)*
        power   := atom (("^" | "**") ["-"] INTEGER)?          (|INTEGER| <= MAX_EXPONENT)
        atom    := ["-"] NUMBER | WORD | "(" product ")" | "sqrt" "(" product ")" | "√" atom
    Juxtaposition multiplies ("0.1 %/(2000 deg/s)"), and * / juxtaposition associate left to right, as in pint."""

    def __init__(self, text: str, reg):
        self.tokens, self.at, self.depth, self.reg = _tokens(text), 0, 0, reg

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
            value = value ** (sign * int(token))
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
            return self.nested(lambda: self.take("(") and self.closed()) ** 0.5
        if token == "√":
            return self.nested(self.atom) ** 0.5
        if token == "(":
            return self.nested(self.closed)
        if kind == "word":
            try:
                return self.reg.Quantity(1.0, self.reg.Unit(token))
            except Exception:
                raise ValueError(f"unknown unit {token!r}") from None
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


def _quantity(text: str):
    """Text -> pint Quantity (or float), bounded in length, nesting and exponents."""
    if len(text) > MAX_TEXT:
        raise ValueError(f"longer than {MAX_TEXT} characters")
    return _Reader(text, registry()).read()


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
        import pint
        reg = registry()
        try:
            ratio = reg.Quantity(_quantity(value.strip())) / reg.Quantity(_quantity(unit))
            number = float(ratio.to(reg.dimensionless).magnitude)
        except pint.DimensionalityError:
            raise SceneError(f"{where}: {value!r} has the wrong dimension (expected a value in {unit})") from None
        except Exception as exc:
            # the reason from the grammar (ValueError) or pint (an unknown unit); the text itself may be long
            shown = repr(value) if len(value) <= 60 else repr(value[:40]) + f"... ({len(value)} characters)"
            reason = f": {exc}" if isinstance(exc, ValueError) else ""
            raise SceneError(f"{where}: cannot read {shown} as a value with units{reason} (e.g. '5 deg/h', "
                             f"'120 ug/sqrt(Hz)'; expected a value in {unit})") from None
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
