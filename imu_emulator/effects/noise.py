"""White noise given as a noise density N (two-sided root PSD), discretized as N * sqrt(f_s) per sample so
its Allan deviation, N / sqrt(tau), does not depend on the sample rate (not a per-sample sigma: gz-sensors)."""
import math

from imu_emulator.effects._record import AXES, TRIADS, Effect, Stage, triad_params


def emit(ctx) -> list[str]:
    lines = []
    for triad in TRIADS:
        out = TRIADS[triad][1]
        for axis, density in enumerate(ctx.value(f"imu.{triad}.noise_density")):
            if density:
                sigma = density * math.sqrt(ctx.scene.rate_hz)
                lines.append(f"{out}{AXES[axis]} += {sigma!r} * {ctx.normal(f'{triad}.{AXES[axis]}')}")
    return lines


EFFECT = Effect(
    name="noise",
    description="white noise: angle / velocity random walk given as a noise density",
    stage=Stage.SENSOR, order=90, emit=emit, random=True,
    params=triad_params("noise_density", "rad/s/sqrt(Hz)", "m/s^2/sqrt(Hz)", "noise density N (root PSD)",
                        gyro_aliases=("arw",), accel_aliases=("vrw",),
                        gyro_datasheet="`0.007 deg/s/sqrt(Hz)`, arw `0.42 deg/sqrt(h)`, `2.8 mdps/sqrt(Hz)`",
                        accel_datasheet="`120 ug/sqrt(Hz)`, vrw `0.07 m/s/sqrt(h)`"))
