"""The unit's own navigation estimate, for parts that output one (VN-100/300, Xsens MTi, MicroStrain GQ7, a
flight controller's MAVLink ATTITUDE): the truth plus first-order Gauss-Markov errors of attitude, position and
velocity, the 1-sigma uncertainties a consistent filter states (the same sigmas), and its mode.

Errors are drawn at the IMU's sample rate with time constant error_time_s, per axis: attitude as a small
rotation about local north, east, down (applied on the navigation side of the attitude, so it is the same
whatever the sensor's axes: estimate = Exp(e) * truth); position in metres north, east, down, added through
the local radii (imu_emulator.companions.gnss.offset_llh); velocity in m/s north, east, down. The reported
sigmas are attitude_error (roll, pitch, yaw, taken as about north, east, down, as small errors of a level
unit are), position_error and velocity_error. ins_mode is 1 (aligning) until aligning_s of scene time after
the run's start, then 2 (tracking), what a healthy unit reports.

Outputs (Samples): position_llh, velocity_ned, attitude_sigma_rad, position_sigma_m, velocity_sigma_mps,
ins_mode, and ins_attitude_error_rad (the rotation vector e, NED) that the stream applies to the attitude it
sends (`estimate_quat`); for the files, ins_quat and ins_euler: that estimated attitude as the unit reports it
(its forward-right-down axes -> local NED, whatever the scene's frame).
"""
from __future__ import annotations

import numpy as np

from imu_emulator.companions._record import Companion, Markov, Runner, check_sigmas, param_maker
from imu_emulator.companions.gnss import offset_llh
from imu_emulator.errors import SceneError


def estimate_quat(quat_ned: np.ndarray, error_ned: np.ndarray) -> np.ndarray:
    """(n, 4) sensor -> NED attitudes (scalar first) turned by the small NED rotation vectors error_ned:
    Exp(e) (x) q."""
    angle = np.linalg.norm(error_ned, axis=1)
    half = 0.5 * angle
    scale = np.where(angle > 0, np.sin(half) / np.where(angle > 0, angle, 1.0), 0.5)
    ew, ev = np.cos(half), error_ned * scale[:, None]
    qw, qv = quat_ned[:, 0], quat_ned[:, 1:]
    w = ew * qw - np.einsum("ni,ni->n", ev, qv)
    v = ew[:, None] * qv + qw[:, None] * ev + np.cross(ev, qv)
    return np.column_stack([w, v])


class _Estimate(Runner):
    def __init__(self, scene, m: int, values: dict):
        super().__init__()
        self.v = values
        step, tau = 1.0 / scene.rate_hz, values["error_time_s"]
        self.errors = [Markov(scene.seed, m, f"ins.{key}", values[key], step, tau)
                       for key in ("attitude_error", "position_error", "velocity_error")]
        self.t0 = scene.t0_s
        # the scene's sensor axes -> the part's forward-right-down ones (an ENU scene's are forward-left-up)
        self.frd = np.diag([1.0, -1.0, -1.0]) if scene.frame == "ENU" else np.eye(3)

    def block(self, truth) -> dict[str, np.ndarray]:
        v = self.v
        attitude, position, velocity = (markov.at(truth.s) for markov in self.errors)
        n = len(truth.s)

        def sigma(key):
            return np.broadcast_to(np.asarray(v[key], dtype=float), (n, 3))
        run_time = truth.s / truth.rate_hz
        return {"position_llh": offset_llh(truth.llh, position), "velocity_ned": truth.v_ned + velocity,
                "ins_attitude_error_rad": attitude, "attitude_sigma_rad": sigma("attitude_error"),
                "position_sigma_m": sigma("position_error"), "velocity_sigma_mps": sigma("velocity_error"),
                "ins_mode": np.where(run_time < v["aligning_s"], 1.0, 2.0), **self.reported(truth, attitude)}

    def reported(self, truth, error: np.ndarray) -> dict[str, np.ndarray]:
        """The attitude the unit reports, Exp(e) C_n,frd: its forward-right-down axes -> local NED (the wire
        formats' convention), as a quaternion (scalar first, w >= 0) and roll, pitch, yaw (z-y-x, rad)."""
        from scipy.spatial.transform import Rotation
        estimate = Rotation.from_rotvec(error) * Rotation.from_matrix(truth.c_ns @ self.frd)
        xyzw = estimate.as_quat()
        quat = xyzw[:, [3, 0, 1, 2]] * np.where(xyzw[:, 3:] < 0, -1.0, 1.0)
        return {"ins_quat": quat, "ins_euler": estimate.as_euler("ZYX")[:, ::-1].copy()}


def validate(values: dict, where: str) -> None:
    check_sigmas(values, ("attitude_error", "position_error", "velocity_error"), where, "ins")
    if not values["error_time_s"] > 0:
        raise SceneError(f"{where}.ins.error_time_s: a time constant > 0 s, got {values['error_time_s']!r}")
    if values["aligning_s"] < 0:
        raise SceneError(f"{where}.ins.aligning_s: a time >= 0 s, got {values['aligning_s']!r}")


_param = param_maker("ins", "vector3")


COMPANION = Companion(
    name="ins",
    description="the unit's own attitude, position and velocity estimate: truth plus Gauss-Markov errors, "
                "stated sigmas, mode",
    fields={"position_llh": 3, "velocity_ned": 3, "ins_attitude_error_rad": 3, "attitude_sigma_rad": 3,
            "position_sigma_m": 3, "velocity_sigma_mps": 3, "ins_mode": 0, "ins_quat": 4, "ins_euler": 3},
    start=_Estimate, validate=validate,
    params=(_param("attitude_error", "rad", "attitude error, 1 sigma roll, pitch, yaw (about N, E, D)",
                   datasheet='`["0.5 deg", "0.5 deg", "2 deg"]`'),
            _param("position_error", "m", "position error, 1 sigma north, east, down", datasheet="`[1, 1, 2]`"),
            _param("velocity_error", "m/s", "velocity error, 1 sigma north, east, down", datasheet="`0.05 m/s`"),
            _param("error_time_s", "s", "time constant of the errors (first-order Gauss-Markov)", "scalar", 60.0,
                   "`60 s`"),
            _param("aligning_s", "s", "ins_mode 1 (aligning) for this long after the run's start, then 2",
                   "scalar", 0.0, "`30 s`")))
