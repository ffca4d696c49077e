"""Range: the sensor's full scale. Outputs beyond ±range saturate there and are counted per IMU and axis
(Simulation.counts(), shown by generate and stream; apart from the wire fields' own saturation counts).
0 (the default) leaves that axis unlimited."""
from imu_emulator.effects._record import AXES, TRIADS, Effect, Stage, triad_params
from imu_emulator.errors import SceneError


def emit(ctx) -> list[str]:
    lines = []
    for triad, (_, out, _) in TRIADS.items():
        for axis, full_scale in enumerate(ctx.value(f"imu.{triad}.range")):
            if full_scale:
                v, count = f"{out}{AXES[axis]}", ctx.count(f"{triad}.{AXES[axis]}")
                lines += [f"if {v} > {full_scale!r}:", f"    {v} = {full_scale!r}", f"    {count} += 1.0",
                          f"elif {v} < {-full_scale!r}:", f"    {v} = {-full_scale!r}", f"    {count} += 1.0"]
    return lines


def validate(values: dict, where: str) -> None:
    for triad in TRIADS:
        for axis, full_scale in enumerate(values[f"imu.{triad}.range"]):
            if full_scale < 0:
                raise SceneError(f"{where}.{triad}.range: a full scale is positive (or 0 for unlimited), "
                                 f"got {full_scale!r} on axis {AXES[axis]}")


EFFECT = Effect(
    name="range",
    description="full scale: outputs beyond +-range saturate there, counted per IMU and axis",
    stage=Stage.OUTPUT, order=0, emit=emit, validate=validate,
    params=triad_params("range", "rad/s", "m/s^2", "full scale (0: unlimited)", gyro_datasheet="`2000 deg/s`",
                        accel_datasheet="`16 g`"))
