"""Vibration: motion of the IMU relative to the body (issue 9), not noise on its outputs.

Linear vibration is a displacement d(t) of the IMU in body axes. It is a moving lever arm, so the IMU feels
f += d'' + 2 w x d' + alpha x d + w x (w x d) (w, alpha: the body's inertial rate and its derivative), exactly.
Angular vibration turns the IMU's axes against the body's by R_v = Rx(a) Ry(b) Rz(c) (a, b, c: the angles
about body x, y, z), so the sensor sees R_v^T f, and R_v^T w plus the relative rate
a' (cos c cos b, -sin c cos b, sin b) + b' (sin c, cos c, 0) + c' (0, 0, 1). Because it is motion, coning
(angular lines on two axes out of phase) and sculling (angular with linear) appear in the outputs as they
would on a shaker. The attitude output (the IMU's quaternion) is the body's, turned by R_v, then by the mounting:
the IMU's axes really turn. (--truth roll, pitch, yaw stay the body's, like its position at the reference point.)

- `sines`: lines {axis, amplitude, frequency, phase}; the amplitude is what the sensor on that axis sees:
  linear (an acceleration, "2 g") gives d'' = A sin(2 pi f t + phase), angular (a rate, "3 deg/s") gives the
  relative rate A sin(2 pi f t + phase). Plain numbers are m/s^2 unless kind = "angular" (rad/s).
- `psd`: random linear vibration given as an acceleration PSD table ((m/s^2)^2/Hz, e.g. "0.04 g^2/Hz"), one-
  sided as vibration specifications print it, interpolated log-log between breakpoints, zero outside them. On
  each body axis (weighted by psd_axes, a factor on the PSD) it is Gaussian noise of that PSD (issue 25): unit
  white noise w_j (counter-based normals of the axis's stream, j the run sample) through FIR filters of
  psd_lines taps, the acceleration's and its two integrals': H_a = sqrt(S fs / 2) on the taps' frequency grid
  (one-sided S = 2 T |H|^2 for white noise of unit variance at rate fs = 1/T), H_v = H_a / (j 2 pi f),
  H_d = -H_a / (2 pi f)^2, each made a linear-phase FIR (delay psd_lines / 2 samples) and tapered by a Hann
  window. So d'' is the acceleration sampled (whose Welch estimate the tests hold to the table within its
  chi-square interval), and d', d are the same noise through the exact integrators, tapered alike: exact on the
  frequency grid, smoothed between its points by the window (resolution fs / psd_lines), which is what d'' has
  too; they enter the lever-arm terms above unchanged (for a vibration of tens of Hz and more they are small
  beside d''). The table's resolution is the filter's: breakpoints closer than 2 fs / psd_lines are blurred.
  Rows are computed a chunk at a time into the IMU's state, a cache of a pure function of (seed, run sample): the
  same bytes for any block size, and the table's levels are run-time numbers (the filters' coefficients are
  parameters, only their count is structure). Above DIRECT_TAPS lines the FIRs run by FFT (overlap-save,
  imu_emulator.numerics.shaped_noise): chunks of n - psd_lines samples, n = fft_size(psd_lines) >= 2 psd_lines,
  each three transforms (linear; angular: two) of n / 2 log2 n butterflies and n normals; up to DIRECT_TAPS in
  direct form, cheaper for short filters: chunks of 256 samples, orders x psd_lines multiply-adds and at most two
  normals per sample and axis. No sin/cos either way (tools/bench_vibration.py: 3 axes x 256 lines at 1 kHz,
  the FFT costs a quarter to a third of the direct form).
  Between samples (the quadrature nodes of the integrated outputs) the motion is the quintic through
  (d, d', d'') at the samples s - 1 and s, its derivatives with it (cubic through (angle, rate) for angular):
  the increments integrate that interpolant exactly, continuous with the samples. The clock effect's offset does
  not move the vibration: its realization follows the run sample.
- `angular_psd`: random angular vibration, an angular rate PSD table ((rad/s)^2/Hz, "(deg/s)^2/Hz"), realized
  the same way (weights angular_psd_axes, streams of their own) as the relative rate and its integral, the angle:
  each axis turns the IMU's axes exactly as an angular sine does.

Sines above the Nyquist rate (rate_hz / 2) alias, as they do in a MEMS part whose anti-alias filter does not
reach them (a gyro's drive resonance, a shaker's harmonics): the simulation samples the continuous motion and
adds no filter, which would be a property of the part (its bandwidth), not of the vibration. A PSD table's band
above Nyquist is folded the same way into 0 .. rate_hz / 2 (the filter's level at f is the sum of the table's at
every frequency that samples to f); its d' and d are then those of the folded frequency (larger than the true
ones by the frequency ratio, in the small coupling terms only). Scene validation warns once per such sine (with
the frequency it aliases to) and once per PSD table reaching past Nyquist (with the share of its power there).
A PSD band holding fewer than MIN_BINS of the filter's frequency bins (rate_hz / psd_lines apart) is warned
about too: it would be realized coarsely, or not at all.
"""
import math

