"""Motion of the body's reference point S: turns the scene's trajectory and attitude into the lines of
kernel source that produce, per sample, position derivatives (s, v, a[, j]) in the navigation frame and
the attitude with its rates.

Symbolic input: sympy differentiates the expressions exactly, common subexpressions are shared, and the
result is printed as straight-line code. Sin/cos/tan of an argument linear in t get their phase reduced
exactly: the phase in cycles is frac(C0 + k*CS) with CS held as a double-double and k*CS formed with an
error-free product, so t = 1e7 s is as exact as t = 1 s (imu_emulator.motion.phases); sin and cos of it come from
imu_emulator.numerics.phase.

Sampled input: derivative arrays are evaluated per block in Python (imu_emulator.numerics.derivatives) and the
kernel reads them.

Variables the generated code defines, per sample:
    px py pz, vx vy vz, ax ay az (and jx jy jz when the attitude is tangent): navigation frame
    cr sr cp sp cy sy: cos/sin of roll, pitch, yaw; dr dp dy, ddr ddp ddy: their rates
    roll pitch yaw (only when `angles` is requested)
"""
from __future__ import annotations

from dataclasses import dataclass, field

from imu_emulator.motion import phases
from imu_emulator.numerics import expressions
from imu_emulator.scene.model import Expressions, SampledData, Scene

AXES = "xyz"
DERIVATIVE_NAMES = ("its value", "its first derivative", "its second derivative", "its third derivative")
ANGLES = ("r", "p", "y")       # roll, pitch, yaw suffixes


@dataclass
class MotionCode:
    lines: list[str]             # straight-line code inside the per-sample loop
    constants: dict[str, float]  # module-level constants the lines use
    needs_jerk: bool
    phase_lines: list[str] = field(default_factory=list)  # computes sph_i, cph_i from k; run as a stage
    phase_vars: list[str] = field(default_factory=list)   # of its own so samples overlap in the CPU
    rotation_given: bool = False  # the lines define R (r00..r22), w and alpha themselves (quaternion input)
    after_rotation: list[str] = field(default_factory=list)   # run after R, w, alpha (attitude reference)
    level_rate: tuple[str, str, str] = ("wx", "wy", "wz")     # the body's rate w.r.t. the level axes R maps to


def _kernel_printer_class():
    from sympy.printing.pycode import PythonCodePrinter

    class KernelPrinter(PythonCodePrinter):
        def _print_Pow(self, expr, rational=False):
            # numba raises ZeroDivisionError for 0.0**-n whatever the error model; a float division gives
            # inf, which the finite check then reports by key, expression and time.
            if expr.exp.is_Integer and expr.exp < 0:
                n = -int(expr.exp)
                return f"(1.0/({self._print(expr.base)}){'' if n == 1 else f'**{n}'})"
            return super()._print_Pow(expr, rational)

    return KernelPrinter


def _symbolic(parts: list[tuple[str, object]], scene: Scene) -> MotionCode:
    """parts: (variable name, sympy expression in t). Returns CSE'd code assigning every name."""
    import sympy

    t = sympy.Symbol("t", real=True)
    names = [name for name, _ in parts]
    exprs = [expressions.drop_impulses(sympy.sympify(e)) for _, e in parts]
    exprs, constants, n_phases = phases.reduce_phases(exprs, t, scene)
    # Fold numeric constants (pi**3 etc.) to 30 digits now, not per sample in the kernel.
    exprs = [sympy.N(e, 30) for e in exprs]
    replacements, reduced = sympy.cse(exprs, symbols=sympy.numbered_symbols("_x"), optimizations="basic")
    printer = _kernel_printer_class()({"fully_qualified_modules": True, "standard": "python3"})
    phase_lines = []
    if n_phases:
        # Split k once for Dekker's product; every phase slot shares it.
        phase_lines += list(phases.SPLIT_K)
        for i in range(n_phases):
            phase_lines += phases.phase_lines(i)
    lines = []
    for sym, value in replacements:
        lines.append(f"{sym} = {printer.doprint(value)}")
    for name, value in zip(names, reduced):
        code = printer.doprint(value)
        lines.append(f"{name} = float({code})")
    return MotionCode(lines=lines, constants=constants, needs_jerk=False, phase_lines=phase_lines,
                      phase_vars=[f"{sc}ph{i}" for i in range(n_phases) for sc in "sc"])


