"""The companion sensors' part of a block (imu_emulator.companions): their output arrays, and running them on the
kernel's truth (body position, velocity, rate; Earth truth) and each IMU's attitude output.

The attitude is relative to the local level frame at the current position when the Earth model is on
(imu_emulator.motion.earth); with it off (a flat ENU/NED scene with an origin) it is relative to the origin's
tangent axes, taken here as the local ones: off by the distance from the origin over the Earth's radius
(1.6e-4 rad a kilometre), as the flat scene itself is."""
from __future__ import annotations

import numpy as np

from imu_emulator.companions import COMPANIONS, Truth
from imu_emulator.geo.frames import NED_FROM_ENU
from imu_emulator.geo.rotations import euler_to_matrix, quat_to_matrix


def new_outputs(scene, n: int) -> list[dict]:
    """Per IMU, empty arrays for the fields of the companions it carries."""
    return [{name: np.empty((n,) if width == 0 else (n, width))
             for companion in imu.companions for name, width in COMPANIONS[companion].fields.items()}
            for imu in scene.imus]


def run_companions(scene, runners: list[dict], t: np.ndarray, s0: int, out) -> None:
    """Fill out.companion from the block's truth (earth_truth.fill has run) and attitude, IMU by IMU."""
    truth = out.truth
    level = NED_FROM_ENU if scene.frame == "ENU" else np.eye(3)      # the attitude's level axes -> NED
    c_nb = level @ euler_to_matrix(truth["euler"])
    s = s0 + np.arange(len(t), dtype=np.int64)
    for m, imu in enumerate(scene.imus):
        if not runners[m]:
            continue
        view = Truth(s=s, t=t, rate_hz=scene.rate_hz, llh=truth["geodetic"], v_ned=truth["velocity_ned"],
                     c_ns=level @ quat_to_matrix(out.quat[m]), c_nb=c_nb, omega_b=truth["omega_body"],
                     values=imu.values)
        for runner in runners[m].values():
            for name, values in runner.block(view).items():
                out.companion[m][name][:] = values