from imu_emulator.effects._record import AXES, Effect, Param, Stage
from imu_emulator.errors import SceneError

MIN_TAPS, MAX_TAPS = 16, 16384    # psd_lines: taps of the shaping filter (its cost per sample)
MIN_BINS = 4     # fewer of its frequency bins in a PSD band: a warning (the band is realized coarsely)


def psd_level(table, f: float) -> float:
    """The table's level at f (log-log interpolation between breakpoints; f within the table's band)."""
    for (f0, s0), (f1, s1) in zip(table, table[1:]):
        if f <= f1:
            return s0 * (f / f0) ** (math.log(s1 / s0) / math.log(f1 / f0))
    return table[-1][1]


def folded_level(table, f: float, rate_hz: float) -> float:
    """The table's one-sided level folded into [0, rate_hz / 2] at f: the sum over the frequencies that sample
    to f (|f + m rate_hz|, m whole), as a part without anti-alias filter samples them (module doc)."""
    lo, hi = table[0][0], table[-1][0]
    found, m = set(), 0
    while m * rate_hz - f <= hi:
        found |= {abs(m * rate_hz - f), m * rate_hz + f}     # a set: at f = rate_hz / 2 both are one frequency
        m += 1
    return sum(psd_level(table, g) for g in found if lo <= g <= hi and g > 0)


