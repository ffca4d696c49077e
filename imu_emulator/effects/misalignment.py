"""Misalignment / cross-axis sensitivity: the off-diagonal of M in (I + M)·ω and (I + M)·f, in the sensor
frame, so it composes after the mounting rotation (mounting turns body axes into the nominal sensor axes;
this is how far the real sensing axes lean from those). M[i][j] is axis i's sensitivity to the true value
on axis j: an angle in rad (small-angle) or a cross-axis ratio (%). One value fills every off-diagonal
element; three values fill row i's off-diagonal elements; a 3x3 is taken as it is (a diagonal given there
adds to the scale factor, as in the model's M)."""
from imu_emulator.effects._linear import add_matrix
from imu_emulator.effects._record import TRIADS, Effect, Stage, triad_params


def emit(ctx) -> list[str]:
    lines = []
    for triad, (_, out, _) in TRIADS.items():
        lines += add_matrix(ctx, out, ctx.value(f"imu.{triad}.misalignment"), triad)
    return lines


EFFECT = Effect(
    name="misalignment",
    description="misalignment / cross-axis sensitivity: off-diagonal M, after mounting",
    stage=Stage.SENSOR, order=20, emit=emit,
    params=triad_params("misalignment", "rad|dimensionless", "rad|dimensionless",
                        "misalignment M[i][j] (rad or cross-axis ratio; one value, 3 rows' values or a 3x3)",
                        shape="crossaxis", gyro_datasheet="`1 mrad`, `0.1 deg`, cross-axis `1 %`",
                        accel_datasheet="`1 mrad`, cross-axis `0.5 %`"))
