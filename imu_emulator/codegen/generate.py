"""The numba kernel's source, generated for exactly the effects a scene names.

The source is KERNEL_TEMPLATE (imu_emulator.codegen.template) with its slots filled: the motion
(imu_emulator.motion.code), then the effects of each stage (imu_emulator.effects: navigation frame, body frame at
the IMU, sensor frame, sensor output), in their declared order (imu_emulator.codegen.plan). A switched-off effect
contributes no line, so it is absent from the machine code rather than multiplied by zero. The scene's numbers
are not in the source: the effects' parameters, lever arms, mountings, t0 and the sample interval arrive at run
time in the array `prm` (imu_emulator.codegen.plan), the seed as stream keys, so scenes that differ only in them
(a Monte Carlo over seeds, a --vary over parameters, another duration) compile once. What stays literal: which
values are zero (a zero removes its line), the form of the motion's expressions with the numbers that stay in them
(phases, exponents, zeros: imu_emulator.numerics.expressions.lift; the others are parameters) and the phase
constants (the origin is a parameter: imu_emulator.motion.earth.origin_terms). Variables each stage may read and update:
imu_emulator.effects.STAGE_CONTRACT. How the kernel is called: imu_emulator.codegen.signature; how it is cached, compiled and loaded: imu_emulator.runtime.kernels.
"""
from __future__ import annotations

import ast
import builtins
import re

from imu_emulator.codegen import explain
from imu_emulator.codegen.plan import EffectPlan
from imu_emulator.codegen.signature import ARG_NOTES, ARGS, RUNTIME_IMPORTS, TRUTH_OUTPUTS
from imu_emulator.codegen.template import CHUNK, IMU_FRAME_TEMPLATE, KERNEL_TEMPLATE, PER_IMU_TEMPLATE, fill
from imu_emulator.effects import AXES, TRIADS
# From the package, not scene.model: the cache key's fingerprint follows this module's imports, and the scene's
# loaders (units, presets, shapes, sources) decide the values a kernel is generated from, as they did when they
# were one module.
from imu_emulator.scene import Scene

CODEGEN_VERSION = "3"
EPS_SPEED = 1e-6     # m/s: below this the body is standing still for tangent attitude


def _rotation_and_rates() -> list[str]:
    """R = Rz(yaw) Ry(pitch) Rx(roll); w_B = E(phi) dphi/dt (exact at any pitch); alpha_B its derivative."""
    return [
        "# R = Rz(yaw) Ry(pitch) Rx(roll), body -> navigation; w = E(phi) dphi/dt, exact at any pitch; al.. = dw/dt",
        "r00 = cy * cp", "r01 = cy * sp * sr - sy * cr", "r02 = cy * sp * cr + sy * sr",
        "r10 = sy * cp", "r11 = sy * sp * sr + cy * cr", "r12 = sy * sp * cr - cy * sr",
        "r20 = -sp", "r21 = cp * sr", "r22 = cp * cr",
        "wx = dr - sp * dy",
        "wy = cr * dp + sr * cp * dy",
        "wz = -sr * dp + cr * cp * dy",
        "alx = ddr - cp * dp * dy - sp * ddy",
        "aly = -sr * dr * dp + cr * ddp + cr * dr * cp * dy - sr * sp * dp * dy + sr * cp * ddy",
        "alz = -cr * dr * dp - sr * ddp - sr * dr * cp * dy - cr * sp * dp * dy + cr * cp * ddy",
    ]



INLINE_IMUS = 16     # up to this many IMUs, their lines sit in the kernel's loop (see generate_source)


# --- source ------------------------------------------------------------------------------------------

#: Angles derived from what the motion computed anyway (tangent: cos/sin; a quaternion or a reference: R), which
#: only the truth output reads: with switched outputs they run where the truth is written, only when it is
_DERIVED_ANGLE = re.compile(r"^(roll|pitch|yaw) = (math\.atan2\(.*|0\.0)$")
#: With switched outputs: which outputs the caller passed (an output not wanted is an empty array,
#: imu_emulator.codegen.signature.arguments), read once per call
_SWITCHES = ["# the outputs this call writes: an output not wanted is an empty array (one kernel serves every choice)",
             "want_quat = out_quat.shape[0] > 0", "want_truth = tr_pos.shape[0] > 0",
             "want_bias = tr_bias_acc.shape[0] > 0"]


def _when(flag: str, lines: list[str]) -> list[str]:
    return [f"if {flag}:"] + ["    " + line for line in lines] if lines else []


