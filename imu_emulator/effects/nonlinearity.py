"""Quadratic nonlinearity: K2·v² (element-wise) added to each output, v the true sensor-frame value; under a
sine vibration of amplitude a0 it gives the DC shift K2·a0²/2 (the vibration rectification error). K2 is per
unit of the triad's quantity; datasheets' vibration-rectification figures are K2 directly ("10 ug/g^2").
Datasheets print nonlinearity as a percentage of full scale (`nonlinearity_fs = "0.5 %"`): a quadratic term
reaching x % of FS at FS is K2 = x % / FS, with FS the triad's `nonlinearity_full_scale` or else its `range`
(when the range effect is on). Both forms given add up."""
from imu_emulator.effects._linear import TRUE
from imu_emulator.effects._record import AXES, TRIADS, Effect, Param, Stage, triad_params
from imu_emulator.errors import SceneError


def full_scale(values: dict, triad: str, axis: int, range_on: bool) -> float:
    explicit = values[f"imu.{triad}.nonlinearity_full_scale"][axis]
    return explicit or (values[f"imu.{triad}.range"][axis] if range_on else 0.0)


def coefficient(values: dict, triad: str, axis: int, range_on: bool, where: str) -> float:
    """K2 of one axis: the per-unit form plus the %FS form over the full scale."""
    k2 = values[f"imu.{triad}.nonlinearity"][axis]
    fraction = values[f"imu.{triad}.nonlinearity_fs"][axis]
    if fraction:
        fs = full_scale(values, triad, axis, range_on)
        if not fs > 0:
            raise SceneError(f"{where}.{triad}.nonlinearity_fs: needs a full scale on axis {AXES[axis]}: give "
                             f"{triad}.nonlinearity_full_scale, or {triad}.range with effects.range = true")
        k2 += fraction / fs
    return k2


def emit(ctx) -> list[str]:
    lines = []
    range_on = "range" in ctx.scene.effects
    for triad, (_, out, _) in TRIADS.items():
        for axis in range(3):
            k2 = coefficient(ctx.imu.values, triad, axis, range_on, f"imu[{ctx.m}]")
            if k2:
                true = TRUE[triad][axis]
                lines.append(f"{out}{AXES[axis]} += {ctx.number(k2)} * ({true} * {true})")
    return lines


def validate(values: dict, where: str) -> None:
    for triad in TRIADS:
        for axis in range(3):
            if values[f"imu.{triad}.nonlinearity_full_scale"][axis] < 0:
                raise SceneError(f"{where}.{triad}.nonlinearity_full_scale: a full scale is positive")
            # without knowing whether the range effect is on, a missing full scale is certain only when
            # neither key gives one (emit checks the rest)
            coefficient(values, triad, axis, True, where)


EFFECT = Effect(
    name="nonlinearity",
    description="quadratic nonlinearity K2 v^2 per axis (vibration rectification: DC shift K2 a0^2 / 2)",
    stage=Stage.SENSOR, order=31, emit=emit, validate=validate,
    params=(*triad_params("nonlinearity", "s/rad", "s^2/m", "quadratic coefficient K2 (per unit of the output)",
                          gyro_datasheet="`1e-4 s/deg`, `0.1 %/(2000 deg/s)`",
                          accel_datasheet="`10 ug/g^2`, `0.5 %/(16 g)`"),
            *triad_params("nonlinearity_fs", "1", "1", "nonlinearity as a fraction of full scale (K2 = x / FS)",
                          gyro_datasheet="`0.1 %` (%FS)", accel_datasheet="`0.5 %` (%FS)"),
            *triad_params("nonlinearity_full_scale", "rad/s", "m/s^2", "full scale for nonlinearity_fs "
                          "(default: range, with the range effect on)", gyro_datasheet="`2000 deg/s`",
                          accel_datasheet="`16 g`")))
