"""Coriolis and transport rate: f gains 2 omega_ie x v; the gyros sense omega_en, the turning of the local
level frame as it follows the vehicle over the curved Earth (Groves 2nd ed. §5.4)."""
from imu_emulator.geo import wgs84
from imu_emulator.motion.earth import TRANSPORT_RATE, rho_lines
from imu_emulator.effects import _earth
from imu_emulator.effects._record import Effect, Stage


def emit(ctx) -> list[str]:
    w2 = repr(2.0 * wgs84.OMEGA_IE)
    scene = ctx.scene
    # 2 omega_ie^n x v^n with omega_ie^n = omega (cos L, 0, -sin L)
    coriolis = _earth.add(scene, "fn", f"{w2} * e_sl * e_ve", f"-{w2} * (e_sl * e_vn + e_cl * e_vd)",
                          f"{w2} * e_cl * e_ve")
    # omega_en^n = (v_E / (R_E + h), -v_N / (R_N + h), -v_E tan L / (R_E + h)) and its derivative
    # (imu_emulator.motion.earth.rho_lines); tan L: the NED frame itself is undefined at the poles
    return coriolis + rho_lines() + _earth.add_rate(scene, *TRANSPORT_RATE)


EFFECT = Effect(
    name="coriolis",
    description="Coriolis force 2 omega_ie x v on the accelerometers and the transport rate omega_en on the "
                "gyros",
    stage=Stage.NAVIGATION, order=2, emit=emit, nav_rate=True)
