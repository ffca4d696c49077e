"""Bias instability: a flicker floor at 0.664 B in the Allan deviation (IEEE 952), realized as a sum of
stationary Gauss-Markov processes with poles one per decade over [tau_min, tau_max] (defaults 0.1 s .. 1e4 s,
not tied to the sample rate), each of standard deviation 0.856 B (spec: sensor-errors.md; the floor stays
within -5.4 % / +0.9 % of 0.664 B from 3 tau_min to tau_max / 3). Also the plain Gauss-Markov form (sigma,
correlation time) of Kalibr / RotorS.

Exact discretization x' = a x + sigma sqrt(1 - a^2) w, a = exp(-h / tau), x_0 drawn from N(0, sigma^2) (a
stationary start, neither 0 nor +sigma). Slow poles step on a grid of m samples (h = m dt at most the fastest slow
tau / STEPS_PER_TAU) and are interpolated linearly between knots: what that changes is at cluster times below
h, where the faster poles dominate the sum; the Allan-recovery tests measure the result."""
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


def _steps(tau: float, dt: float) -> int:
    return max(1, int(tau / (STEPS_PER_TAU * dt)))


def _coefficients(sigma: float, tau: float, h: float) -> tuple[float, float]:
    """x' = a x + q w over a step h: a = exp(-h / tau), q = sigma sqrt(1 - a^2)."""
    return math.exp(-h / tau), sigma * math.sqrt(-math.expm1(-2.0 * h / tau))


def _processes(values: dict, triad: str, axis: int) -> list[tuple[str, float, float]]:
    b = values[f"imu.{triad}.bias_instability"][axis]
    band = poles(values[f"imu.{triad}.bias_instability_tau_min_s"], values[f"imu.{triad}.bias_instability_tau_max_s"])
    found = [(f"{triad}.{AXES[axis]}.p{i}", SIGMA_PER_B * b, tau) for i, tau in enumerate(band)] if b else []
    if values[f"imu.{triad}.gauss_markov_sigma"][axis]:
        found.append((f"{triad}.{AXES[axis]}.gm", values[f"imu.{triad}.gauss_markov_sigma"][axis],
                      values[f"imu.{triad}.gauss_markov_tau_s"][axis]))
    return found


def emit(ctx) -> list[str]:
    """Fast processes (tau < 2 * STEPS_PER_TAU * dt) step every sample. The slow ones of this IMU all step on one
    common grid of m samples (the fastest slow pole's tau / STEPS_PER_TAU, so at least every 100th of any
    slow tau), exactly for h = m dt, and each axis interpolates linearly between the sums of its slow
    processes at two knots: one interpolation per axis and sample, whatever the number of poles."""
    every = {(triad, axis): _processes(ctx.imu.values, triad, axis) for triad in TRIADS for axis in range(3)}
    slow_steps = [_steps(tau, ctx.dt) for procs in every.values() for _, _, tau in procs if _steps(tau, ctx.dt) > 1]
    m = min(slow_steps) if slow_steps else 1
    step, adds, after = [], [], []
    r = ctx.var("r")
    for (triad, axis), procs in every.items():
        terms = []
        slow = []
        for name, sigma, tau in procs:
            if _steps(tau, ctx.dt) == 1:   # x_s is read, then x_{s+1} = a x_s + q w
                a, q = _coefficients(sigma, tau, ctx.dt)
                x = ctx.state(f"gm[{name}]", lambda draw, sigma=sigma, name=name: sigma * draw(name, 0))
                terms.append(x)
                after.append(f"{x} = {a!r} * {x} + {q!r} * {ctx.normal(name, '(s + 1)')}")
            else:
                slow.append((name, sigma, *_coefficients(sigma, tau, m * ctx.dt)))
        if slow:
            # knots i = s // m and i + 1: sums sa, sb of the slow processes; each process keeps its value at i + 1
            def start(draw, slow=slow):
                return sum(sigma * draw(name, 0) for name, sigma, _, _ in slow)

            def start_next(draw, slow=slow):
                return sum(a * sigma * draw(name, 0) + q * draw(name, 1) for name, sigma, a, q in slow)
            label = f"{triad}.{AXES[axis]}"
            sa = ctx.state(f"gm[{label}.sa]", start)
            sb = ctx.state(f"gm[{label}.sb]", start_next)
            step.append(f"    {sa} = {sb}")
            nexts = []
            for name, sigma, a, q in slow:
                xb = ctx.state(f"gm[{name}.b]", lambda draw, name=name, sigma=sigma, a=a, q=q:
                               a * sigma * draw(name, 0) + q * draw(name, 1))
                step.append(f"    {xb} = {a!r} * {xb} + {q!r} * {ctx.normal(name, f'(s // {m} + 1)')}")
                nexts.append(xb)
            step.append(f"    {sb} = {' + '.join(nexts)}")
            terms.append(f"({sa} + ({sb} - {sa}) * ({r} * {1.0 / m!r}))")
        if terms:
            adds += ctx.add_bias(triad, axis, " + ".join(terms))
    before = [f"{r} = s % {m}", f"if {r} == 0 and s > 0:", *step] if step else []
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
                    shape="scalar", default=0.1, example=0.2) for t in TRIADS),
            *(Param("bias_instability_tau_max_s", f"imu.{t}", "s", f"{t}: slowest pole of the flicker band",
                    shape="scalar", default=1e4, example=2000.0) for t in TRIADS),
            *triad_params("gauss_markov_sigma", "rad/s", "m/s^2", "first-order Gauss-Markov bias, stationary sigma"),
            *triad_params("gauss_markov_tau_s", "s", "s", "first-order Gauss-Markov bias, correlation time")))
