"""Earth rate: the gyros sense the Earth's rotation, omega_ie^n = omega_ie (cos L, 0, -sin L) in local NED."""
from imu_emulator.motion.earth import EARTH_RATE, earth_rate_lines
from imu_emulator.effects import _earth
from imu_emulator.effects._record import Effect, Stage


def emit(ctx) -> list[str]:
    return earth_rate_lines() + _earth.add_rate(ctx.scene, *EARTH_RATE)


EFFECT = Effect(
    name="earth_rate",
    description="gyros sense the Earth's rotation (7.292115e-5 rad/s, WGS-84) at the current latitude; "
                "ENU/NED frames are tangent at [scene] origin",
    stage=Stage.NAVIGATION, order=1, emit=emit, nav_rate=True)