#: Expressions the kernel takes the cos and sin of as a whole (their numbers are phases: expressions.lift)
PHASE_KEYS = ("attitude.roll", "attitude.pitch", "attitude.yaw", "trajectory.lat_deg", "trajectory.lon_deg")


def lifted_numbers(scene: Scene) -> dict[str, tuple[str, list[float]]]:
    """Per expression key, its structure and the numbers the kernel takes at run time (expressions.lift): the
    EffectPlan gives each a parameter slot and the cache keys on the structures. No sympy."""
    return {key: expressions.lift(expressions.check(text, key, scene.params), scene.params, key in PHASE_KEYS)
            for key, text, _ in _keyed_expressions(scene)}


def _to_sympy(text: str, key: str, scene: Scene, t, slots):
    """A checked expression in sympy; its lifted numbers are the symbols slots[key] (parameter slots prm_i) when
    given, literals otherwise (explain_nonfinite, tests)."""
    tree = expressions.check(text, key, scene.params)
    return expressions.to_sympy(tree, scene.params, t, lifted=None if slots is None else slots[key],
                                phase=key in PHASE_KEYS)


def translational_parts(exprs: Expressions, scene: Scene, order: int, slots=None):
    """sympy expressions of s, v, a[, j] for x, y, z (`slots`: _to_sympy's)."""
    import sympy
    t = sympy.Symbol("t", real=True)
    given = [_to_sympy(text, f"trajectory.{key}", scene, t, slots) for key, text in zip(exprs.keys, exprs.texts)]
    if exprs.keys != ("x", "y", "z"):
        from imu_emulator.motion.earth import geodetic_to_ecef
        given = geodetic_to_ecef(given)
    elif scene.frame == "ECI":
        from imu_emulator.motion.earth import eci_to_ecef
        given = eci_to_ecef(given, t)
    parts = []
    for axis, key, text, e in zip(AXES, exprs.keys, exprs.texts, given):
        where = f"trajectory.{key}"
        for d, prefix in enumerate("pva" + ("j" if order >= 3 else "")):
            expressions.check_symbolic(e, where, text, DERIVATIVE_NAMES[d])
            parts.append((f"{prefix}{axis}", e))
            e = sympy.diff(e, t)
    return parts


def attitude_parts(exprs: Expressions, scene: Scene, angles: bool, slots=None):
    """cos/sin of each angle, first and second derivatives; sympy folds constant angles away."""
    import sympy
    t = sympy.Symbol("t", real=True)
    parts = []
    for suffix, key, text in zip(ANGLES, ("roll", "pitch", "yaw"), exprs.texts):
        where = f"attitude.{key}"
        e = _to_sympy(text, where, scene, t, slots)
        d1 = sympy.diff(e, t)
        for d, part in enumerate((e, d1, sympy.diff(d1, t))):
            expressions.check_symbolic(part, where, text, DERIVATIVE_NAMES[d])
        parts += [(f"c{suffix}", sympy.cos(e)), (f"s{suffix}", sympy.sin(e)),
                  (f"d{suffix}", d1), (f"dd{suffix}", sympy.diff(d1, t))]
        if angles:
            parts.append(({"r": "roll", "p": "pitch", "y": "yaw"}[suffix], e))
    return parts


def sampled_translational_lines(order: int) -> list[str]:
    return [f"{prefix}{axis} = mot[{i}, j, {a}]"
            for i, prefix in enumerate("pvaj"[: order + 1]) for a, axis in enumerate(AXES)]


def sampled_attitude_lines(angles: bool) -> list[str]:
    lines = ["roll = att[0, j, 0]", "pitch = att[0, j, 1]", "yaw = att[0, j, 2]"]
    for a, (suffix, name) in enumerate(zip(ANGLES, ("roll", "pitch", "yaw"))):
        lines += [f"c{suffix} = math.cos({name})", f"s{suffix} = math.sin({name})",
                  f"d{suffix} = att[1, j, {a}]", f"dd{suffix} = att[2, j, {a}]"]
    return lines


