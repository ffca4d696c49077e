"""Bias instability: a flicker floor at 0.664 B in the Allan deviation (IEEE 952), realized as a sum of
stationary Gauss-Markov processes with poles one per decade over [tau_min, tau_max] (defaults 0.1 s .. 1e4 s,
not tied to the sample rate), each of standard deviation 0.856 B (spec: sensor-errors.md; the floor stays
within -5.4 % / +0.9 % of 0.664 B from 3 tau_min to tau_max / 3). Also the plain Gauss-Markov form (sigma,
correlation time) of Kalibr / RotorS.

Exact discretization x' = a x + sigma sqrt(1 - a^2) w, a = exp(-h / tau), x_0 drawn from N(0, sigma^2) (a
stationary start, neither 0 nor +sigma). Slow processes step on grids of h = m_p dt (at most tau / STEPS_PER_TAU,
tau / FLICKER_STEPS_PER_TAU for the flicker poles) and are interpolated linearly between knots: what that changes
is at cluster times below h, where the faster poles and the white noise dominate; the Allan-recovery tests
measure the result."""
import math

from imu_emulator.effects._record import AXES, TRIADS, Effect, Param, Stage, triad_params
from imu_emulator.errors import SceneError

SIGMA_PER_B = 0.856
#: a plain Gauss-Markov process steps at least STEPS_PER_TAU times per tau (its per-knot statistics are
#: exact, the straight lines between knots its only approximation); a pole of the flicker sum at least
#: FLICKER_STEPS_PER_TAU times: only the sum's Allan curve is promised, and interpolating a pole over tau / 10
#: changes it by far less than its confidence intervals at tau >= 0.1 s (tests/effects/test_allan.py, the 2 h tests and
#: tests/scene/test_presets.py pass at 10 as at 20; the per-pole variance dips by (1 - exp(-1/10)) / 2 = 4.8 % midway
#: between knots, 0.8 % of a six-pole sum). 10 rather than 20 halves the knot work: -5 ns/sample of the full
#: model (tools/bench_bias_instability.py --steps 20,10)
STEPS_PER_TAU = 100
FLICKER_STEPS_PER_TAU = 10


def poles(tau_min: float, tau_max: float) -> list[float]:
    out, tau = [], tau_min
    while tau <= tau_max * (1 + 1e-9):
        out.append(tau)
        tau *= 10.0
    return out


def _steps(tau: float, dt: float, per_tau: int = STEPS_PER_TAU) -> int:
    return max(1, int(tau / (per_tau * dt)))


def _coefficients(sigma: float, tau: float, h: float) -> tuple[float, float]:
    """x' = a x + q w over a step h: a = exp(-h / tau), q = sigma sqrt(1 - a^2)."""
    return math.exp(-h / tau), sigma * math.sqrt(-math.expm1(-2.0 * h / tau))


def _processes(values: dict, triad: str, axis: int, dt: float) -> list[tuple[str, float, float, int]]:
    """(stream name, stationary sigma, tau, samples per step at most) of one axis."""
    b = values[f"imu.{triad}.bias_instability"][axis]
    band = poles(values[f"imu.{triad}.bias_instability_tau_min_s"], values[f"imu.{triad}.bias_instability_tau_max_s"])
    found = [(f"{triad}.{AXES[axis]}.p{i}", SIGMA_PER_B * b, tau, _steps(tau, dt, FLICKER_STEPS_PER_TAU))
             for i, tau in enumerate(band)] if b else []
    if values[f"imu.{triad}.gauss_markov_sigma"][axis]:
        tau = values[f"imu.{triad}.gauss_markov_tau_s"][axis]
        found.append((f"{triad}.{AXES[axis]}.gm", values[f"imu.{triad}.gauss_markov_sigma"][axis], tau,
                      _steps(tau, dt)))
    return found


