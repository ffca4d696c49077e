"""Vibration: motion of the IMU relative to the body (issue 9), not noise on its outputs.

Linear vibration is a displacement d(t) of the IMU in body axes. It is a moving lever arm, so the IMU feels
f += d'' + 2 w x d' + alpha x d + w x (w x d) (w, alpha: the body's inertial rate and its derivative), exactly.
Angular vibration turns the IMU's axes against the body's by R_v = Rx(a) Ry(b) Rz(c) (a, b, c: the angles
about body x, y, z), so the sensor sees R_v^T f, and R_v^T w plus the relative rate
a' (cos c cos b, -sin c cos b, sin b) + b' (sin c, cos c, 0) + c' (0, 0, 1). Because it is motion, coning
(angular lines on two axes out of phase) and sculling (angular with linear) appear in the outputs as they
would on a shaker. The attitude output stays the body's (with mounting): the vibration's small rotation is
not in it.

- `sines`: lines {axis, amplitude, frequency, phase}; the amplitude is what the sensor on that axis sees:
  linear (an acceleration, "2 g") gives d'' = A sin(2 pi f t + phase), angular (a rate, "3 deg/s") gives the
  relative rate A sin(2 pi f t + phase). Plain numbers are m/s^2 unless kind = "angular" (rad/s).
- `psd`: random linear vibration given as an acceleration PSD table ((m/s^2)^2/Hz, e.g. "0.04 g^2/Hz"), one-
  sided as vibration specifications print it, interpolated log-log between breakpoints. Realized on each body
  axis (weighted by psd_axes, a factor on the PSD) as a sum of psd_lines sinusoids: the band between the
  first and last breakpoint cut into cells of equal log width, one line at each cell's geometric centre f_i
  with amplitude sqrt(2 S(f_i) df_i) (its power S(f_i) df_i) and a phase drawn uniformly from the seed (per IMU
  and axis, at the run's start). A continuous motion with exact derivatives whose PSD, averaged over a cell,
  is the table's; the frequencies are incommensurate, so it does not repeat. Lines above the Nyquist rate
  alias as they would in a part without an anti-alias filter.
"""
import math

from imu_emulator.effects._record import AXES, Effect, Param, Stage
from imu_emulator.errors import SceneError

MAX_LINES = 100000


def psd_level(table, f: float) -> float:
    """The table's level at f (log-log interpolation between breakpoints; f within the table's band)."""
    for (f0, s0), (f1, s1) in zip(table, table[1:]):
        if f <= f1:
            return s0 * (f / f0) ** (math.log(s1 / s0) / math.log(f1 / f0))
    return table[-1][1]


def psd_lines(table, n: int, weight: float = 1.0) -> list[tuple[float, float]]:
    """(frequency in Hz, acceleration amplitude) of the n lines realizing the PSD table (see the module doc)."""
    lo, hi = table[0][0], table[-1][0]
    ratio = (hi / lo) ** (1.0 / n)
    lines = []
    for i in range(n):
        left, right = lo * ratio ** i, lo * ratio ** (i + 1)
        f = math.sqrt(left * right)
        lines.append((f, math.sqrt(2.0 * weight * psd_level(table, f) * (right - left))))
    return lines


def _uniform(draw, axis: str, i: int) -> float:
    """A phase in cycles, uniform on [0, 1): the normal's distribution function."""
    return 0.5 * math.erfc(-draw(axis, i) / math.sqrt(2.0))