def sampled_quaternion_lines(angles: bool) -> list[str]:
    """R, omega_B and alpha_B straight from a fitted quaternion curve p(t) (att[0..2]: p, p', p''), never
    through Euler angles. p need not be unit: R is that of p/|p|, and with q = p/|p| the kinematic equation
    q' = q (0, w)/2 gives w = 2 vec(p* p')/|p|^2 and, differentiated, alpha = (2 vec(p* p'') - 2 (p.p') w)/|p|^2
    (vec(p'* p') vanishes: it is the scalar |p'|^2)."""
    lines = [f"{c}{i} = att[{d}, j, {i}]" for d, c in enumerate("pde") for i in range(4)]
    lines += [
        "n2 = p0 * p0 + p1 * p1 + p2 * p2 + p3 * p3",
        "inv = 1.0 / n2",
        "r00 = (p0 * p0 + p1 * p1 - p2 * p2 - p3 * p3) * inv",
        "r01 = 2.0 * (p1 * p2 - p0 * p3) * inv", "r02 = 2.0 * (p1 * p3 + p0 * p2) * inv",
        "r10 = 2.0 * (p1 * p2 + p0 * p3) * inv",
        "r11 = (p0 * p0 - p1 * p1 + p2 * p2 - p3 * p3) * inv", "r12 = 2.0 * (p2 * p3 - p0 * p1) * inv",
        "r20 = 2.0 * (p1 * p3 - p0 * p2) * inv", "r21 = 2.0 * (p2 * p3 + p0 * p1) * inv",
        "r22 = (p0 * p0 - p1 * p1 - p2 * p2 + p3 * p3) * inv",
        # vec(p* x) = p0 x_v - x0 p_v - p_v cross x_v
        "wx = 2.0 * (p0 * d1 - d0 * p1 - (p2 * d3 - p3 * d2)) * inv",
        "wy = 2.0 * (p0 * d2 - d0 * p2 - (p3 * d1 - p1 * d3)) * inv",
        "wz = 2.0 * (p0 * d3 - d0 * p3 - (p1 * d2 - p2 * d1)) * inv",
        "pd = 2.0 * (p0 * d0 + p1 * d1 + p2 * d2 + p3 * d3) * inv",
        "alx = 2.0 * (p0 * e1 - e0 * p1 - (p2 * e3 - p3 * e2)) * inv - pd * wx",
        "aly = 2.0 * (p0 * e2 - e0 * p2 - (p3 * e1 - p1 * e3)) * inv - pd * wy",
        "alz = 2.0 * (p0 * e3 - e0 * p3 - (p1 * e2 - p2 * e1)) * inv - pd * wz",
    ]
    if angles:
        lines += ["roll = math.atan2(r21, r22)", "pitch = math.atan2(-r20, math.hypot(r21, r22))",
                  "yaw = math.atan2(r10, r00)"]
    return lines


