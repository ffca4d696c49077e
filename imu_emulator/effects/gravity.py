"""Gravity: accelerometers measure specific force f = a - g (at rest, level, ENU: f = (0, 0, +g))."""
from imu_emulator.effects._record import Effect, Stage


def emit(ctx) -> list[str]:
    # g = (0, 0, -g0) in ENU, (0, 0, +g0) in NED; g0 is [scene] gravity_mps2
    sign = "+" if ctx.scene.frame == "ENU" else "-"
    return [f"fnz = fnz {sign} {float(ctx.scene.gravity_mps2)!r}"]


EFFECT = Effect(
    name="gravity",
    description="specific force includes -g (at rest, level, ENU: f = (0, 0, +g)); g0 is [scene] gravity_mps2",
    stage=Stage.NAVIGATION, order=0, emit=emit)
