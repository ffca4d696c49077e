"""Resolution: outputs rounded to the nearest multiple of the LSB, floor(v / lsb + 1/2)·lsb (ties go up),
after range."""
from imu_emulator.effects._linear import nonnegative, per_axis
from imu_emulator.effects._record import Effect, Stage, triad_params


def emit(ctx) -> list[str]:
    lines = []
    for _, v, _, lsb in per_axis(ctx, "resolution"):
        step = ctx.number(lsb)
        lines.append(f"{v} = math.floor({v} / {step} + 0.5) * {step}")
    return lines


EFFECT = Effect(
    name="resolution",
    description="outputs rounded to the LSB (after range)",
    stage=Stage.OUTPUT, order=10, emit=emit,
    validate=nonnegative("resolution", "the LSB is positive (or 0: not rounded)"),
    params=triad_params("resolution", "rad/s", "m/s^2", "LSB (0: not rounded)", gyro_datasheet="`0.061 deg/s`",
                        accel_datasheet="`0.488 mg`, `2*16 g / 2**16`"))
