"""Rate random walk K (gyro) and acceleration random walk (accelerometer): b_{k+1} = b_k + K sqrt(dt) w_k,
starting at 0 (the turn-on bias is the `bias` effect's). sqrt(dt), not dt (NaveGo's bug)."""
import math

from imu_emulator.effects._linear import nonnegative
from imu_emulator.effects._record import AXES, TRIADS, Effect, Stage, triad_params


def emit(ctx) -> list[str]:
    lines = []
    for triad in TRIADS:
        for axis, k in enumerate(ctx.value(f"imu.{triad}.random_walk")):
            if k:
                name = f"{triad}.{AXES[axis]}"
                # the walk's steps are drawn in the part's FRD axes (EmitContext.frd_sign)
                walk = ctx.state(f"walk[{name}]", lambda draw: 0.0)
                lines += ctx.add_bias(triad, axis, walk)
                lines.append(f"{walk} += {ctx.number(k * math.sqrt(ctx.dt) * ctx.frd_sign(axis))} * {ctx.normal(name)}")
    return lines


EFFECT = Effect(
    name="random_walk",
    description="rate random walk (gyro) and acceleration random walk (accelerometer) of the bias",
    stage=Stage.SENSOR, order=62, emit=emit, random=True, state=("walk",),
    validate=nonnegative("random_walk", "a random walk coefficient is >= 0"),
    params=triad_params("random_walk", "rad/s/sqrt(s)", "m/s^2/sqrt(s)", "random walk K of the bias",
                        gyro_datasheet="`0.5 deg/h/sqrt(h)`", accel_datasheet="`0.01 m/s/h/sqrt(h)`"))
