"""The numba kernel, generated as source for exactly the effects a scene names.

An effect is a small set of code snippets attached to hooks in the per-sample loop. A switched-off
effect contributes no line, so it is absent from the machine code rather than multiplied by zero.
Scene constants (lever arms, mounting matrices, g, phase constants) are baked in as literals so LLVM
folds them. The generated module is written to a cache directory named by a hash of everything that
shapes it, and compiled with numba's cache=True beside it: a second run with the same scene imports
it without sympy and without compiling.

Hooks, in loop order (variables available to each):
    nav:    fnx fny fnz        specific-force input in the navigation frame (starts as a)
    body:   fax fay faz, gwx gwy gwz   per IMU, body frame, at the IMU's position
    sensor: ox oy oz, gx gy gz  per IMU, sensor frame (what the sensor measures)
Adding an effect = adding an entry to EFFECT_CODE (and its name to scene.EFFECTS).
"""
from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import sys
from pathlib import Path

import numpy as np

from imu_emulator.scene import Expressions, ImuSpec, Scene

CODEGEN_VERSION = "2"
CHUNK = 256          # samples per phase stage; the kernel's scratch `phases` is (CHUNK, N_PHASE)
# Ranks of the kernel's array arguments after (k0, n): mot, att, hold, out_acc, out_gyro, out_quat, tr_pos,
# tr_vel, tr_euler, tr_omega, tr_alpha, phases (scratch: the kernel allocates nothing, so it runs without NRT).
KERNEL_ARRAY_NDIMS = (3, 3, 1, 3, 3, 3, 2, 2, 2, 2, 2, 2)
EPS_SPEED = 1e-6     # m/s: below this the body is standing still for tangent attitude


def _lever_arm(scene: Scene, imu: ImuSpec, m: int) -> list[str]:
    rx, ry, rz = imu.lever_arm_m
    if not any(imu.lever_arm_m):
        return []
    # f_I = f_S + w x (w x r) + alpha x r, body frame
    return [
        f"ux = wy * {rz!r} - wz * {ry!r}", f"uy = wz * {rx!r} - wx * {rz!r}", f"uz = wx * {ry!r} - wy * {rx!r}",
        f"fax += wy * uz - wz * uy + (aly * {rz!r} - alz * {ry!r})",
        f"fay += wz * ux - wx * uz + (alz * {rx!r} - alx * {rz!r})",
        f"faz += wx * uy - wy * ux + (alx * {ry!r} - aly * {rx!r})",
    ]


def mounting_matrix(imu: ImuSpec) -> np.ndarray:
    """M maps sensor coordinates to body coordinates (sensor frame = body frame rotated by M)."""
    from imu_emulator.rotations import euler_to_matrix
    return euler_to_matrix(np.radians(imu.mounting_rpy_deg))


def _mounting(scene: Scene, imu: ImuSpec, m: int) -> list[str]:
    if not any(imu.mounting_rpy_deg):
        return []
    M = mounting_matrix(imu)
    lines = []
    for src, dst in (("fa", "o"), ("gw", "g")):
        for row, axis in enumerate("xyz"):
            # sensor = M^T body
            lines.append(f"{dst}{axis} = " + " + ".join(f"{float(M[col, row])!r} * {src}{'xyz'[col]}" for col in range(3)))
    return lines


def _gravity(scene: Scene) -> list[str]:
    # f = a - g; g = (0, 0, -g0) in ENU, (0, 0, +g0) in NED
    sign = "+" if scene.frame == "ENU" else "-"
    return [f"fnz = fnz {sign} {scene.gravity_mps2!r}"]


EFFECT_CODE = {
    "gravity": {"nav": _gravity},
    "lever_arm": {"body": _lever_arm},
    "mounting": {"sensor_frame": _mounting},
}


def _indent(lines, level):
    return [("    " * level) + line for line in lines]


