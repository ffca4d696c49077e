"""Coriolis and transport rate: f gains 2 omega_ie x v; the gyros sense omega_en, the turning of the local
level frame as it follows the vehicle over the curved Earth (Groves 2nd ed. §5.4)."""
from imu_emulator.effects import _earth
from imu_emulator.effects._record import Effect, Stage
from imu_emulator.geo import wgs84


def rho_lines() -> list[str]:
    """rho = omega_en^n (t_rh..), v^n' (t_d..) and rho' (t_rp..) in NED, from the geometry's e_* (the motion's
    tangent attitude and [attitude] reference read them too: imu_emulator.motion.earth.tangent_level_lines)."""
    a, e2 = wgs84.A, wgs84.E2
    lines = [
        _earth.LATITUDE_RATE,
        "t_tl = e_sl / e_cl",
        "t_rhn = e_ve / e_re",
        "t_rhe = -e_vn / e_rn",
        "t_rhd = -t_rhn * t_tl",
    ]
    rho = _earth.ned("t_rh")
    lines += _earth.cross("t_rv", rho, _earth.ned("e_v"))
    lines += [f"t_d{axis} = e_a{axis} - t_rv{axis}" for axis in "ned"]
    lines += [
        "t_scw = e_sl * e_cl / (e_w * e_w * e_w)",
        f"t_red = {a * e2!r} * t_scw * t_ld - e_vd",                    # (R_E + h)'
        f"t_rnd = {3.0 * a * (1.0 - e2) * e2!r} * t_scw / (e_w * e_w) * t_ld - e_vd",   # (R_N + h)'
        "t_rpn = (t_de - t_rhn * t_red) / e_re",
        "t_rpe = -(t_dn + t_rhe * t_rnd) / e_rn",
        "t_rpd = -t_rpn * t_tl - t_rhn * t_ld / (e_cl * e_cl)",
    ]
    return lines


#: rho and rho' as NED triples (after rho_lines)
TRANSPORT_RATE = (_earth.ned("t_rh"), _earth.ned("t_rp"))


def emit(ctx) -> list[str]:
    w2 = repr(2.0 * wgs84.OMEGA_IE)
    scene = ctx.scene
    # 2 omega_ie^n x v^n with omega_ie^n = omega (cos L, 0, -sin L)
    coriolis = _earth.add(scene, "fn", f"{w2} * e_sl * e_ve", f"-{w2} * (e_sl * e_vn + e_cl * e_vd)",
                          f"{w2} * e_cl * e_ve")
    # omega_en^n = (v_E / (R_E + h), -v_N / (R_N + h), -v_E tan L / (R_E + h)) and its derivative
    # (rho_lines); tan L: the NED frame itself is undefined at the poles
    return coriolis + rho_lines() + _earth.add_rate(scene, *TRANSPORT_RATE)


EFFECT = Effect(
    name="coriolis",
    description="Coriolis force 2 omega_ie x v on the accelerometers and the transport rate omega_en on the "
                "gyros",
    stage=Stage.NAVIGATION, order=2, emit=emit, nav_rate=True)
