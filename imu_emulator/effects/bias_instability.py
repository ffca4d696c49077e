"""Bias instability: a flicker floor at 0.664 B in the Allan deviation (IEEE 952), realized as a sum of
stationary Gauss-Markov processes with poles one per decade over [tau_min, tau_max] (defaults 0.1 s .. 1e4 s,
not tied to the sample rate), each of standard deviation 0.856 B (spec: sensor-errors.md; the floor stays
within -5.4 % / +0.9 % of 0.664 B from 3 tau_min to tau_max / 3). Also the plain Gauss-Markov form (sigma,
correlation time) of Kalibr / RotorS.

Exact discretization x' = a x + sigma sqrt(1 - a^2) w, a = exp(-h / tau), x_0 drawn from N(0, sigma^2) (a
stationary start, neither 0 nor +sigma). A slow pole steps every m samples (h = m dt, m = tau / (STEPS_PER_TAU
dt) rounded down) and is interpolated linearly between its knots: what that changes is at cluster times below
h = tau / STEPS_PER_TAU, where the faster poles dominate the sum; the Allan-recovery tests measure the result."""
import math

from imu_emulator.effects._record import AXES, TRIADS, Effect, Param, Stage, triad_params
from imu_emulator.errors import SceneError

SIGMA_PER_B = 0.856
STEPS_PER_TAU = 100


def poles(tau_min: float, tau_max: float) -> list[float]:
    out, tau = [], tau_min
    while tau <= tau_max * (1 + 1e-9):
        out.append(tau)
        tau *= 10.0
    return out


def _process(ctx, name: str, sigma: float, tau: float) -> tuple[list[str], str, list[str]]:
    """One Gauss-Markov process at run sample s: lines before its value is read, its value, lines after."""
    m = max(1, int(tau / (STEPS_PER_TAU * ctx.dt)))
    h = m * ctx.dt
    a = math.exp(-h / tau)
    q = sigma * math.sqrt(-math.expm1(-2.0 * h / tau))
    if m == 1:   # x_s is read, then x_{s+1} = a x_s + q w
        x = ctx.state(f"gm[{name}]", lambda draw: sigma * draw(name, 0))
        return [], x, [f"{x} = {a!r} * {x} + {q!r} * {ctx.normal(name, '(s + 1)')}"]
    # knots i and i + 1 around sample s (i = s // m); crossing a knot steps them before the value is read
    xa = ctx.state(f"gm[{name}.a]", lambda draw: sigma * draw(name, 0))
    xb = ctx.state(f"gm[{name}.b]", lambda draw: a * sigma * draw(name, 0) + q * draw(name, 1))
    r = ctx.var(f"r_{name.replace('.', '_')}")
    before = [f"{r} = s % {m}",
              f"if {r} == 0 and s > 0:",
              f"    {xa} = {xb}",
              f"    {xb} = {a!r} * {xb} + {q!r} * {ctx.normal(name, f'(s // {m} + 1)')}"]
    return before, f"({xa} + ({xb} - {xa}) * ({r} * {1.0 / m!r}))", []


def _processes(values: dict, triad: str, axis: int) -> list[tuple[str, float, float]]:
    b = values[f"imu.{triad}.bias_instability"][axis]
    band = poles(values[f"imu.{triad}.bias_instability_tau_min_s"], values[f"imu.{triad}.bias_instability_tau_max_s"])
    found = [(f"{triad}.{AXES[axis]}.p{i}", SIGMA_PER_B * b, tau) for i, tau in enumerate(band)] if b else []
    if values[f"imu.{triad}.gauss_markov_sigma"][axis]:
        found.append((f"{triad}.{AXES[axis]}.gm", values[f"imu.{triad}.gauss_markov_sigma"][axis],
                      values[f"imu.{triad}.gauss_markov_tau_s"][axis]))
    return found


def emit(ctx) -> list[str]:
    before, adds, after = [], [], []
    for triad in TRIADS:
        for axis in range(3):
            terms = []
            for name, sigma, tau in _processes(ctx.imu.values, triad, axis):
                pre, value, post = _process(ctx, name, sigma, tau)
                before += pre
                after += post
                terms.append(value)
            if terms:
                adds += ctx.add_bias(triad, axis, " + ".join(terms))
    return before + adds + after


def validate(values: dict, where: str) -> None:
    for triad in TRIADS:
        lo = values[f"imu.{triad}.bias_instability_tau_min_s"]
        hi = values[f"imu.{triad}.bias_instability_tau_max_s"]
        if not 0 < lo <= hi:
            raise SceneError(f"{where}.{triad}.bias_instability_tau_min_s: need 0 < tau_min <= tau_max, "
                             f"got {lo!r} .. {hi!r}")
        for axis in range(3):
            if values[f"imu.{triad}.gauss_markov_sigma"][axis] and not values[f"imu.{triad}.gauss_markov_tau_s"][axis] > 0:
                raise SceneError(f"{where}.{triad}.gauss_markov_tau_s: a positive correlation time is needed "
                                 f"where gauss_markov_sigma is given (axis {AXES[axis]})")


EFFECT = Effect(
    name="bias_instability",
    description="bias instability: flicker floor 0.664 B (sum of Gauss-Markov poles), and/or one Gauss-Markov bias",
    stage=Stage.SENSOR, order=61, emit=emit, validate=validate, random=True, state=("gm",),
    params=(*triad_params("bias_instability", "rad/s", "m/s^2", "bias instability B (Allan floor 0.664 B)",
                          gyro_datasheet="`10 deg/h`", accel_datasheet="`30 ug`, `0.03 mg`"),
            *(Param("bias_instability_tau_min_s", f"imu.{t}", "s", f"{t}: fastest pole of the flicker band",
                    shape="scalar", default=0.1) for t in TRIADS),
            *(Param("bias_instability_tau_max_s", f"imu.{t}", "s", f"{t}: slowest pole of the flicker band",
                    shape="scalar", default=1e4) for t in TRIADS),
            *triad_params("gauss_markov_sigma", "rad/s", "m/s^2", "first-order Gauss-Markov bias, stationary sigma"),
            *triad_params("gauss_markov_tau_s", "s", "s", "first-order Gauss-Markov bias, correlation time")))