def emit(ctx) -> list[str]:
    sines = ctx.value("imu.vibration.sines")
    table = ctx.value("imu.vibration.psd")
    weights = ctx.value("imu.vibration.psd_axes")
    n = int(ctx.value("imu.vibration.psd_lines"))
    # per axis: linear acceleration, velocity, displacement; angular rate and angle (body axes)
    acc, vel, disp = ([ctx.var(f"{q}{a}") for a in AXES] for q in ("acc", "vel", "disp"))
    rate, angle = ([ctx.var(f"{q}{a}") for a in AXES] for q in ("rate", "angle"))
    linear = sorted({axis for axis, kind, *_ in sines if kind == 0}
                    | ({i for i in range(3) if weights[i] > 0} if table else set()))
    angular = sorted({axis for axis, kind, *_ in sines if kind == 1})
    if not linear and not angular:
        return []
    lines = [f"{v} = 0.0" for i in linear for v in (acc[i], vel[i], disp[i])]
    lines += [f"{v} = 0.0" for i in angular for v in (rate[i], angle[i])]
    sn, cs = ctx.var("sn"), ctx.var("cs")
    for axis, kind, amplitude, frequency, phase in sines:
        w = 2.0 * math.pi * frequency
        lines.append(f"{sn}, {cs} = sincos_cycles({frequency!r} * t + {phase / (2.0 * math.pi)!r})")
        if kind == 0:   # d'' = A sin, d' = -A/w cos, d = -A/w^2 sin
            lines += [f"{acc[axis]} += {amplitude!r} * {sn}", f"{vel[axis]} -= {amplitude / w!r} * {cs}",
                      f"{disp[axis]} -= {amplitude / w ** 2!r} * {sn}"]
        else:           # rate = A sin, angle = -A/w cos
            lines += [f"{rate[axis]} += {amplitude!r} * {sn}", f"{angle[axis]} -= {amplitude / w!r} * {cs}"]
    if table:
        i = ctx.var("i")
        for axis in range(3):
            if not weights[axis] > 0:
                continue
            found = psd_lines(table, n, weights[axis])
            a = AXES[axis]
            f = ctx.constant(f"F{a}", [fi for fi, _ in found])
            amp = ctx.constant(f"A{a}", [ai for _, ai in found])
            amp_w = ctx.constant(f"AW{a}", [ai / (2.0 * math.pi * fi) for fi, ai in found])
            amp_w2 = ctx.constant(f"AWW{a}", [ai / (2.0 * math.pi * fi) ** 2 for fi, ai in found])
            base = ctx.state_block("phase", [lambda draw, a=a, k=k: _uniform(draw, a, k) for k in range(n)])
            lines += [f"for {i} in range({n}):",
                      f"    {sn}, {cs} = sincos_cycles({f}[{i}] * t + state[{base} + {i}])",
                      f"    {acc[axis]} += {amp}[{i}] * {sn}", f"    {vel[axis]} -= {amp_w}[{i}] * {cs}",
                      f"    {disp[axis]} -= {amp_w2}[{i}] * {sn}"]
    if linear:
        d = [disp[i] if i in linear else "0.0" for i in range(3)]
        v = [vel[i] if i in linear else "0.0" for i in range(3)]
        ux, uy, uz = (ctx.var(f"u{a}") for a in AXES)
        lines += [f"{ux} = gwy * {d[2]} - gwz * {d[1]}", f"{uy} = gwz * {d[0]} - gwx * {d[2]}",
                  f"{uz} = gwx * {d[1]} - gwy * {d[0]}"]
        for j, a in enumerate(AXES):   # component j of d'' + 2 w x d' + alpha x d + w x (w x d)
            b, c = AXES[(j + 1) % 3], AXES[(j + 2) % 3]
            jb, jc = (j + 1) % 3, (j + 2) % 3
            term = acc[j] if j in linear else "0.0"
            lines.append(f"fa{a} += {term} + 2.0 * (gw{b} * {v[jc]} - gw{c} * {v[jb]}) "
                         f"+ (al{b} * {d[jc]} - al{c} * {d[jb]}) + (gw{b} * {ctx.var('u' + c)} - gw{c} * "
                         f"{ctx.var('u' + b)})")
    if angular:
        lines += _rotate(ctx, angular, rate, angle)
    return lines


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
    if not (n == int(n) and 1 <= n <= MAX_LINES):
        raise SceneError(f"{where}.vibration.psd_lines: expected a whole number from 1 to {MAX_LINES}, got {n!r}")
    if any(w < 0 for w in values["imu.vibration.psd_axes"]):
        raise SceneError(f"{where}.vibration.psd_axes: weights are >= 0, got {values['imu.vibration.psd_axes']!r}")


EFFECT = Effect(
    name="vibration",
    description="vibration as motion of the IMU: sinusoidal lines (linear or angular) and a random PSD",
    stage=Stage.BODY, order=50, emit=emit, validate=validate, random=True, state=("phase",), drawn_once=True,
    params=(Param("sines", "imu.vibration", "m/s^2|rad/s", "sinusoidal lines: [{axis, amplitude, frequency, "
                  "phase}], amplitude as the sensor sees it (acceleration, or kind = \"angular\": rate)",
                  shape="sines", default=(), datasheet="`[{axis = \"x\", amplitude = \"2 g\", frequency = "
                  "\"120 Hz\"}]`"),
            Param("psd", "imu.vibration", "m^2/s^4/Hz", "random linear vibration: one-sided acceleration PSD "
                  "breakpoints [frequency, level], log-log", shape="psd", default=(),
                  datasheet="`[[\"20 Hz\", \"0.01 g^2/Hz\"], [\"2000 Hz\", \"0.01 g^2/Hz\"]]`"),
            Param("psd_axes", "imu.vibration", "1", "PSD weight per body axis (0: none)", default=1.0),
            Param("psd_lines", "imu.vibration", "1", "sinusoids per axis realizing the PSD", shape="scalar",
                  default=256.0, example=64.0)))
