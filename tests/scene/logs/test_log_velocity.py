"""position_noise_m = "velocity": the smoothing of a replayed log chosen from the log's own velocity.

Synthetic log with known motion (tools/smoothing_scan.py's track: a 5 m circle at 0.2 Hz and a 0.5 m weave at
0.5 Hz): positions with Gaussian noise of σ = 1 cm at 50 Hz, and a velocity as an estimator logs it, the exact
derivative plus its own independent noise (3 cm/s). The property: the acceleration error with the chosen
smoothing is within 2x of the error with the true σ stated (the issue's bound for `smooth` against the best
fixed smoothing), and 10x below spline5c's. Fixed seeds."""
import sys
from pathlib import Path

import numpy as np
import pytest

from imu_emulator import scene_from_dict
from imu_emulator.numerics.derivatives import SampledSeries
from imu_emulator.errors import SceneError
from imu_emulator.scene.logs import LogMotion, Series
from imu_emulator.scene.logs.velocity import noise_from_velocity
from tests.support.paths import TOOLS

sys.path.insert(0, str(TOOLS))
from smoothing_scan import W_CIRCLE, W_WEAVE, rms_error, track  # noqa: E402

SIGMA = 0.01


def velocity(t):
    return np.column_stack([-5 * W_CIRCLE * np.sin(W_CIRCLE * t), 5 * W_CIRCLE * np.cos(W_CIRCLE * t),
                            0.5 * W_WEAVE * np.cos(W_WEAVE * t)])


def synthetic_log(rate=50.0, seconds=20.0, with_velocity=True):
    t = np.arange(int(seconds * rate) + 1) / rate
    rng = np.random.default_rng(7)
    pos = track(t)[0] + rng.normal(0, SIGMA, (t.size, 3))
    vel = velocity(t) + rng.normal(0, 0.03, (t.size, 3))
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1))
    return LogMotion(source=Path("synthetic.ulg"), frame="NED", position=Series("vehicle_local_position", t, pos),
                     attitude=Series("vehicle_attitude", t, quat),
                     velocity=Series("vehicle_local_position", t, vel) if with_velocity else None)


def acceleration_error(log, method, noise=0.0):
    t_out = np.linspace(0, log.position.t[-1], 4001)
    fit = SampledSeries(log.position.t, log.position.values, method, 2, noise=noise)
    return rms_error(t_out, fit.evaluate(t_out, 2)[2], track(t_out)[1])


def test_smoothing_chosen_from_the_velocity_is_near_the_true_noises():
    log = synthetic_log()
    sigma, scores = noise_from_velocity(log.position, log.velocity, "synthetic")
    chosen = acceleration_error(log, "smooth", sigma)
    assert chosen <= 2 * acceleration_error(log, "smooth", SIGMA), (sigma, scores)
    assert chosen * 10 <= acceleration_error(log, "spline5c")


def test_scene_takes_the_noise_from_the_velocity(tmp_path, monkeypatch):
    from imu_emulator.scene import logs
    log = synthetic_log()
    monkeypatch.setattr(logs, "load_log", lambda *args, **kwargs: log)
    (tmp_path / "synthetic.ulg").write_bytes(b"")
    raw = {"scene": {"rate_hz": 50}, "imu": [{}], "attitude": {"attitude_noise_rad": 1e-3},
           "trajectory": {"file": str(tmp_path / "synthetic.ulg"), "derivative": "smooth",
                          "position_noise_m": "velocity"}}
    scene = scene_from_dict(raw)
    expected, _ = noise_from_velocity(log.position, log.velocity, "synthetic")
    assert scene.trajectory.noise == expected
    assert any("chosen from the logged velocity" in w for w in scene.warnings)
    raw["trajectory"]["derivative"] = "spline5c"
    with pytest.raises(SceneError, match=r"trajectory\.position_noise_m: \"velocity\" chooses the smoothing"):
        scene_from_dict(raw)
    monkeypatch.setattr(logs, "load_log", lambda *args, **kwargs: synthetic_log(with_velocity=False))
    raw["trajectory"]["derivative"] = "smooth"
    with pytest.raises(SceneError, match=r"synthetic\.ulg logs no velocity"):
        scene_from_dict(raw)