def generate_source(scene: Scene, attitude: bool, truth: bool, increments: int = 0, switched: bool = False) -> str:
    """The kernel module for this scene and outputs (`increments`: Gauss–Legendre nodes of the integrated
    outputs, 0 for none). `switched`: every output's lines, each written only when the caller passes its arrays
    (not empty), so that one kernel could serve generate, generate --truth and stream (`attitude` and `truth` are
    then ignored). The cache does not use it: it cost 3-7 % per sample against each choice's own kernel
    (tools/bench_parametric.py; docs/kernel.md); it stays for that
    benchmark to measure again. No user text reaches the source except validated numbers as repr."""
    from imu_emulator.motion.code import motion_code

    if switched:
        attitude = truth = True
    plan = EffectPlan(scene)
    motion = motion_code(scene, angles=truth, origin=plan.origin, slots=plan.expression_slots)
    derived_angles = []
    if switched:
        derived_angles = [line for line in motion.lines + motion.after_rotation if _DERIVED_ANGLE.match(line)]
        motion.lines = [line for line in motion.lines if not _DERIVED_ANGLE.match(line)]
        motion.after_rotation = [line for line in motion.after_rotation if not _DERIVED_ANGLE.match(line)]
    n_phase = len(motion.phase_vars)
    phase_stage = []
    if n_phase:
        phase_stage = ["# short independent chains the CPU overlaps across samples; one contiguous row of `phases`",
                       "# per term, so that this loop vectorizes",
                       "for jj in range(mc):", "    k = k0 + c0 + jj"]
        phase_lines = motion.phase_lines
        if plan.clock:   # the phase at the actual instant: frac(C0 + (k + clk) CS), clk small
            phase_stage += ["    s = s0 + c0 + jj"] + ["    " + line for line in plan.clock]
            phase_lines = [re.sub(r"(PH(\d+)_C0\))$", r"\1 + clk * PH\2_HI", line) for line in phase_lines]
        phase_stage += ["    " + line for line in explain.annotate(phase_lines)]
        phase_stage += [f"    phases[{i}, jj] = {name}" for i, name in enumerate(motion.phase_vars)]
    body = [f"{name} = phases[{i}, jj]" for i, name in enumerate(motion.phase_vars)] + motion.lines
    if not motion.rotation_given:   # attitude given as a rotation matrix (e.g. quaternion logs)
        body += _rotation_and_rates()
    body += motion.after_rotation   # [attitude] reference other than local level (imu_emulator.motion.earth)
    body = explain.annotate(body)
    navigation = list(plan.navigation)
    if plan.nav_rate:   # the navigation frame's rate, then it and its derivative in body axes (wb.., gal..)
        from imu_emulator.motion.earth import inertial_rate_lines
        navigation = (["# the navigation frame's rate w.r.t. inertial space (wn..) and its derivative (dwn..), "
                       "from the effects below"]
                      + [f"{v}{a} = 0.0" for v in ("wn", "dwn") for a in "xyz"] + navigation
                      + ["# that rate and its derivative in body axes (wb.., gal..)"]
                      + inertial_rate_lines(motion.level_rate))

    per_imu, frames = [], []
    for m, imu in enumerate(scene.imus):
        stages = plan.per_imu[m]
        gw = ("wx", "wy", "wz")
        if plan.nav_rate:   # plus R^T w_n: the navigation frame's rate in body axes
            gw = tuple(f"{w} + wb{c}" for w, c in zip(gw, "xyz"))
        frame_slots = dict(m=m, gwx=gw[0], gwy=gw[1], gwz=gw[2], body=stages["body"], frame=stages["frame"])
        frames.append(fill(IMU_FRAME_TEMPLATE, **frame_slots, increment=[]).splitlines())
        quat = []
        if attitude:
            q = "qbw, qbx, qby, qbz"
            for lines, turn in plan.axes_turns.get(m, []):   # the IMU's axes turned in the body stage
                quat += lines + [f"qw, qx, qy, qz = quat_multiply_scalar({q}, {', '.join(turn)})"]
                q = "qw, qx, qy, qz"
            if m in plan.mounting_quat:
                quat += [f"qw, qx, qy, qz = quat_multiply_scalar({q}, {', '.join(plan.mounting_quat[m])})"]
            elif not quat:
                quat = ["qw, qx, qy, qz = qbw, qbx, qby, qbz"]
            quat = (["# this IMU's attitude: the body's, then its axes' turns, then its mounting"] + quat
                    + [f"out_quat[{m}, j, {i}] = q{c}" for i, c in enumerate("wxyz")])
            quat = _when("want_quat", quat) if switched else quat
        bias_truth = []
        if truth and plan.bias_truth:
            for array, prefix in (("tr_bias_acc", TRIADS["accel"][2]), ("tr_bias_gyro", TRIADS["gyro"][2])):
                bias_truth += [f"{array}[{m}, j, {i}] = {prefix}{c}" for i, c in enumerate(AXES)]
            bias_truth = _when("want_bias", bias_truth) if switched else bias_truth
        sensor = stages["sensor"]
        if sensor:   # the true sensor-frame values and the realized bias, for the error effects to use
            sensor = ["# the true sensor-frame values (tf.., tw..) and the realized bias (ba.., bg..) for the errors",
                      "tfx, tfy, tfz, twx, twy, twz = ox, oy, oz, gx, gy, gz",
                      "bax = bay = baz = bgx = bgy = bgz = 0.0"] + sensor
        elif truth and plan.bias_truth:   # an IMU without error terms beside one with: its bias is 0
            sensor = ["# no error terms on this IMU: its realized bias is 0", "bax = bay = baz = bgx = bgy = bgz = 0.0"]
        increment = []
        if increments:
            from imu_emulator.codegen import increments as inc
            increment = inc.imu_lines(m, sensor, [f"state[{i}]" if var is None else var   # slots read in place too
                                                  for i, (var, owner, _) in enumerate(plan.slots) if owner == m])
        per_imu.append(fill(PER_IMU_TEMPLATE, **frame_slots, increment=increment, sensor=sensor,
                            output=stages["output"], quat=quat, bias_truth=bias_truth).splitlines())

    truth_lines = []
    if truth:
        truth_lines.append("# truth: the motion of the reference point S")
        truth_lines += derived_angles
        for array, names in TRUTH_OUTPUTS:
            truth_lines += [f"{array}[j, {i}] = {name}" for i, name in enumerate(names)]
        truth_lines = _when("want_truth", truth_lines) if switched else truth_lines
    attitude_lines = (["qbw, qbx, qby, qbz = matrix_to_quat_scalar(r00, r01, r02, r10, r11, r12, r20, r21, r22)"]
                      if attitude else [])
    attitude_lines = _when("want_quat", attitude_lines) if switched else attitude_lines
    imports = [f"from {module} import {', '.join(names)}" for module, names in RUNTIME_IMPORTS.items()]
    constants = [f"{name} = {value!r}" for name, value in motion.constants.items()]
    args, integrate = ARGS, []
    if increments:
        from imu_emulator.codegen import increments as inc
        inc.check_integrable(plan.active)
        args, constants = ARGS + inc.ARGS, constants + inc.constants(increments)
        node_motion = inc.sampled_at_nodes(motion.lines)   # sampled motion: node rows after the samples'
        integrate = explain.annotate(inc.node_lines(
            increments, n_imu=len(scene.imus), clock=plan.clock, phase_lines=motion.phase_lines,
            motion=node_motion + ([] if motion.rotation_given else _rotation_and_rates()) + motion.after_rotation,
            navigation=navigation,
            imu_frames=frames, t0=plan.t0, dt=plan.dt))
    # Many IMUs: each IMU's lines are a function of its own (compile time linear in the IMU count). A few
    # compile faster inline (16 IMUs: 4.5 s inline, 7.0 s as functions; 64: 39.8 s against 20.8 s,
    # tools/bench_compile_imus.py). With increments the node loop in the body shares the IMUs' variables, so
    # their lines stay in the loop there.
    separate = len(per_imu) > INLINE_IMUS and not increments
    module_names = {"math", "np", "numba", "EPS_V2", "CHUNK", "N_PHASE", *motion.constants,
                    *(name for names in RUNTIME_IMPORTS.values() for name in names)}
    # slots without a variable (state blocks) are read as state[i] where they are used
    shared_slots = [(i, var) for i, (var, m, _) in enumerate(plan.slots)
                    if var is not None and (m is None or not separate)]
    imu_functions, per_imu_lines = [], []
    for m, lines in enumerate(per_imu):
        if not separate:
            per_imu_lines += lines
            continue
        slots = [(i, var) for i, (var, owner, _) in enumerate(plan.slots) if owner == m and var is not None]
        function, call = _imu_function(m, lines, slots, module_names)
        imu_functions += function
        per_imu_lines.append(call)
    header = explain.header(plan, module=__name__, version=CODEGEN_VERSION, attitude=attitude, truth=truth,
                            increments=increments)
    header += explain.glossary(plan, args=args, arg_notes=ARG_NOTES, motion_constants=motion.constants)
    load_state = ["# the state slots this loop keeps in local variables (the glossary names them)"] * bool(shared_slots)
    load_state = (_SWITCHES if switched else []) + load_state
    return explain.stamp(_load_params(fill(
        KERNEL_TEMPLATE, header=header, imports=imports, eps_v2=repr(EPS_SPEED ** 2), chunk=CHUNK,
        constants=constants, load_params=[_LOAD_PARAMS],
        imu_functions=imu_functions, args=", ".join(args), increments=integrate,
        load_state=load_state + [f"{var} = state[{i}]" for i, var in shared_slots],
        store_state=[f"state[{i}] = {var}" for i, var in shared_slots],
        n_phase=max(n_phase, 1), phase_stage=phase_stage, t0=plan.t0, dt=plan.dt,
        clock=plan.clock, clock_shift=f" + clk * {plan.dt}" if plan.clock else "",
        motion=body, navigation=navigation, attitude=attitude_lines, per_imu=per_imu_lines, truth=truth_lines)))


