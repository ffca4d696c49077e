"""Earth rate: the gyros sense the Earth's rotation, omega_ie^n = omega_ie (cos L, 0, -sin L) in local NED."""
from imu_emulator.effects import _earth
from imu_emulator.effects._record import Effect, Stage
from imu_emulator.geo import wgs84


def earth_rate_lines() -> list[str]:
    """omega_ie^n = omega_ie (cos L, 0, -sin L) (t_wi.., NED) and the rate of change of those components,
    t_wp.. = omega_ie L' (-sin L, 0, -cos L) (= -rho x omega_ie^n: omega_ie^e is constant and the level frame
    turns at rho against the Earth)."""
    w = repr(wgs84.OMEGA_IE)
    return [_earth.LATITUDE_RATE, f"t_win = {w} * e_cl", f"t_wid = -{w} * e_sl", f"t_wpn = -{w} * e_sl * t_ld",
            f"t_wpd = -{w} * e_cl * t_ld"]


#: omega_ie^n and its derivative as NED triples (after earth_rate_lines)
EARTH_RATE = (("t_win", "0.0", "t_wid"), ("t_wpn", "0.0", "t_wpd"))


def emit(ctx) -> list[str]:
    return earth_rate_lines() + _earth.add_rate(ctx.scene, *EARTH_RATE)


EFFECT = Effect(
    name="earth_rate",
    description="gyros sense the Earth's rotation (7.292115e-5 rad/s, WGS-84) at the current latitude; "
                "ENU/NED frames are tangent at [scene] origin",
    stage=Stage.NAVIGATION, order=1, emit=emit, nav_rate=True)
