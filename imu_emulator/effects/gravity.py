"""Gravity: accelerometers measure specific force f = a - g (at rest, level, ENU: f = (0, 0, +g))."""
from imu_emulator.geo import wgs84
from imu_emulator.effects import _earth
from imu_emulator.effects._record import Effect, Stage


def emit(ctx) -> list[str]:
    scene = ctx.scene
    if not scene.earth_model:
        # g = (0, 0, -g0) in ENU, (0, 0, +g0) in NED; g0 is [scene] gravity_mps2
        sign = "+" if scene.frame == "ENU" else "-"
        return [f"fnz = fnz {sign} {float(scene.gravity_mps2)!r}"]
    lines = []     # the Earth geometry (e_*) comes with the motion (imu_emulator.motion.earth)
    if scene.gravity_model == "wgs84":
        # normal gravity (Somigliana, TR8350.2 eq. 4-3) along the ellipsoid normal, and its north component
        # off the ellipsoid (imu_emulator.geo.wgs84.normal_gravity_north: -8.1e-9 h sin 2L m/s^2)
        k, f, m, a = (repr(x) for x in (wgs84.K_SOMIGLIANA, wgs84.F, wgs84.M_RATIO, wgs84.A))
        lines += [
            "e_s2 = e_sl * e_sl",
            f"e_g = {wgs84.GAMMA_E!r} * (1.0 + {k} * e_s2) / e_w * (1.0 - {repr(2.0 / wgs84.A)} * "
            f"(1.0 + {f} + {m} - {repr(2.0 * wgs84.F)} * e_s2) * e_h + {repr(3.0 / wgs84.A ** 2)} * e_h * e_h)",
            f"e_gn = {repr(-2.0 * wgs84.NORTH_GRAVITY_COEF)} * e_sl * e_cl * ({k} * e_w * e_w + "
            f"(1.0 + {k} * e_s2) * {repr(0.5 * wgs84.E2)}) * e_h",
        ]
        return lines + _earth.add(scene, "fn", "-e_gn", "0.0", "-e_g")
    return _earth.add(scene, "fn", "0.0", "0.0", f"-{float(scene.gravity_mps2)!r}")


EFFECT = Effect(
    name="gravity",
    description="specific force includes -g (at rest, level, ENU: f = (0, 0, +g)); g0 is [scene] gravity_mps2, "
                "or WGS-84 normal gravity with [scene] gravity_model = \"wgs84\"",
    stage=Stage.NAVIGATION, order=0, emit=emit)
