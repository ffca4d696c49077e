"""Resolution: outputs rounded to the nearest multiple of the LSB, floor(v / lsb + 1/2)·lsb (ties go up),
after range."""
from imu_emulator.effects._record import AXES, TRIADS, Effect, Stage, triad_params
from imu_emulator.errors import SceneError


def emit(ctx) -> list[str]:
    lines = []
    for triad, (_, out, _) in TRIADS.items():
        for axis, lsb in enumerate(ctx.value(f"imu.{triad}.resolution")):
            if lsb:
                v = f"{out}{AXES[axis]}"
                lines.append(f"{v} = math.floor({v} / {lsb!r} + 0.5) * {lsb!r}")
    return lines


def validate(values: dict, where: str) -> None:
    for triad in TRIADS:
        for axis, lsb in enumerate(values[f"imu.{triad}.resolution"]):
            if lsb < 0:
                raise SceneError(f"{where}.{triad}.resolution: the LSB is positive (or 0: not rounded), "
                                 f"got {lsb!r} on axis {AXES[axis]}")


EFFECT = Effect(
    name="resolution",
    description="outputs rounded to the LSB (after range)",
    stage=Stage.OUTPUT, order=10, emit=emit, validate=validate,
    params=triad_params("resolution", "rad/s", "m/s^2", "LSB (0: not rounded)", gyro_datasheet="`0.061 deg/s`",
                        accel_datasheet="`0.488 mg`, `2*16 g / 2**16`"))
