"""The position smoothing of a replayed log chosen from the log's own velocity (`position_noise_m =
"velocity"`): PX4's `vehicle_local_position` and ArduPilot's EKF log a velocity beside the position, estimated
from other sensors, so its errors are independent of the position's noise. Among smoothing splines whose
stated noise σ runs over a grid, the one whose derivative best matches the logged velocity (least RMS
difference) has the least velocity error, the logged velocity's own error adding the same to every candidate;
its σ is used for the replay (one choice for all three axes, as one receiver's noise is stated for all)."""
from __future__ import annotations

import numpy as np

from imu_emulator.errors import DataError

# Half-decade steps from 0.1 mm to 3 m: what a log's position noise can be (RTK to plain GNSS).
GRID_M = tuple(float(x) for x in 10.0 ** np.arange(-4.0, 0.6, 0.5))
MIN_OVERLAP = 16            # velocity samples inside the position span needed to judge


def noise_from_velocity(position, velocity, where: str) -> tuple[float, dict[float, float]]:
    """(σ in m, {σ: RMS velocity difference in m/s}) for position and velocity Series on one clock and frame."""
    from imu_emulator.numerics.derivatives import SampledSeries
    inside = (velocity.t > position.t[0]) & (velocity.t < position.t[-1])
    if inside.sum() < MIN_OVERLAP:
        raise DataError(f"{where}: the logged velocity has {int(inside.sum())} samples inside the position's span "
                        f"(need {MIN_OVERLAP}) to choose position_noise_m from")
    t, v = velocity.t[inside], velocity.values[inside]
    scores = {}
    for sigma in GRID_M:
        fit = SampledSeries(position.t, position.values, "smooth", 1, noise=sigma)
        scores[sigma] = float(np.sqrt(np.mean(np.sum((fit.evaluate(t, 1)[1] - v) ** 2, axis=1))))
    return min(scores, key=scores.get), scores
