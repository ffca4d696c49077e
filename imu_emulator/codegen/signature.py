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
}
#: The kernel's arguments (then imu_emulator.codegen.increments.ARGS when it integrates); `arguments` lays them out.
ARGS = ("k0", "n", "s0", "mot", "att", "hold", "keys", "state", "out_acc", "out_gyro", "out_quat",
        "tr_pos", "tr_vel", "tr_euler", "tr_omega", "tr_alpha", "tr_bias_acc", "tr_bias_gyro")
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


def arguments(k0, n, s0, mot, att, hold, keys, state, accel, gyro, quat=None, truth=None, bias=None,
              increments=None) -> tuple:
    """The kernel's arguments in ARGS order: `quat` (n_imu, n, 4), `truth` the TRUTH_OUTPUTS arrays, `bias` the
    BIAS_TRUTH_KEYS arrays, `increments` (dtheta, dvel), each None when not output."""
    return (np.int64(k0), np.int64(n), np.int64(s0), mot, att, hold, keys, state, accel, gyro,
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
                     plan.keys(0), plan.initial_state(0), *outputs(2),
                     quat=np.zeros((n_imu, 0, 4)) if attitude else None,
                     truth=[np.zeros((0, 3))] * len(TRUTH_OUTPUTS) if truth else None,
                     bias=outputs(len(BIAS_TRUTH_KEYS)) if truth and plan.bias_truth else None,
                     increments=outputs(2) if increments else None)


def trial(kernel, scene: Scene, attitude: bool, truth: bool, increments: int = 0) -> None:
    """Call a freshly loaded kernel on no sample with the argument types a block uses (numba compiles on the
    first call; the cache publishes only compiled kernels)."""
    kernel(*trial_arguments(scene, attitude, truth, increments))
