"""Range: the sensor's full scale. Outputs beyond ±range saturate there and are counted per IMU and axis
(Simulation.counts(), shown by generate and stream; apart from the wire fields' own saturation counts).
0 (the default) leaves that axis unlimited."""
from imu_emulator.effects._linear import nonnegative, per_axis
from imu_emulator.effects._record import Effect, Stage, triad_params


def emit(ctx) -> list[str]:
    lines = []
    for triad, v, axis, full_scale in per_axis(ctx, "range"):
        count = ctx.count(f"{triad}.{axis}")
        high, low = ctx.number(full_scale), ctx.number(-full_scale)
        lines += [f"if {v} > {high}:", f"    {v} = {high}", f"    {count} += 1.0",
                  f"elif {v} < {low}:", f"    {v} = {low}", f"    {count} += 1.0"]
    return lines


EFFECT = Effect(
    name="range",
    description="full scale: outputs beyond +-range saturate there, counted per IMU and axis",
    stage=Stage.OUTPUT, order=0, emit=emit,
    validate=nonnegative("range", "a full scale is positive (or 0 for unlimited)"),
    params=triad_params("range", "rad/s", "m/s^2", "full scale (0: unlimited)", gyro_datasheet="`2000 deg/s`",
                        accel_datasheet="`16 g`"))
