"""Scale-factor error: the diagonal of M in (I + M)·ω and (I + M)·f (ppm or %, one value or one per axis)."""
from imu_emulator.effects._linear import add_matrix
from imu_emulator.effects._record import TRIADS, Effect, Stage, triad_params


def emit(ctx) -> list[str]:
    lines = []
    for triad, (_, out, _) in TRIADS.items():
        s = ctx.value(f"imu.{triad}.scale_factor")
        lines += add_matrix(ctx, out, [[s[i] if i == j else 0.0 for j in range(3)] for i in range(3)], triad)
    return lines


EFFECT = Effect(
    name="scale_factor",
    description="scale-factor error: output (1 + s) times the true value, per axis",
    stage=Stage.SENSOR, order=21, emit=emit,
    params=triad_params("scale_factor", "dimensionless", "dimensionless", "scale-factor error s (ratio)",
                        gyro_datasheet="`500 ppm`, `0.5 %`", accel_datasheet="`0.3 %`"))