def tangent_lines(angles: bool, v: str = "v", a: str = "a", j: str = "j") -> list[str]:
    """Attitude along the velocity (roll 0), from v, a, j, without trig: cos/sin come from v itself.
    v, a, j name the velocity and its first two time derivatives in the level axes ({v}x, {v}y, {v}z): the
    frame's own vx.. by default; with the Earth model on, the components in the local level frame at the
    current position (imu_emulator.motion.earth.tangent_level_lines).

    Where |v| vanishes the last defined attitude is held; where v is vertical the last heading is
    held. The held cos/sin live in `hold` so they carry across blocks.
    """
    # Reciprocals once: divisions are the slow part of this block. The held cos/sin are locals
    # (hcy, hsy, hcp, hsp) loaded before the loop and stored after it, so nothing aliases the outputs.
    lines = [
        f"v2 = {v}x * {v}x + {v}y * {v}y + {v}z * {v}z",
        f"h2 = {v}x * {v}x + {v}y * {v}y",
        "if v2 > EPS_V2:",
        "    if h2 > EPS_V2:",
        "        ih = 1.0 / math.sqrt(h2)",
        "        h = h2 * ih",
        "        ih2 = ih * ih",
        f"        cy = {v}x * ih",
        f"        sy = {v}y * ih",
        f"        cross = {v}x * {a}y - {v}y * {a}x",
        f"        dot = {v}x * {a}x + {v}y * {a}y",
        "        hd = dot * ih",
        "        dy = cross * ih2",
        f"        ddy = (({v}x * {j}y - {v}y * {j}x) - 2.0 * cross * dot * ih2) * ih2",
        f"        hdd = ({a}x * {a}x + {a}y * {a}y + {v}x * {j}x + {v}y * {j}y - hd * hd) * ih",
        "        hcy = cy",
        "        hsy = sy",
        "    else:",
        "        h = math.sqrt(h2)",
        "        cy = hcy",
        "        sy = hsy",
        "        hd = 0.0",
        "        hdd = 0.0",
        "        dy = 0.0",
        "        ddy = 0.0",
        "    iv = 1.0 / math.sqrt(v2)",
        "    iv2 = iv * iv",
        "    cp = h * iv",
        f"    sp = -{v}z * iv",
        # pitch = -atan2(vz, h): differentiate the N/D form once and twice
        f"    num = h * {a}z - {v}z * hd",
        "    dp = -num * iv2",
        f"    ddp = -((h * {j}z - {v}z * hdd) - num * 2.0 * ({v}z * {a}z + h * hd) * iv2) * iv2",
        "    hcp = cp",
        "    hsp = sp",
        "else:",
        "    cy = hcy",
        "    sy = hsy",
        "    cp = hcp",
        "    sp = hsp",
        "    dy = 0.0",
        "    ddy = 0.0",
        "    dp = 0.0",
        "    ddp = 0.0",
        "cr = 1.0",
        "sr = 0.0",
        "dr = 0.0",
        "ddr = 0.0",
    ]
    if angles:
        lines += ["roll = 0.0", "pitch = math.atan2(sp, cp)", "yaw = math.atan2(sy, cy)"]
    return lines


def motion_code(scene: Scene, angles: bool, origin=None, slots=None) -> MotionCode:
    """All motion lines for the kernel: translation first (tangent attitude reads v, a, j). `origin`: the sources
    of the tangent frame's origin (imu_emulator.motion.earth.origin_terms; default literals); `slots`: per
    expression key, the parameter slots of its lifted numbers (lifted_numbers; default literals)."""
    tangent = scene.attitude_mode == "tangent"
    order = 3 if tangent else 2
    symbolic_parts = []
    lines: list[str] = []
    if isinstance(scene.trajectory, Expressions):
        symbolic_parts += translational_parts(scene.trajectory, scene, order, slots)
    else:
        lines += sampled_translational_lines(order)
    attitude_lines: list[str] = []
    rotation_given = False
    from imu_emulator.motion.earth import geometry_lines, tangent_level_lines
    from imu_emulator.scene.earth import model_on
    earth = model_on(scene)
    if tangent and earth:
        # heading and pitch from the velocity in the local level frame at the current position
        attitude_lines = (geometry_lines(scene, jerk=True, origin=origin) + tangent_level_lines(scene)
                          + tangent_lines(angles, "t_v", "t_a", "t_j"))
    elif tangent:
        attitude_lines = tangent_lines(angles)
    elif isinstance(scene.attitude, Expressions):
        symbolic_parts += attitude_parts(scene.attitude, scene, angles, slots)
    elif scene.attitude.kind == "quaternion":
        attitude_lines = sampled_quaternion_lines(angles)
        rotation_given = True
    else:
        assert isinstance(scene.attitude, SampledData)
        attitude_lines = sampled_attitude_lines(angles)
    if earth and not tangent:
        attitude_lines = attitude_lines + geometry_lines(scene, origin=origin)
    sym = (_symbolic(symbolic_parts, scene) if symbolic_parts
           else MotionCode(lines=[], constants={}, needs_jerk=tangent))
    if scene.frame == "ECI" and isinstance(scene.trajectory, SampledData):
        from imu_emulator.motion.earth import sampled_eci_lines
        constants, phase_lines, eci = sampled_eci_lines(scene, _earth_rotation_slot(sym))
        sym.constants.update(constants)
        sym.phase_lines += phase_lines
        lines += eci
    reference = getattr(scene, "attitude_reference", "local_level")
    if reference != "local_level":
        from imu_emulator.motion.earth import LEVEL_RATE, reference_lines, sampled_eci_lines
        index = None
        if reference == "ECI":
            index = _earth_rotation_slot(sym)
            constants, phase_lines, _ = sampled_eci_lines(scene, index)
            sym.constants.update(constants)
            sym.phase_lines += phase_lines
        sym.after_rotation = reference_lines(scene, angles, index)
        sym.level_rate = LEVEL_RATE
    if not symbolic_parts and not sym.phase_lines:
        return MotionCode(lines=lines + attitude_lines, constants={}, needs_jerk=tangent,
                          rotation_given=rotation_given, after_rotation=sym.after_rotation,
                          level_rate=sym.level_rate)
    if isinstance(scene.trajectory, Expressions):
        # Position and velocity feed no output in euler mode, yet an undefined position (log(400.0001 - t)
        # past t = 400) must stop the run: x - x is 0 for a finite x and NaN otherwise, so a non-finite p
        # or v makes a non-finite and the finite check names the expression.
        sym.lines += [f"a{axis} += (p{axis} - p{axis}) + (v{axis} - v{axis})" for axis in AXES]
    return MotionCode(lines=sym.lines + lines + attitude_lines, constants=sym.constants, needs_jerk=tangent,
                      phase_lines=sym.phase_lines, phase_vars=sym.phase_vars, rotation_given=rotation_given,
                      after_rotation=sym.after_rotation, level_rate=sym.level_rate)


