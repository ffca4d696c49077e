"""Quadratic nonlinearity: K2·v² (element-wise) added to each output, v the true sensor-frame value; under a
sine vibration of amplitude a0 it gives the DC shift K2·a0²/2 (the vibration rectification error). K2 is per
unit of the triad's quantity; datasheets' vibration-rectification figures are K2 directly ("10 ug/g^2"), and a
quadratic term reaching x % of full scale FS at FS is K2 = x % / FS ("0.5 %/(16 g)")."""
from imu_emulator.effects._linear import TRUE, per_axis
from imu_emulator.effects._record import Effect, Stage, triad_params


def emit(ctx) -> list[str]:
    lines = []
    for triad, v, axis, k2 in per_axis(ctx, "nonlinearity"):
        true = TRUE[triad]["xyz".index(axis)]
        lines.append(f"{v} += {k2!r} * ({true} * {true})")
    return lines


EFFECT = Effect(
    name="nonlinearity",
    description="quadratic nonlinearity K2 v^2 per axis (vibration rectification: DC shift K2 a0^2 / 2)",
    stage=Stage.SENSOR, order=31, emit=emit,
    params=triad_params("nonlinearity", "s/rad", "s^2/m", "quadratic coefficient K2 (per unit of the output)",
                        gyro_datasheet="`1e-4 s/deg`, `0.1 %/(2000 deg/s)`",
                        accel_datasheet="`10 ug/g^2`, `0.5 %/(16 g)`"))
