"""Exact phase reduction: sin, cos and tan of a phase linear in t (A t + B) become sin and cos of the phase in
cycles, frac(C0 + k CS), with CS held as a double-double and k CS formed with an error-free product (Dekker), so
t = 1e7 s is as exact as t = 1 s (imu_emulator.numerics.phase gives sin and cos of it). The symbolic motion
(imu_emulator.motion.code) reduces its periodic phases so; the Earth rotation angle of ECI scenes
(imu_emulator.motion.earth) takes a phase slot of its own."""
from __future__ import annotations

from imu_emulator.scene.model import Scene

#: k split once for Dekker's product (kh + kl = k, each half exact in a product); every phase slot shares it
SPLIT_K = ("kf = float(k)", "_s = 134217729.0 * kf", "kh = _s - (_s - kf)", "kl = kf - kh")


def phase_constants(coef, offset, scene: Scene, index: int) -> dict[str, float]:
    """C0 = frac((A t0 + B) / 2pi), CS = A dt / 2pi as (hi, lo) doubles, hi pre-split for Dekker."""
    import mpmath
    import sympy
    with mpmath.workdps(50):
        a_cycles = mpmath.mpf(sympy.N(coef / (2 * sympy.pi), 50))
        b_cycles = mpmath.mpf(sympy.N(offset / (2 * sympy.pi), 50))
        # dt is 1/rate exactly, not the rounded double, so phase does not drift over long runs.
        step = a_cycles / mpmath.mpf(scene.rate_hz)
        start = a_cycles * mpmath.mpf(scene.t0_s) + b_cycles
        start = start - mpmath.floor(start)
        hi = float(step)
        lo = float(step - mpmath.mpf(hi))
    split = 134217729.0 * hi
    hi_h = split - (split - hi)
    return {f"PH{index}_C0": float(start), f"PH{index}_HI": hi, f"PH{index}_HI_H": hi_h,
            f"PH{index}_HI_L": hi - hi_h, f"PH{index}_LO": lo}


def phase_lines(index: int) -> list[str]:
    # Exact product k*HI = p + err (Dekker); frac(p) is exact; the small terms are added after.
    c = f"PH{index}"
    return [
        f"_p = kf * {c}_HI",
        f"_e = ((kh * {c}_HI_H - _p) + kh * {c}_HI_L + kl * {c}_HI_H) + kl * {c}_HI_L",
        f"_c = (_p - math.floor(_p)) + ((_e + kf * {c}_LO) + {c}_C0)",
        f"sph{index}, cph{index} = sincos_cycles(_c)",
    ]


def reduce_phases(exprs, t, scene: Scene):
    """Replace sin/cos/tan of A*t + B by sph_i, cph_i (sin and cos of the exactly reduced phase i)."""
    import sympy
    slots: dict[tuple, tuple] = {}
    constants: dict[str, float] = {}

    def replace(fn):
        def inner(arg):
            coef = sympy.diff(arg, t)
            if coef.free_symbols or coef == 0:
                return fn(arg)
            offset = sympy.simplify(arg - coef * t)
            if offset.free_symbols:
                return fn(arg)
            key = (sympy.srepr(coef), sympy.srepr(offset))
            if key not in slots:
                index = len(slots)
                slots[key] = (sympy.Symbol(f"sph{index}", real=True), sympy.Symbol(f"cph{index}", real=True))
                constants.update(phase_constants(coef, offset, scene, index))
            sin_, cos_ = slots[key]
            return sin_ if fn is sympy.sin else cos_ if fn is sympy.cos else sin_ / cos_
        return inner

    out = []
    for e in exprs:
        for fn in (sympy.sin, sympy.cos, sympy.tan):
            e = e.replace(fn, replace(fn))
        out.append(e)
    return out, constants, len(slots)