def _rotation_and_rates() -> list[str]:
    """R = Rz(yaw) Ry(pitch) Rx(roll); w_B = E(phi) dphi/dt (exact at any pitch); alpha_B its derivative."""
    return [
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


def generate_source(scene: Scene, attitude: bool, truth: bool) -> str:
    from imu_emulator.motion import motion_code

    motion = motion_code(scene, angles=truth)
    effects = [name for name in EFFECT_CODE if name in scene.effects]

    body = ["k = k0 + j", f"t = {scene.t0_s!r} + k * {1.0 / scene.rate_hz!r}"]
    body += [f"{name} = phases[jj, {i}]" for i, name in enumerate(motion.phase_vars)]
    body += motion.lines
    if not motion.rotation_given:
        body += _rotation_and_rates()
    body += ["fnx = ax", "fny = ay", "fnz = az"]
    for name in effects:
        if "nav" in EFFECT_CODE[name]:
            body += EFFECT_CODE[name]["nav"](scene)
    # specific force at S in body coordinates: R^T (a - g)
    body += ["fbx = r00 * fnx + r10 * fny + r20 * fnz",
             "fby = r01 * fnx + r11 * fny + r21 * fnz",
             "fbz = r02 * fnx + r12 * fny + r22 * fnz"]
    if attitude:
        body += ["qbw, qbx, qby, qbz = matrix_to_quat_scalar(r00, r01, r02, r10, r11, r12, r20, r21, r22)"]
    for m, imu in enumerate(scene.imus):
        body += [f"# IMU {m}", "fax = fbx", "fay = fby", "faz = fbz", "gwx = wx", "gwy = wy", "gwz = wz"]
        for name in effects:
            if "body" in EFFECT_CODE[name]:
                body += EFFECT_CODE[name]["body"](scene, imu, m)
        frame_lines = []
        for name in effects:
            if "sensor_frame" in EFFECT_CODE[name]:
                frame_lines += EFFECT_CODE[name]["sensor_frame"](scene, imu, m)
        if not frame_lines:
            frame_lines = ["ox = fax", "oy = fay", "oz = faz", "gx = gwx", "gy = gwy", "gz = gwz"]
        body += frame_lines
        for name in effects:
            if "sensor" in EFFECT_CODE[name]:
                body += EFFECT_CODE[name]["sensor"](scene, imu, m)
        body += [f"out_acc[{m}, j, 0] = ox", f"out_acc[{m}, j, 1] = oy", f"out_acc[{m}, j, 2] = oz",
                 f"out_gyro[{m}, j, 0] = gx", f"out_gyro[{m}, j, 1] = gy", f"out_gyro[{m}, j, 2] = gz"]
        if attitude:
            if "mounting" in effects and any(imu.mounting_rpy_deg):
                from imu_emulator.rotations import matrix_to_quat
                qm = matrix_to_quat(mounting_matrix(imu))
                body += ["qw, qx, qy, qz = quat_multiply_scalar(qbw, qbx, qby, qbz, "
                         + ", ".join(repr(float(v)) for v in qm) + ")"]
            else:
                body += ["qw, qx, qy, qz = qbw, qbx, qby, qbz"]
            body += [f"out_quat[{m}, j, 0] = qw", f"out_quat[{m}, j, 1] = qx",
                     f"out_quat[{m}, j, 2] = qy", f"out_quat[{m}, j, 3] = qz"]
    if truth:
        for array, names in (("tr_pos", ("px", "py", "pz")), ("tr_vel", ("vx", "vy", "vz")),
                             ("tr_euler", ("roll", "pitch", "yaw")), ("tr_omega", ("wx", "wy", "wz")),
                             ("tr_alpha", ("alx", "aly", "alz"))):
            body += [f"{array}[j, {i}] = {name}" for i, name in enumerate(names)]

    header = [
        "# Generated by imu_emulator.kernel; do not edit.",
        "import math",
        "import numba",
        "import numpy as np",
        "from imu_emulator.phase import sincos_cycles",
        "from imu_emulator.rotations import matrix_to_quat_scalar, quat_multiply_scalar",
        f"EPS_V2 = {EPS_SPEED ** 2!r}",
        f"CHUNK = {CHUNK!r}",
        f"N_PHASE = {max(len(motion.phase_vars), 1)!r}",
    ]
    header += [f"{name} = {value!r}" for name, value in motion.constants.items()]
    # Samples are processed in chunks: first every periodic phase of the chunk (short, independent
    # chains the CPU overlaps across samples), then the rest. One long chain per sample would leave the
    # CPU waiting on latency: measured 50 -> 35 ns/sample on the circle scene.
    n_phase = len(motion.phase_vars)
    func = [
        "",
        "@numba.njit(cache=True, nogil=True, error_model='numpy')",
        "def kernel(k0, n, mot, att, hold, out_acc, out_gyro, out_quat, tr_pos, tr_vel, tr_euler, tr_omega, tr_alpha,",
        "           phases):",
        "    hcy, hsy, hcp, hsp = hold[0], hold[1], hold[2], hold[3]",
        "    for j0 in range(0, n, CHUNK):",
        "        m = min(CHUNK, n - j0)",
    ]
    if n_phase:
        func += ["        for jj in range(m):", "            k = k0 + j0 + jj"]
        func += _indent(motion.phase_lines, 3)
        func += _indent([f"phases[jj, {i}] = {name}" for i, name in enumerate(motion.phase_vars)], 3)
    func += ["        for jj in range(m):", "            j = j0 + jj"]
    tail = ["    hold[0], hold[1], hold[2], hold[3] = hcy, hsy, hcp, hsp"]
    return "\n".join(header + func + _indent(body, 3) + tail) + "\n"


def cache_dir() -> Path:
    root = os.environ.get("IMU_EMULATOR_CACHE")
    path = Path(root) if root else Path.home() / ".cache" / "imu-emulator"
    return path / "kernels"


def _code_fingerprint() -> str:
    """Changes when the code that generates kernels changes, so stale cached kernels are never used."""
    here = Path(__file__).parent
    h = hashlib.sha256(CODEGEN_VERSION.encode())
    for name in ("kernel.py", "motion.py", "expressions.py", "rotations.py", "phase.py", "native.py"):
        h.update((here / name).read_bytes())
    return h.hexdigest()


def scene_key(scene: Scene, attitude: bool, truth: bool) -> str:
    """Everything that shapes the generated source, without running sympy."""
    def describe(part):
        if isinstance(part, Expressions):
            return ["expr", list(part.texts)]
        return ["sampled", part.kind] if part is not None else None
    spec = {
        "rate": scene.rate_hz, "t0": scene.t0_s, "frame": scene.frame, "g": scene.gravity_mps2,
        "params": sorted(scene.params.items()), "trajectory": describe(scene.trajectory),
        "attitude_mode": scene.attitude_mode, "attitude": describe(scene.attitude),
        "imus": [[i.lever_arm_m, i.mounting_rpy_deg] for i in scene.imus],
        "effects": sorted(scene.effects), "outputs": [attitude, truth], "code": _code_fingerprint(),
        "python": sys.version_info[:2],
    }
    return hashlib.sha256(json.dumps(spec, default=repr).encode()).hexdigest()[:24]


_loaded: dict[str, object] = {}


def compile_kernel(scene: Scene, attitude: bool = True, truth: bool = False):
    """The kernel function for this scene's motion, effects and outputs (cached in memory and on disk).

    Called as kernel(k0, n, mot, att, hold, out_acc, out_gyro, out_quat, tr_pos, tr_vel, tr_euler, tr_omega,
    tr_alpha). A kernel compiled before is loaded as machine code without numba (imu_emulator.native)."""
    from imu_emulator import native

    key = scene_key(scene, attitude, truth)
    if key in _loaded:
        return _loaded[key]
    directory = cache_dir()
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"k_{key}.py"
    object_path = path.with_suffix(".o")
    loaded = native.load(object_path, KERNEL_ARRAY_NDIMS)
    if loaded is None:
        if not path.exists():
            source = generate_source(scene, attitude, truth)
            tmp = path.with_suffix(f".tmp{os.getpid()}")
            tmp.write_text(source)
            os.replace(tmp, path)  # atomic: a concurrent run sees the whole file or none
        spec = importlib.util.spec_from_file_location(f"imu_emulator_kernel_{key}", path)
        module = importlib.util.module_from_spec(spec)
        # numba's on-disk cache refers to the module by name when it reloads a compiled kernel.
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
        meta = {"n_phase": module.N_PHASE}
        if native.export(module.kernel, KERNEL_ARRAY_NDIMS, object_path, meta):
            loaded = native.load(object_path, KERNEL_ARRAY_NDIMS)
        if loaded is None:   # this numba or platform cannot: keep its dispatcher
            loaded = module.kernel, meta
    function, meta = loaded
    n_phase = int(meta["n_phase"])

    def kernel(*args):
        function(*args, np.empty((CHUNK, n_phase)))
    _loaded[key] = kernel
    return kernel


def cached_kernel(scene: Scene, attitude: bool = True, truth: bool = False) -> tuple[Path, bool]:
    """Where this scene's compiled kernel lives in the cache, and whether it is there (so the next run loads it
    instead of compiling)."""
    path = cache_dir() / f"k_{scene_key(scene, attitude, truth)}.o"
    return path, path.exists()
