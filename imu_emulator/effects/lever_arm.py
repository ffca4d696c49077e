"""Lever arm: an IMU away from the body's reference point S feels the centripetal and Euler terms."""
from imu_emulator.effects._record import Effect, Param, Stage


def emit(ctx) -> list[str]:
    r = ctx.value("imu.lever_arm_m")
    if not any(r):
        return []
    rx, ry, rz = (ctx.number(v) for v in r)
    # f_I = f_S + w x (w x r) + alpha x r, body frame (w the inertial rate, alpha its derivative)
    alx, aly, alz = ctx.alpha
    return [
        f"ux = gwy * {rz} - gwz * {ry}", f"uy = gwz * {rx} - gwx * {rz}", f"uz = gwx * {ry} - gwy * {rx}",
        f"fax += gwy * uz - gwz * uy + ({aly} * {rz} - {alz} * {ry})",
        f"fay += gwz * ux - gwx * uz + ({alz} * {rx} - {alx} * {rz})",
        f"faz += gwx * uy - gwy * ux + ({alx} * {ry} - {aly} * {rx})",
    ]


EFFECT = Effect(
    name="lever_arm",
    description="centripetal and Euler terms w x (w x r) + alpha x r for each IMU's lever arm",
    stage=Stage.BODY, order=0, emit=emit,
    params=(Param("lever_arm_m", "imu", "m", "position of the IMU relative to S, body axes", shape="triple",
                  default=(0.0, 0.0, 0.0)),))