_LOAD_PARAMS = "#@load_params"
_PARAM = re.compile(r"\bprm_(\d+)\b")


def _load_params(source: str) -> str:
    """kernel_body's `prm_i = prm[i]` lines, for the scalar parameters its own lines read (an IMU of its own
    function loads its own: 100 IMUs' parameters as locals of one function is what made numba's typing slow)."""
    head, _, body = source.partition("def kernel_body(")
    used = sorted({int(i) for i in _PARAM.findall(body)})
    indent = "    "
    loads = "\n".join(f"{indent}prm_{i} = prm[{i}]" for i in used)
    return head + "def kernel_body(" + body.replace(f"{indent}{_LOAD_PARAMS}", loads) if loads else \
        head + "def kernel_body(" + body.replace(f"{indent}{_LOAD_PARAMS}\n", "")


class _ReadsBeforeAssigned(ast.NodeVisitor):
    """Names read before any assignment, in execution order: an assignment's value before its targets, an `if`'s
    test before its branches. (Walking a whole statement's loads before its stores took a name assigned and then
    read inside one `if` -- bias_instability's interpolation weights -- for an argument the caller does not have.)"""

    def __init__(self, assigned: set[str]):
        self.assigned, self.reads = set(assigned), []

    def visit_Name(self, node):
        if isinstance(node.ctx, ast.Store):
            self.assigned.add(node.id)
        elif node.id not in self.assigned and node.id not in self.reads:
            self.reads.append(node.id)

    def visit_Assign(self, node):
        self.visit(node.value)
        for target in node.targets:
            self.visit(target)

    def visit_AugAssign(self, node):
        self.visit(node.value)
        if isinstance(node.target, ast.Name):
            self.visit(ast.Name(node.target.id, ast.Load()))
        self.visit(node.target)