def shaping_taps(table, taps: int, rate_hz: float, weight: float, orders: int) -> list[list[float]]:
    """The FIR taps (reversed: oldest noise first) of order 0 .. orders - 1 (the quantity, its integral, its double
    integral) shaping unit white noise at rate_hz into the table's PSD times weight (module doc)."""
    import numpy as np
    freqs = np.fft.rfftfreq(taps, 1.0 / rate_hz)
    # one-sided S = 2 T |H|^2 for unit white noise at rate 1/T
    magnitude = np.sqrt(np.array([weight * folded_level(table, f, rate_hz) for f in freqs]) * rate_hz / 2.0)
    window = np.hanning(taps + 2)[1:-1]     # nonzero at both ends; ~1 at the centre, where the response sits
    out = []
    for order in range(orders):
        with np.errstate(divide="ignore", invalid="ignore"):
            response = np.where(freqs > 0, magnitude / (2j * np.pi * np.where(freqs > 0, freqs, 1.0)) ** order, 0)
        h = np.roll(np.fft.irfft(response, taps), taps // 2) * window   # linear phase, delay taps // 2
        out.append([float(x) for x in h[::-1]])
    return out


def emit(ctx) -> list[str]:
    sines = ctx.value("imu.vibration.sines")
    taps = int(ctx.value("imu.vibration.psd_lines"))
    # per axis: linear acceleration, velocity, displacement; angular rate and angle (body axes)
    acc, vel, disp = ([ctx.var(f"{q}{a}") for a in AXES] for q in ("acc", "vel", "disp"))
    rate, angle = ([ctx.var(f"{q}{a}") for a in AXES] for q in ("rate", "angle"))
    psd = {kind: _psd_axes(ctx, key) for kind, key in ((0, "psd"), (1, "angular_psd"))}
    linear = sorted({axis for axis, kind, *_ in sines if kind == 0} | set(psd[0]))
    angular = sorted({axis for axis, kind, *_ in sines if kind == 1} | set(psd[1]))
    if not linear and not angular:
        return []
    lines = [f"{v} = 0.0" for i in linear for v in (acc[i], vel[i], disp[i])]
    lines += [f"{v} = 0.0" for i in angular for v in (rate[i], angle[i])]
    sn, cs = ctx.var("sn"), ctx.var("cs")
    for axis, kind, amplitude, frequency, phase in sines:
        w = 2.0 * math.pi * frequency
        number = ctx.number
        lines.append(f"{sn}, {cs} = sincos_cycles({number(frequency)} * t + {number(phase / (2.0 * math.pi))})")
        if kind == 0:   # d'' = A sin, d' = -A/w cos, d = -A/w^2 sin
            lines += [f"{acc[axis]} += {number(amplitude)} * {sn}", f"{vel[axis]} -= {number(amplitude / w)} * {cs}",
                      f"{disp[axis]} -= {number(amplitude / w ** 2)} * {sn}"]
        else:           # rate = A sin, angle = -A/w cos
            lines += [f"{rate[axis]} += {number(amplitude)} * {sn}", f"{angle[axis]} -= {number(amplitude / w)} * {cs}"]
    if psd[0] or psd[1]:
        lines += _filtered_noise(ctx, psd, taps, (acc, vel, disp), (rate, angle))
    if linear:
        d = [disp[i] if i in linear else "0.0" for i in range(3)]
        v = [vel[i] if i in linear else "0.0" for i in range(3)]
        ux, uy, uz = (ctx.var(f"u{a}") for a in AXES)
        lines += [f"{ux} = gwy * {d[2]} - gwz * {d[1]}", f"{uy} = gwz * {d[0]} - gwx * {d[2]}",
                  f"{uz} = gwx * {d[1]} - gwy * {d[0]}"]
        al = ctx.alpha
        for j, a in enumerate(AXES):   # component j of d'' + 2 w x d' + alpha x d + w x (w x d)
            b, c = AXES[(j + 1) % 3], AXES[(j + 2) % 3]
            jb, jc = (j + 1) % 3, (j + 2) % 3
            term = acc[j] if j in linear else "0.0"
            lines.append(f"fa{a} += {term} + 2.0 * (gw{b} * {v[jc]} - gw{c} * {v[jb]}) "
                         f"+ ({al[jb]} * {d[jc]} - {al[jc]} * {d[jb]}) + (gw{b} * {ctx.var('u' + c)} - gw{c} * "
                         f"{ctx.var('u' + b)})")
    if angular:
        lines += _rotate(ctx, angular, rate, angle)
        ctx.turn_axes(*_quaternion(ctx, angular, angle))
    return lines


def _filtered_noise(ctx, psd, taps: int, linear_vars, angular_vars) -> list[str]:
    """Lines adding each PSD axis's filtered noise (linear: a, v, d; angular: rate, angle) at this instant: the
    sample's rows of its chunk, or between the run samples s - 1 and s (the increments' quadrature nodes) the
    Hermite interpolant of those two rows."""
    size, coefficients, fill = _chunk_filler(ctx, taps)
    u, row, chunk = ctx.var("u"), ctx.var("row"), ctx.var("chunk")
    # where this instant sits between the samples s - 1 (u = 0) and s (u = 1): the quadrature's nodes lie inside,
    # the sample itself at 1 (to rounding, which the clamp and the exact branch below take out)
    lines = [f"{u} = min(1.0, max(0.0, 1.0 + (t - {ctx.plan.t0}) / {ctx.plan.dt} - k))",
             f"{chunk} = s // {size}", f"{row} = s - {chunk} * {size} + 1"]
    for kind, per_axis in psd.items():
        orders = 3 if kind == 0 else 2
        # targets: (value, first integral, second integral) of the acceleration, (rate, angle) of the angular rate
        targets = [linear_vars[0], linear_vars[1], linear_vars[2]] if kind == 0 else list(angular_vars)
        for axis, weight in per_axis.items():
            a = AXES[axis]
            # drawn on the part's forward-right-down axis: the sign into the scene's body axes
            # (EmitContext.frd_sign) rides on the filters' coefficients, an exact negation through every product
            # and sum, so an ENU and a NED scene vibrate alike to the bit
            sign = ctx.frd_sign(axis)
            h = ctx.constant(f"H{kind}{a}", [sign * x for order in shaping_taps(
                ctx.value(f"imu.vibration.{('psd', 'angular_psd')[kind]}"), taps, ctx.scene.rate_hz, weight,
                orders) for x in coefficients(order)])
            block = ctx.state_block(STATES[kind], [lambda draw: -1.0] + [lambda draw: 0.0] * ((size + 1) * orders))
            cached, out = block, block + 1
            key = ctx.stream_key(f"{STATES[kind]}.{a}")
            here = [f"state[{out} + {row} * {orders} + {o}]" for o in range(orders)]
            before = [f"state[{out} + ({row} - 1) * {orders} + {o}]" for o in range(orders)]
            got = [ctx.var(f"y{kind}{o}{a}") for o in range(orders)]
            # the value first, then its integrals: the interpolants take the highest integral first
            hermite = "hermite5" if orders == 3 else "hermite3"
            args = ", ".join(x for pair in (before[::-1], here[::-1]) for x in pair)
            lines += [f"if state[{cached}] != {chunk}:",   # a chunk not cached yet: compute it
                      f"    {fill(key, chunk, orders, h, out)}",
                      f"    state[{cached}] = {chunk}",
                      f"if {u} > {1.0 - 1e-6!r}:",   # the sample (nodes stay below 1 - 5e-3)
                      *[f"    {g} = {x}" for g, x in zip(got, here)],
                      "else:",
                      f"    {', '.join(got[::-1])} = {hermite}({u}, {ctx.plan.dt}, {args})"]
            lines += [f"{targets[o][axis]} += {got[o]}" for o in range(orders)]
    return lines


STATES = {0: "noise", 1: "angular_noise"}
#: psd_lines up to this: the direct-form FIR (chunks of CHUNK rows); above, FFT convolution. The direct form's
#: cost grows with the taps, the FFT's barely up to 512 (one 1024-point transform): they meet near 38
#: (tools/bench_vibration.py --lines, 3 axes at 1 kHz, the PSD's own CPU ns per sample, 2026-12-02: direct 77 at
#: 32 taps, 105 at 48, 146 at 64, 499 at 256; FFT 88 at 32 to 64, 135 at 256)
DIRECT_TAPS = 40
CHUNK = 256


def _chunk_filler(ctx, taps: int):
    """How this IMU's chunks of filtered noise are filled (imu_emulator.numerics.shaped_noise): (rows per chunk,
    the parameters standing for one order's reversed taps, the call's source from (key, chunk, orders, parameters'
    base, rows' base)). The scratch is dead between calls: one block serves every axis."""
    from imu_emulator.numerics.shaped_noise import correlation_spectrum, fft_size, twiddles
    if taps <= DIRECT_TAPS:
        scratch = ctx.state_block("scratch", [lambda draw: 0.0] * (CHUNK + taps))
        return CHUNK, list, lambda key, chunk, orders, h, out: (
            f"fill_chunk_direct({key}, {chunk}, {CHUNK}, {taps}, {orders}, prm, {h}, state, {out}, {scratch})")
    n = fft_size(taps)
    size = n - taps      # rows per chunk: the transform's length less the filter's reach
    tw = ctx.constant("TW", twiddles(n))
    scratch = ctx.state_block("scratch", [lambda draw: 0.0] * (4 * n))
    return size, lambda order: correlation_spectrum(order, n), lambda key, chunk, orders, h, out: (
        f"fill_chunk({key}, {chunk}, {size}, {taps}, {orders}, prm, {h}, {tw}, state, {out}, {scratch})")


def _psd_axes(ctx, key: str) -> dict[int, float]:
    """{axis: its weight} of the PSD table `key` ("psd" or "angular_psd"), for the axes of nonzero weight."""
    table = ctx.value(f"imu.vibration.{key}")
    weights = ctx.value(f"imu.vibration.{key}_axes")
    if not table:
        return {}
    return {axis: weights[axis] for axis in range(3) if weights[axis] > 0}


def _quaternion(ctx, angular, angle) -> tuple[list[str], tuple[str, str, str, str]]:
    """The unit quaternion of R_v = Rx(a) Ry(b) Rz(c): q_x(a) q_y(b) q_z(c), each q_i(t) = (cos t/2, sin t/2 e_i)
    (Hamilton products compose as the matrices do). -> (source lines, its four variables)."""
    q = [ctx.var(f"q{c}") for c in "wxyz"]
    h = {i: (ctx.var(f"hc{AXES[i]}"), ctx.var(f"hs{AXES[i]}")) for i in angular}
    lines = [f"{h[i][0]}, {h[i][1]} = math.cos(0.5 * {angle[i]}), math.sin(0.5 * {angle[i]})" for i in angular]

    def unit(i):
        return [h[i][0]] + [h[i][1] if j == i else "0.0" for j in range(3)]
    first, *rest = angular
    lines.append(f"{', '.join(q)} = {', '.join(unit(first))}")
    for i in rest:
        lines.append(f"{', '.join(q)} = quat_multiply_scalar({', '.join(q)}, {', '.join(unit(i))})")
    return lines, tuple(q)


def _rotate(ctx, angular, rate, angle) -> list[str]:
    """fa, gw -> R_v^T fa, R_v^T gw + relative rate, R_v = Rx(a) Ry(b) Rz(c); only the axes that vibrate."""
    out = []
    c, s = ({i: ctx.var(f"{q}{AXES[i]}") for i in angular} for q in ("c", "s"))
    for i in angular:
        out.append(f"{s[i]}, {c[i]} = math.sin({angle[i]}), math.cos({angle[i]})")
    # Rx^T, then Ry^T, then Rz^T, applied to both vectors
    for vec in ("fa", "gw"):
        x, y, z = (f"{vec}{a}" for a in AXES)
        if 0 in angular:
            out += [f"{y}, {z} = {c[0]} * {y} + {s[0]} * {z}, {c[0]} * {z} - {s[0]} * {y}"]
        if 1 in angular:
            out += [f"{x}, {z} = {c[1]} * {x} - {s[1]} * {z}, {s[1]} * {x} + {c[1]} * {z}"]
        if 2 in angular:
            out += [f"{x}, {y} = {c[2]} * {x} + {s[2]} * {y}, {c[2]} * {y} - {s[2]} * {x}"]
    cb, cc = c.get(1, "1.0"), c.get(2, "1.0")
    sb, sc = s.get(1, "0.0"), s.get(2, "0.0")
    ra, rb, rc = (rate[i] if i in angular else "0.0" for i in range(3))
    out += [f"gwx += {ra} * {cc} * {cb} + {rb} * {sc}", f"gwy += -{ra} * {sc} * {cb} + {rb} * {cc}",
            f"gwz += {ra} * {sb} + {rc}"]
    return out


def validate(values: dict, where: str) -> None:
    n = values["imu.vibration.psd_lines"]
    if not (n == int(n) and MIN_TAPS <= n <= MAX_TAPS):
        raise SceneError(f"{where}.vibration.psd_lines: expected a whole number from {MIN_TAPS} to {MAX_TAPS} (the "
                         f"shaping filter's taps), got {n!r}")
    for key in ("psd_axes", "angular_psd_axes"):
        if any(w < 0 for w in values[f"imu.vibration.{key}"]):
            raise SceneError(f"{where}.vibration.{key}: weights are >= 0, got {values[f'imu.vibration.{key}']!r}")


def _power(table, f0: float, f1: float) -> float:
    """The table's power between f0 and f1 (the integral of its log-log segments: closed form per segment)."""
    total = 0.0
    for (fa, sa), (fb, sb) in zip(table, table[1:]):
        lo, hi = max(f0, fa), min(f1, fb)
        if hi <= lo:
            continue
        slope = math.log(sb / sa) / math.log(fb / fa)    # S = sa (f / fa)^slope
        if abs(slope + 1.0) < 1e-12:
            total += sa * fa * math.log(hi / lo)
        else:
            total += sa * fa ** -slope * (hi ** (slope + 1.0) - lo ** (slope + 1.0)) / (slope + 1.0)
    return total


def alias_hz(f: float, rate_hz: float) -> float:
    """The frequency a line at f shows in samples taken at rate_hz (folded into [0, rate_hz / 2])."""
    return abs(f - rate_hz * round(f / rate_hz))


def warn(values: dict, where: str, rate_hz: float) -> list[str]:
    """One line per sinusoid and per PSD table with lines above the Nyquist rate: they alias (module doc)."""
    nyquist = rate_hz / 2.0
    out = []
    for k, (axis, kind, _, f, _) in enumerate(values["imu.vibration.sines"]):
        if f > nyquist:
            out.append(f"{where}.vibration.sines[{k}]: {f:g} Hz ({AXES[axis]}, {('linear', 'angular')[kind]}) is "
                       f"above the Nyquist rate {nyquist:g} Hz of rate_hz = {rate_hz:g}: it aliases to "
                       f"{alias_hz(f, rate_hz):g} Hz (no anti-alias filter is simulated)")
    taps = int(values["imu.vibration.psd_lines"])
    for key in ("psd", "angular_psd"):
        table = values[f"imu.vibration.{key}"]
        if not table or not any(w > 0 for w in values[f"imu.vibration.{key}_axes"]):
            continue
        # the filter resolves rate_hz / taps: a band holding few of its frequency bins is realized coarsely, or
        # not at all
        bins = sum(1 for i in range(taps // 2 + 1) if table[0][0] <= i * rate_hz / taps <= table[-1][0])
        if bins < MIN_BINS:
            out.append(f"{where}.vibration.{key}: its band {table[0][0]:g} to {table[-1][0]:g} Hz holds {bins} of "
                       f"the shaping filter's frequency bins (every {rate_hz / taps:g} Hz at psd_lines = {taps}): "
                       f"it is realized coarsely or not at all; raise psd_lines")
        if table[-1][0] <= nyquist:
            continue
        total, above = _power(table, table[0][0], table[-1][0]), _power(table, max(nyquist, table[0][0]), table[-1][0])
        out.append(f"{where}.vibration.{key}: its band above the Nyquist rate {nyquist:g} Hz of rate_hz = {rate_hz:g} "
                   f"({max(nyquist, table[0][0]):.4g} to {table[-1][0]:.4g} Hz, {100.0 * above / total:.3g} % of its "
                   f"power) folds into 0 to {nyquist:g} Hz (no anti-alias filter is simulated)")
    return out


EFFECT = Effect(
    name="vibration",
    description="vibration as motion of the IMU: sinusoidal lines (linear or angular) and random PSDs",
    stage=Stage.BODY, order=50, emit=emit, validate=validate, warn=warn, random=True,
    state=("noise", "angular_noise", "scratch"), cached_state=True,
    params=(Param("sines", "imu.vibration", "m/s^2|rad/s", "sinusoidal lines: [{axis, amplitude, frequency, "
                  "phase}], amplitude as the sensor sees it (acceleration, or kind = \"angular\": rate)",
                  shape="sines", default=(), datasheet="`[{axis = \"x\", amplitude = \"2 g\", frequency = "
                  "\"120 Hz\"}]`"),
            Param("psd", "imu.vibration", "m^2/s^4/Hz", "random linear vibration: one-sided acceleration PSD "
                  "breakpoints [frequency, level], log-log", shape="psd", default=(),
                  datasheet="`[[\"20 Hz\", \"0.01 g^2/Hz\"], [\"2000 Hz\", \"0.01 g^2/Hz\"]]`"),
            Param("psd_axes", "imu.vibration", "1", "PSD weight per body axis (0: none)", default=1.0),
            Param("angular_psd", "imu.vibration", "rad^2/s^2/Hz", "random angular vibration: one-sided angular "
                  "rate PSD breakpoints [frequency, level], log-log", shape="psd", default=(),
                  datasheet="`[[\"10 Hz\", \"1e-4 (deg/s)^2/Hz\"], [\"500 Hz\", \"1e-4 (deg/s)^2/Hz\"]]`"),
            Param("angular_psd_axes", "imu.vibration", "1", "angular PSD weight per body axis (0: none)",
                  default=1.0),
            Param("psd_lines", "imu.vibration", "1", "taps of the FIR filter shaping each PSD's noise (its "
                  "frequency resolution: rate_hz / psd_lines)", shape="scalar", default=256.0, example=32.0)))
