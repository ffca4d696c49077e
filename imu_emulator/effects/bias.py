"""Constant bias and turn-on (run-to-run) bias: the turn-on part is drawn once per run from the seed and held
(not redrawn every sample, the PX4 SITL plugin's bug)."""
from imu_emulator.effects._record import AXES, TRIADS, Effect, Stage, triad_params


def emit(ctx) -> list[str]:
    lines = []
    for triad in TRIADS:
        constant = ctx.value(f"imu.{triad}.bias")
        spread = ctx.value(f"imu.{triad}.turn_on_bias_sd")
        for axis in range(3):
            terms = [ctx.number(constant[axis])] if constant[axis] else []
            if spread[axis]:
                name = f"{triad}.{AXES[axis]}"
                # the state holds the standard normal drawn for this run, on the part's FRD axis; its scale (and
                # the sign into the scene's axes, EmitContext.frd_sign) is a run-time parameter
                z = ctx.state(f"turn_on[{name}]", lambda draw, name=name: draw(name, 0))
                terms.append(f"{ctx.number(spread[axis] * ctx.frd_sign(axis))} * {z}")
            if terms:
                lines += ctx.add_bias(triad, axis, " + ".join(terms))
    return lines


EFFECT = Effect(
    name="bias",
    description="constant bias plus a turn-on bias drawn once per run (seeded) with a given standard deviation",
    stage=Stage.SENSOR, order=60, emit=emit, random=True, state=("turn_on",),
    params=(*triad_params("bias", "rad/s", "m/s^2", "constant bias", gyro_datasheet="`0.1 deg/s`",
                          accel_datasheet="`20 mg`"),
            *triad_params("turn_on_bias_sd", "rad/s", "m/s^2", "turn-on (run-to-run) bias, standard deviation",
                          gyro_datasheet="`0.2 deg/s`", accel_datasheet="`5 mg`")))
