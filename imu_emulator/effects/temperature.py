"""Temperature: a temperature profile per IMU and the bias and scale-factor temperature coefficients.

T(t) = temperature_c (a number or an expression in t, °C) + warmup_rise_c·(1 − e^(−t/warmup_tau_s)) (the
warm-up exponential, from the scene's t = 0); then per axis v ← v + b₁·(T − T₀) + s₁·(T − T₀)·v_true with T₀ =
temperature_ref_c. The profile also reaches the samples (SampleBlock.temperature_c), so formats that carry a
temperature send this one. Coefficients are per kelvin of difference ("0.015 deg/s/K", "0.2 mg/K",
"30 ppm/K"; degC is accepted for K, as a difference)."""
from imu_emulator.effects._linear import TRUE
from imu_emulator.effects._record import AXES, TRIADS, Effect, Param, Stage, triad_params
from imu_emulator.errors import SceneError


def _tree(values: dict):
    from imu_emulator.numerics import expressions
    return expressions.check(values["imu.temperature_c"], "imu.temperature_c", set())


def profile(values: dict, t):
    """The temperature (°C) of an IMU at the times t (numpy), as the kernel computes it."""
    import numpy as np

    from imu_emulator.numerics import expressions
    temperature = expressions.evaluate_array(_tree(values), {}, t)
    rise, tau = values["imu.warmup_rise_c"], values["imu.warmup_tau_s"]
    return temperature + rise * -np.expm1(-np.asarray(t) / tau) if rise else np.array(temperature)


def emit(ctx) -> list[str]:
    from imu_emulator.numerics import expressions
    values = ctx.imu.values
    temperature = ctx.var("T")
    lines = [f"{temperature} = {expressions.to_code(_tree(values), {})}"]
    if values["imu.warmup_rise_c"]:
        rise, tau = ctx.number(values["imu.warmup_rise_c"]), ctx.number(values["imu.warmup_tau_s"])
        lines.append(f"{temperature} += {rise} * -math.expm1(-t / {tau})")
    delta = ctx.var("dT")
    lines.append(f"{delta} = {temperature} - {ctx.number(values['imu.temperature_ref_c'])}")
    terms = []
    for triad, (_, out, _) in TRIADS.items():
        for axis in range(3):
            b1 = ctx.value(f"imu.{triad}.bias_tc")[axis]
            s1 = ctx.value(f"imu.{triad}.scale_tc")[axis]
            if b1:
                terms += ctx.add_bias(triad, axis, f"{ctx.number(b1)} * {delta}")
            if s1:
                terms.append(f"{out}{AXES[axis]} += {ctx.number(s1)} * {delta} * {TRUE[triad][axis]}")
    return lines + terms if terms else []


def validate(values: dict, where: str) -> None:
    if values["imu.warmup_rise_c"] and not values["imu.warmup_tau_s"] > 0:
        raise SceneError(f"{where}.warmup_tau_s: a positive time constant is needed with warmup_rise_c")


EFFECT = Effect(
    name="temperature",
    description="temperature profile (constant, expression in t, warm-up) with bias and scale-factor coefficients",
    stage=Stage.SENSOR, order=40, emit=emit, validate=validate,
    params=(Param("temperature_c", "imu", "degC", "temperature profile: a number or an expression in t (°C)",
                  shape="expression", default=25.0, datasheet="`25`, `\"25 + 0.01*t\"`"),
            Param("warmup_rise_c", "imu", "K", "warm-up: rise of the exponential from t = 0", shape="scalar",
                  datasheet="`15`"),
            Param("warmup_tau_s", "imu", "s", "warm-up: time constant", shape="scalar", default=600.0),
            Param("temperature_ref_c", "imu", "K", "reference temperature T0 of the coefficients (°C)",
                  shape="scalar", default=25.0),
            *triad_params("bias_tc", "rad/s/K", "m/s^2/K", "bias temperature coefficient b1",
                          gyro_datasheet="`0.015 deg/s/K`", accel_datasheet="`0.2 mg/K`"),
            *triad_params("scale_tc", "1/K", "1/K", "scale-factor temperature coefficient s1",
                          gyro_datasheet="`0.03 %/K`", accel_datasheet="`100 ppm/K`")))