def _read_before_assigned(tree: ast.AST, assigned: set[str]) -> list[str]:
    visitor = _ReadsBeforeAssigned(assigned)
    visitor.visit(tree)
    return visitor.reads


def _imu_function(m: int, lines: list[str], slots: list[tuple[int, str]], module_names: set[str]):
    """IMU m's stages 2-4 as a function of its own, and the line that calls it once per sample.

    With every IMU's lines in one loop body, numba's type inference grew faster than linearly with the IMU count
    (64 IMUs: 40 s; 100 did not finish); one function per IMU is typed and optimized on its own. Its arguments
    are the names its lines read before assigning them (shared motion, arrays, sample indices), found from the
    code; its state slots are read at its start and written back at its end."""
    reads = _read_before_assigned(ast.parse("\n".join(lines)), {var for _, var in slots})
    args = [name for name in reads if name not in module_names and not hasattr(builtins, name)]
    params = [name for name in args if _PARAM.fullmatch(name)]     # its parameters: loaded here, from prm
    args = [name for name in args if name not in params] + (["prm"] if params and "prm" not in args else [])
    if slots and "state" not in args:
        args.append("state")
    body = ([f"{name} = prm[{name[4:]}]" for name in params] + [f"{var} = state[{i}]" for i, var in slots] + lines
            + [f"state[{i}] = {var}" for i, var in slots])
    function = ["", "", f"# IMU {m}'s stages 2-4, a function of its own: numba types it alone (compile time linear in "
                "the IMU count)", "@numba.njit(cache=True, nogil=True, error_model='numpy')",
                f"def imu_{m}({', '.join(args)}):"] + ["    " + line for line in body]
    return function, f"imu_{m}({', '.join(args)})"

