"""The generated kernel's calling convention, in one place: what it imports at run time, its arguments in order,
which motion variables its truth outputs hold, and how a caller lays the arguments out (the Simulation for a
block, the cache for the trial call that compiles an entry and for the typed machine-code export)."""
from __future__ import annotations

import numpy as np

from imu_emulator.codegen.plan import EffectPlan
from imu_emulator.scene.model import SampledData, Scene

#: Modules the generated source imports at run time (part of the generator for the cache key).
RUNTIME_IMPORTS = {
    "imu_emulator.numerics.phase": ("sincos_cycles",),
    "imu_emulator.geo.rotations": ("matrix_to_quat_scalar", "quat_multiply_scalar"),
    "imu_emulator.numerics.counter_rng": ("normal",),
    "imu_emulator.numerics.shaped_noise": ("fill_chunk", "fill_chunk_direct", "hermite5", "hermite3"),
}
#: The kernel's arguments (then imu_emulator.codegen.increments.ARGS when it integrates); `arguments` lays them out.
ARGS = ("k0", "n", "s0", "mot", "att", "hold", "keys", "state", "prm", "out_acc", "out_gyro", "out_quat",
        "tr_pos", "tr_vel", "tr_euler", "tr_omega", "tr_alpha", "tr_bias_acc", "tr_bias_gyro")
#: What each argument holds (the generated source's glossary prints these), kernel_body's scratch included
ARG_NOTES = {
    "k0": "the block's first scene sample (motion: t = t0 + k dt, k = k0 + j)",
    "n": "the block's length in samples (j = 0 .. n-1)",
    "s0": "the run sample of k0 (random numbers and state follow the run sample s = s0 + j)",
    "mot": "sampled trajectory [derivative, row, axis]: rows 0..n-1 the samples, then the increments' nodes; "
           "empty when the trajectory is symbolic",
    "att": "sampled attitude [derivative, row, component] (Euler angles or quaternion), rows as mot; empty else",
    "hold": "tangent attitude's last defined heading and pitch (cos, sin, cos, sin), carried across blocks",
    "keys": "one key per random stream (below), made from the seed at run time",
    "state": "the state slots (below), carried across blocks",
    "prm": "the scene's numbers (below): parameters, lever arms, mountings, t0, dt; the source holds none of them, so "
           "scenes differing only in them share this kernel",
    "out_acc": "accelerometer output (n_imu, n, 3), m/s^2, sensor axes",
    "out_gyro": "gyro output (n_imu, n, 3), rad/s, sensor axes",
    "out_quat": "attitude of each IMU's axes (n_imu, n, 4), scalar first; empty when not output",
    "tr_pos": "truth: position of S (n, 3), m, navigation axes; empty when not output",
    "tr_vel": "truth: velocity of S (n, 3), m/s",
    "tr_euler": "truth: roll, pitch, yaw (n, 3), rad",
    "tr_omega": "truth: body rate (n, 3), rad/s, body axes",
    "tr_alpha": "truth: body angular acceleration (n, 3), rad/s^2, body axes",
    "tr_bias_acc": "truth: realized accelerometer bias (n_imu, n, 3); empty unless an effect adds a bias",
    "tr_bias_gyro": "truth: realized gyro bias (n_imu, n, 3)",
    "out_dtheta": "integrated gyro output (n_imu, n, 3), rad over (t_k-1, t_k] (imu_emulator.codegen.increments)",
    "out_dvel": "integrated accelerometer output (n_imu, n, 3), m/s over (t_k-1, t_k]",
    "phases": "kernel_body's scratch (N_PHASE, CHUNK): sin and cos of each periodic term, per chunk sample",
}
TRUTH_OUTPUTS = (("tr_pos", ("px", "py", "pz")), ("tr_vel", ("vx", "vy", "vz")),
                 ("tr_euler", ("roll", "pitch", "yaw")), ("tr_omega", ("wx", "wy", "wz")),
                 ("tr_alpha", ("alx", "aly", "alz")))
#: The truth arrays' keys in a SampleBlock, in TRUTH_OUTPUTS order: (n, 3) each
TRUTH_KEYS = ("position", "velocity", "euler", "omega_body", "alpha_body")
#: per-IMU truth (n_imu, n, 3), present when an effect adds a bias: the realized bias of each triad
BIAS_TRUTH_KEYS = ("accel_bias", "gyro_bias")
#: What stands for an array the run does not ask for (motion not sampled, an output not wanted): empty, of the
#: rank numba typed the kernel with
EMPTY3 = np.zeros((0, 0, 0))
EMPTY2 = np.zeros((0, 0))


def arguments(k0, n, s0, mot, att, hold, keys, state, params, accel, gyro, quat=None, truth=None, bias=None,
              increments=None) -> tuple:
    """The kernel's arguments in ARGS order: `quat` (n_imu, n, 4), `truth` the TRUTH_OUTPUTS arrays, `bias` the
    BIAS_TRUTH_KEYS arrays, `increments` (dtheta, dvel), each None when not output."""
    return (np.int64(k0), np.int64(n), np.int64(s0), mot, att, hold, keys, state, params, accel, gyro,
            EMPTY3 if quat is None else quat,
            *([EMPTY2] * len(TRUTH_OUTPUTS) if truth is None else truth),
            *([EMPTY3] * len(BIAS_TRUTH_KEYS) if bias is None else bias),
            *(increments or ()))


def trial_arguments(scene: Scene, attitude: bool, truth: bool, increments: int = 0) -> tuple:
    """Arguments for no sample, of the types a block passes (the machine-code export is typed from them)."""
    n_imu = len(scene.imus)
    plan = EffectPlan(scene)
    empty = np.zeros((1, 0, 3))

    def outputs(count):
        return [np.zeros((n_imu, 0, 3))] * count
    return arguments(0, 0, 0, empty if isinstance(scene.trajectory, SampledData) else EMPTY3,
                     empty if isinstance(scene.attitude, SampledData) else EMPTY3, np.zeros(4),
                     plan.keys(0), plan.initial_state(0), plan.param_values(), *outputs(2),
                     quat=np.zeros((n_imu, 0, 4)) if attitude else None,
                     truth=[np.zeros((0, 3))] * len(TRUTH_OUTPUTS) if truth else None,
                     bias=outputs(len(BIAS_TRUTH_KEYS)) if truth and plan.bias_truth else None,
                     increments=outputs(2) if increments else None)


def trial(kernel, scene: Scene, attitude: bool, truth: bool, increments: int = 0) -> None:
    """Call a freshly loaded kernel on no sample with the argument types a block uses (numba compiles on the
    first call; the cache publishes only compiled kernels)."""
    kernel(*trial_arguments(scene, attitude, truth, increments))