def _earth_rotation_slot(sym: MotionCode) -> int:
    """A new phase slot for the Earth rotation angle (its lines come from motion.earth.sampled_eci_lines)."""
    if not sym.phase_lines:     # k split once for Dekker's product, as _symbolic does
        sym.phase_lines = list(phases.SPLIT_K)
    index = len(sym.phase_vars) // 2
    sym.phase_vars += [f"sph{index}", f"cph{index}"]
    return index


def _keyed_expressions(scene: Scene):
    """(key, text, highest derivative the kernel uses) for every expression of the scene."""
    out = []
    if isinstance(scene.trajectory, Expressions):
        order = 3 if scene.attitude_mode == "tangent" else 2
        out += [(f"trajectory.{key}", text, order) for key, text in zip(scene.trajectory.keys, scene.trajectory.texts)]
    if isinstance(scene.attitude, Expressions):
        out += [(f"attitude.{key}", text, 2) for key, text in zip(("roll", "pitch", "yaw"), scene.attitude.texts)]
    return out


def explain_nonfinite(scene: Scene, k: int) -> str | None:
    """Which expression, or which of its derivatives, is not finite at sample k, as a message naming key,
    text and time; None if every one is finite there (then the sum of finite terms overflowed).

    Numerically first (numpy at t0 + k/rate); where that is finite but the kernel was not (1/sin(2*pi*t)
    at t = 1: numpy's sin(2*pi*1.0) is 2.4e-16, the kernel's exactly reduced phase gives 0), exactly with
    sympy at the rational time. Runs only on the error path, so sympy's cost does not matter."""
    import numpy as np
    import sympy

    t = sympy.Symbol("t", real=True)
    t_exact = sympy.Rational(scene.t0_s) + sympy.Integer(k) / sympy.Rational(scene.rate_hz)
    t_float = scene.t0_s + k / scene.rate_hz
    for exact in (False, True):
        for key, text, order in _keyed_expressions(scene):
            e = expressions.to_sympy(expressions.check(text, key, scene.params), scene.params, t)
            for d in range(order + 1):
                e = e.replace(sympy.DiracDelta, lambda *a: sympy.Integer(0))   # as the kernel has it
                if exact:
                    value = e.subs(t, t_exact)
                    # None (undecided) is not evidence: only a definite infinite, undefined or complex value
                    bad = (value.has(sympy.zoo, sympy.nan, sympy.oo, -sympy.oo) or value.is_finite is False
                           or value.is_extended_real is False)
                else:
                    with np.errstate(all="ignore"):
                        value = sympy.lambdify(t, e, "numpy")(np.float64(t_float))
                    bad = not np.isfinite(value)
                if bad:
                    return (f"{key} = {text!r}: {DERIVATIVE_NAMES[d]} is not finite at t = {t_float!r} s "
                            f"(sample {k}); keep t inside the expression's domain")
                e = sympy.diff(e, t)
    return None
