"""Mounting: the sensor frame is the body frame rotated by the IMU's mounting rotation."""
import numpy as np

from imu_emulator.effects._record import Effect, Param, Stage


def mounting_matrix(rpy_deg) -> np.ndarray:
    """M maps sensor coordinates to body coordinates (sensor frame = body frame rotated by M)."""
    from imu_emulator.geo.rotations import euler_to_matrix
    return euler_to_matrix(np.radians(rpy_deg))


def rotation(ctx):
    """The mounting matrix of this IMU, or None when the effect leaves the axes alone."""
    if "mounting" not in ctx.scene.effects:
        return None
    rpy = ctx.imu.values["imu.mounting_rpy_deg"]
    if not any(rpy):
        return None
    return mounting_matrix(rpy)


def emit(ctx) -> list[str]:
    M = rotation(ctx)
    if M is None:
        return []
    lines = []
    for var in ("o", "g"):
        # sensor = M^T body; the right-hand side reads the body values still held in fa*/gw*
        src = {"o": "fa", "g": "gw"}[var]
        for row, axis in enumerate("xyz"):
            lines.append(f"{var}{axis} = " + " + ".join(f"{ctx.number(M[col, row])} * {src}{'xyz'[col]}"
                                                        for col in range(3)))
    return lines


EFFECT = Effect(
    name="mounting",
    description="each IMU's mounting rotation (sensor frame = body frame rotated by mounting_rpy_deg)",
    stage=Stage.SENSOR, order=0, emit=emit,
    params=(Param("mounting_rpy_deg", "imu", "deg", "mounting rotation roll, pitch, yaw (z-y-x) of the sensor "
                  "frame relative to the body frame", shape="triple", default=(0.0, 0.0, 0.0)),))
