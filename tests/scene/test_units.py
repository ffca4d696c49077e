"""Datasheet units -> SI, against the conversions written out in specs/sensor-errors.md (independent of pint)."""
import math

import pytest

from imu_emulator.errors import SceneError
from imu_emulator.scene.units import parse, to_unit

DEG = math.pi / 180


@pytest.mark.parametrize("text, unit, expected", [
    ("5 deg/h", "rad/s", 5 * DEG / 3600),
    ("2000 deg/s", "rad/s", 2000 * DEG),
    ("2000 dps", "rad/s", 2000 * DEG),
    # ARW [deg/sqrt(h)] = ND [deg/s/sqrt(Hz)] * 60
    ("0.42 deg/sqrt(h)", "rad/s/sqrt(Hz)", 0.42 / 60 * DEG),
    ("0.007 deg/s/sqrt(Hz)", "rad/s/sqrt(Hz)", 0.007 * DEG),
    ("0.007 deg/s/√Hz", "rad/s/sqrt(Hz)", 0.007 * DEG),
    ("2.8 mdps/sqrt(Hz)", "rad/s/sqrt(Hz)", 2.8e-3 * DEG),
    # ug is micro standard gravity, not microgram
    ("120 ug/sqrt(Hz)", "m/s^2/sqrt(Hz)", 120e-6 * 9.80665),
    ("120 µg/√Hz", "m/s^2/sqrt(Hz)", 120e-6 * 9.80665),
    ("30 ug", "m/s^2", 30e-6 * 9.80665),
    ("0.03 mg", "m/s^2", 0.03e-3 * 9.80665),
    ("16 g", "m/s^2", 16 * 9.80665),
    # VRW [m/s/sqrt(h)] = ND [ug/sqrt(Hz)] * 9.80665e-6 * 60
    ("0.07 m/s/sqrt(h)", "m/s^2/sqrt(Hz)", 0.07 / 60),
    # K [deg/h/sqrt(h)] * pi / (180 * 3600 * 60) = rad/s/sqrt(s)
    ("0.5 deg/h/sqrt(h)", "rad/s/sqrt(s)", 0.5 * math.pi / (180 * 3600 * 60)),
    ("0.1 %", "", 1e-3),
    ("500 ppm", "", 5e-4),
    ("1 mrad", "rad", 1e-3),
    ("1 deg", "rad", DEG),
    (0.25, "rad/s", 0.25),
])
def test_datasheet_forms(text, unit, expected):
    assert to_unit(text, unit or "1", "imu[0].gyro.x") == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("text, unit", [("5 m/s", "rad/s"), ("120 ug", "m/s^2/sqrt(Hz)"), ("3 deg", "s")])
def test_wrong_dimension_names_the_key(text, unit):
    with pytest.raises(SceneError, match=r"^imu\[0\]\.gyro\.noise_density: .*wrong dimension") as info:
        to_unit(text, unit, "imu[0].gyro.noise_density")
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("text", ["fast", "5 furlongs", "nan deg", "1e999 deg/s"])
def test_unreadable_or_non_finite_is_one_line_error(text):
    with pytest.raises(SceneError, match=r"^imu\[0\]\.gyro\.bias: ") as info:
        to_unit(text, "rad/s", "imu[0].gyro.bias")
    assert "\n" not in str(info.value)


def test_shapes():
    assert parse("1 deg/s", "rad/s", "vector3", "k") == (DEG, DEG, DEG)
    assert parse(["1 deg/s", 0, 2], "rad/s", "vector3", "k") == (DEG, 0.0, 2.0)
    with pytest.raises(SceneError, match=r"k: expected one value or a list of three"):
        parse([1, 2], "rad/s", "vector3", "k")
    assert parse([[1, 0, 0], [0, "1 mrad", 0], [0, 0, 1]], "rad", "matrix3", "k")[1][1] == pytest.approx(1e-3)
    with pytest.raises(SceneError, match=r"k\[1\]: .*wrong dimension"):
        parse([0, "1 s", 0], "rad/s", "vector3", "k")


# Forms the README's parameter table and the presets print, each against its conversion written out by hand.
@pytest.mark.parametrize("text, unit, expected", [
    ("0.1 %/(2000 deg/s)", "s/rad", 1e-3 / (2000 * DEG)),             # nonlinearity per unit of full scale
    ("0.5 %/(16 g)", "s^2/m", 5e-3 / (16 * 9.80665)),
    ("10 ug/g^2", "s^2/m", 10e-6 / 9.80665),
    ("1e-4 (deg/s)^2/Hz", "rad^2/s^2/Hz", 1e-4 * DEG ** 2),           # a PSD level
    ("0.008 m/sec/√hr", "m/s^2/sqrt(Hz)", 0.008 / 60),                # xsens preset
    ("3.2 μg", "m/s^2", 3.2e-6 * 9.80665),
    ("0.01 %/degC", "1/K", 1e-4),
    ("0.1 deg/s/g", "rad*s/m", 0.1 * DEG / 9.80665),
    ("1 m/s²", "m/s^2", 1.0),
    ("2 deg h^-1", "rad/s", 2 * DEG / 3600),
    ("2 kHz", "Hz", 2000.0),
    ("-0.1 %", "1", -1e-3),
])
def test_documented_forms(text, unit, expected):
    assert to_unit(text, unit, "k") == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("text, reason", [
    ("1 sqrt(" + " " * 4000 + "x", "longer than 100 characters"),   # pint's rewrite took minutes (cubic)
    ("9**9**9 deg/s", "exponents are integers up to 4"),              # pint evaluated the power: a hang
    ("10**10**10 deg/h", "exponents are integers up to 4"),
    ("1 deg^(2)", "exponents are integers up to 4"),
    ("2^2^2 deg", "unexpected '^'"),
    ("1 " + "(" * 5 + "deg" + ")" * 5, "more than 4 nested"),
    ("1 deg/s rms, BW = 47 Hz", "unexpected ','"),
    ("1 __import__", "unexpected '_'"),
    ("5 furlongs", "unknown unit 'furlongs'"),
    ("1 deg)", "unexpected ')'"),
])
def test_text_outside_the_grammar_is_refused_with_the_reason(text, reason):
    with pytest.raises(SceneError, match=r"^imu\[0\]\.gyro\.bias: cannot read ") as info:
        to_unit(text, "rad/s", "imu[0].gyro.bias")
    message = str(info.value)
    assert reason in message and "\n" not in message and len(message) < 300
