"""Gyro g-sensitivity: G_g·f added to the gyro output, f the true specific force in the sensor frame.
One value or three fill the diagonal (each gyro axis sensitive to the specific force along itself); a 3x3 is
taken as it is."""
from imu_emulator.effects._linear import add_matrix
from imu_emulator.effects._record import TRIADS, Effect, Param, Stage


def emit(ctx) -> list[str]:
    return add_matrix(ctx, TRIADS["gyro"][1], ctx.value("imu.gyro.g_sensitivity"), "accel")


EFFECT = Effect(
    name="g_sensitivity",
    description="gyro g-sensitivity: G_g times the true specific force added to the gyro output",
    stage=Stage.SENSOR, order=30, emit=emit,
    params=(Param("g_sensitivity", "imu.gyro", "rad*s/m", "gyro g-sensitivity G_g (one value, 3 or a 3x3)",
                  shape="diagonal3", datasheet="`0.1 deg/s/g`"),))