def _grids(every: dict, m: int) -> dict[str, int]:
    """Each slow process's grid m_p: a multiple of m, and of the grid of the next faster process of its axis,
    at most its own step count (the flicker poles of an axis nest, so the knot code tests one remainder per
    level and only when the level above stepped)."""
    grids = {}
    for procs in every.values():
        below = m
        for name, _, _, steps in sorted((p for p in procs if p[3] > 1), key=lambda p: p[3]):
            grids[name] = below * (steps // below)      # steps >= below: sorted, and below <= its steps
            below = grids[name]
    return grids


def emit(ctx) -> list[str]:
    """Fast processes (one step per sample) step every sample. The slow ones of this IMU share one grid of m
    samples (the smallest slow step count), and each axis interpolates linearly between the sums of its slow
    processes at two grid knots: one interpolation per axis and sample, whatever the number of poles. A slow
    process steps exactly on its own coarser grid of m_p samples (a multiple of m, so its value at the m-knots,
    the straight line between its own knots, interpolated again between m-knots is that same straight line): a
    pole of tau = 1e4 s draws a normal every m_p samples, not every m. The knot code runs once every m samples:
    one remainder test per grid level, deeper levels only when the level above stepped."""
    every = {(triad, axis): _processes(ctx.imu.values, triad, axis, ctx.dt) for triad in TRIADS for axis in range(3)}
    slow_steps = [steps for procs in every.values() for *_, steps in procs if steps > 1]
    m = min(slow_steps) if slow_steps else 1
    grids = _grids(every, m)
    adds, after, shift, sums = [], [], [], []
    advance: dict[int, list[str]] = {}       # m_p -> lines stepping the processes on that grid
    r = ctx.var("r")
    for (triad, axis), procs in every.items():
        terms, nexts, slow = [], [], []
        for name, sigma, tau, steps in procs:
            if steps == 1:   # x_s is read, then x_{s+1} = a x_s + q w
                a, q = _coefficients(sigma, tau, ctx.dt)
                x = ctx.state(f"gm[{name}]", lambda draw, sigma=sigma, name=name: sigma * draw(name, 0))
                terms.append(x)
                after.append(f"{x} = {ctx.number(a)} * {x} + {ctx.number(q)} * {ctx.normal(name, '(s + 1)')}")
            else:
                slow.append((name, sigma, grids[name], *_coefficients(sigma, tau, grids[name] * ctx.dt)))
        if not slow:
            if terms:
                adds += ctx.add_bias(triad, axis, _in_scene_axes(ctx, axis, terms))
            continue

        # the sums sa, sb of the slow processes at m-knots i = s // m and i + 1; each process keeps its values xa,
        # xb at its own knots j = s // m_p and j + 1 (xa only when m_p > m: at m-knots it is interpolated)
        def at_next_knot(xa, xb, m_p):
            return xb if m_p == m else xa + (xb - xa) * (m / m_p)

        # the slow processes' own knot values live in the state array, read and written in place by the knot
        # code only: as locals they were some 60 values carried around the sample loop, which the register
        # allocator spilled and reloaded every sample (about 5 ns/sample of the full model). Their initial
        # draws are the state block's streams ("gm.<name>"), so the sums sa, sb start from the same values.
        def start(draw, slow=slow):
            return sum(sigma * draw(f"gm.{name}", 0) for name, sigma, *_ in slow)

        def start_next(draw, slow=slow):
            return sum(at_next_knot(sigma * draw(f"gm.{name}", 0),
                                    a * sigma * draw(f"gm.{name}", 0) + q * draw(f"gm.{name}", 1), m_p)
                       for name, sigma, m_p, a, q in slow)
        label = f"{triad}.{AXES[axis]}"
        sa = ctx.state(f"gm[{label}.sa]", start)
        sb = ctx.state(f"gm[{label}.sb]", start_next)
        shift.append(f"{sa} = {sb}")
        for name, sigma, m_p, a, q in slow:
            initials = [lambda draw, name=name, sigma=sigma, a=a, q=q: a * sigma * draw(name, 0) + q * draw(name, 1)]
            if m_p != m:
                initials.append(lambda draw, name=name, sigma=sigma: sigma * draw(name, 0))
            base = ctx.state_block("gm", initials)
            xb, xa = f"state[{base}]", f"state[{base + 1}]"
            step = f"{xb} = {ctx.number(a)} * {xb} + {ctx.number(q)} * {ctx.normal(name, f'(s // {m_p} + 1)')}"
            if m_p == m:
                advance.setdefault(m_p, []).append(step)
                nexts.append(xb)
                continue
            advance.setdefault(m_p, []).extend([f"{xa} = {xb}", step])
            nexts.append(f"({xa} + ({xb} - {xa}) * {ctx.var(f'w{m_p}')})")
        sums.append(f"{sb} = {' + '.join(nexts)}")
        terms.append(f"({sa} + ({sb} - {sa}) * ({r} * {1.0 / m!r}))")
        adds += ctx.add_bias(triad, axis, _in_scene_axes(ctx, axis, terms))
    if not shift:
        return adds + after
    knot = shift + _nested(sorted(advance), advance, m)
    # where each coarser grid's straight line is at the next m-knot
    knot += [f"{ctx.var(f'w{m_p}')} = (s % {m_p} + {m}) * {1.0 / m_p!r}" for m_p in sorted(advance) if m_p != m]
    knot += sums
    return [f"{r} = s % {m}", f"if {r} == 0 and s > 0:", *("    " + line for line in knot)] + adds + after


def _in_scene_axes(ctx, axis: int, terms: list[str]) -> str:
    """The axis' processes summed, in the scene's sensor axes: they are drawn on the part's forward-right-down
    axis (EmitContext.frd_sign), and every process is linear in its draws, so negating the sum is negating each
    draw, exactly (IEEE rounding is symmetric)."""
    total = " + ".join(terms)
    return total if ctx.frd_sign(axis) > 0 else f"-({total})"


def _nested(levels: list[int], advance: dict, m: int) -> list[str]:
    """The stepping lines of each grid, inside the block of the coarsest finer grid it is a multiple of (so its
    remainder is tested only when that one stepped); the m grid steps at every knot, untested."""
    parent = {g: max((h for h in levels if h < g and g % h == 0), default=None) for g in levels}

    def block(g: int) -> list[str]:
        body = list(advance[g])
        for child in (c for c in levels if parent[c] == g):
            body += block(child)
        return body if g == m else [f"if s % {g} == 0:", *("    " + line for line in body)]
    return [line for g in levels if parent[g] is None for line in block(g)]


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
