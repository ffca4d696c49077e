"""White noise given as a noise density N (two-sided root PSD), discretized as N * sqrt(f_s) per sample so
its Allan deviation, N / sqrt(tau), does not depend on the sample rate (not a per-sample sigma: gz-sensors)."""
import math

from imu_emulator.effects._linear import nonnegative
from imu_emulator.effects._record import AXES, TRIADS, Effect, Stage, triad_params


def per_sample_sigma(density: float, rate_hz: float) -> float:
    return density * math.sqrt(rate_hz)


def variances(scene) -> dict:
    """{IMU name: (gyro variances (3,) in (rad/s)^2, accel variances (3,) in (m/s^2)^2)}: the per-sample
    variance of the white noise this effect adds, per axis; {} when the effect is off (for sensor_msgs/Imu
    covariances)."""
    if EFFECT.name not in scene.effects:
        return {}
    return {imu.name: tuple([per_sample_sigma(d, scene.rate_hz) ** 2 for d in imu.values[f"imu.{triad}.noise_density"]]
                            for triad in ("gyro", "accel"))
            for imu in scene.imus}


def emit(ctx) -> list[str]:
    lines = []
    for triad in TRIADS:
        out = TRIADS[triad][1]
        for axis, density in enumerate(ctx.value(f"imu.{triad}.noise_density")):
            if density:
                # drawn in the part's FRD axes (EmitContext.frd_sign): the sign rides on the run-time parameter
                sigma = per_sample_sigma(density, ctx.scene.rate_hz) * ctx.frd_sign(axis)
                lines.append(f"{out}{AXES[axis]} += {ctx.number(sigma)} * {ctx.normal(f'{triad}.{AXES[axis]}')}")
    return lines


EFFECT = Effect(
    name="noise",
    description="white noise: angle / velocity random walk given as a noise density",
    stage=Stage.SENSOR, order=90, emit=emit, random=True,
    validate=nonnegative("noise_density", "a noise density is >= 0"),
    params=triad_params("noise_density", "rad/s/sqrt(Hz)", "m/s^2/sqrt(Hz)", "noise density N (root PSD)",
                        gyro_aliases=("arw",), accel_aliases=("vrw",),
                        gyro_datasheet="`0.007 deg/s/sqrt(Hz)`, arw `0.42 deg/sqrt(h)`, `2.8 mdps/sqrt(Hz)`",
                        accel_datasheet="`120 ug/sqrt(Hz)`, vrw `0.07 m/s/sqrt(h)`"))
