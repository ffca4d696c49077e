"""Lever arm: an IMU away from the body's reference point S feels the centripetal and Euler terms."""
from imu_emulator.effects._record import Effect, Param, Stage


def emit(ctx) -> list[str]:
    rx, ry, rz = ctx.value("imu.lever_arm_m")
    if not (rx or ry or rz):
        return []
    # f_I = f_S + w x (w x r) + alpha x r, body frame (w the inertial rate, alpha its derivative)
    alx, aly, alz = ctx.alpha
    return [
        f"ux = gwy * {rz!r} - gwz * {ry!r}", f"uy = gwz * {rx!r} - gwx * {rz!r}", f"uz = gwx * {ry!r} - gwy * {rx!r}",
        f"fax += gwy * uz - gwz * uy + ({aly} * {rz!r} - {alz} * {ry!r})",
        f"fay += gwz * ux - gwx * uz + ({alz} * {rx!r} - {alx} * {rz!r})",
        f"faz += gwx * uy - gwy * ux + ({alx} * {ry!r} - {aly} * {rx!r})",
    ]


EFFECT = Effect(
    name="lever_arm",
    description="centripetal and Euler terms w x (w x r) + alpha x r for each IMU's lever arm",
    stage=Stage.BODY, order=0, emit=emit,
    params=(Param("lever_arm_m", "imu", "m", "position of the IMU relative to S, body axes", shape="triple",
                  default=(0.0, 0.0, 0.0)),))
