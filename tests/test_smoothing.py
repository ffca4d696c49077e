"""derivative = "smooth": a quintic smoothing spline whose smoothing condition follows the stated noise.

Property (issue 14): on a track with added noise of known sigma, the acceleration error is at least 10x below
spline5c's and within 2x of the best fixed smoothing a scan over s = c n sigma^2 finds. The scan and the track
are tools/smoothing_scan.py's (which prints the full table); fixed seeds. Measured ratios smooth/best over
10/50/100 Hz and 1 mm/1 cm: 1.05-1.6; the 2x bound is the issue's."""
import sys
from pathlib import Path

import numpy as np
import pytest

from imu_emulator import scene_from_dict
from imu_emulator.derivatives import SampledSeries
from imu_emulator.errors import SceneError

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
from smoothing_scan import ecef_case, noisy_case  # noqa: E402


@pytest.mark.parametrize("rate, sigma", [(50, 1e-2), (100, 1e-3)])
def test_noise_derived_smoothing_beats_interpolation_and_nears_the_best_scan(rate, sigma):
    out, scan = noisy_case(rate, sigma, seconds=20.0)
    smooth = out["smooth"][0]
    assert smooth * 10 <= out["spline5c"][0]
    assert smooth <= 2 * min(scan.values()), (smooth, scan)


def test_rounding_of_ecef_coordinates_is_smoothed_without_stated_noise():
    # 1 kHz circle at 6.4e6 m: spline5c amplifies the 2.7e-10 m rounding to 3.4e-3 m/s^2; smooth takes the
    # rounding as the noise and measures 3.3e-5 (the origin's 6e-8 is NOT reached: see the README)
    res = ecef_case(6.4e6)
    assert res["smooth"] * 50 < res["spline5c"]


def test_noise_free_columns_are_interpolated():
    t = 0.01 * np.arange(201)
    y = np.column_stack([np.sin(t), np.cos(2 * t)])
    a = SampledSeries(t, y, "smooth", 3).evaluate(t, 0)[0]
    np.testing.assert_allclose(a, y, rtol=0, atol=1e-15)


def test_smooth_needs_the_noise_and_refuses_negative_noise(tmp_path):
    path = tmp_path / "track.csv"
    path.write_text("t,x,y,z\n" + "\n".join(f"{i / 10},{i},0,0" for i in range(20)) + "\n")
    base = {"scene": {"rate_hz": 10}, "imu": [{}]}
    with pytest.raises(SceneError, match=r"trajectory\.position_noise_m: derivative 'smooth' needs the data's noise"):
        scene_from_dict({**base, "trajectory": {"file": str(path), "derivative": "smooth"}})
    with pytest.raises(SceneError, match=r"trajectory\.position_noise_m: must be >= 0"):
        scene_from_dict({**base, "trajectory": {"file": str(path), "derivative": "smooth", "position_noise_m": -1}})
    scene = scene_from_dict({**base, "trajectory": {"file": str(path), "derivative": "smooth",
                                                    "position_noise_m": 0.01}})
    assert scene.trajectory.noise == 0.01


def test_noise_with_another_method_is_ignored_with_a_warning(tmp_path):
    path = tmp_path / "track.csv"
    path.write_text("t,x,y,z\n" + "\n".join(f"{i / 10},{i},0,0" for i in range(20)) + "\n")
    scene = scene_from_dict({"scene": {"rate_hz": 10}, "imu": [{}],
                             "trajectory": {"file": str(path), "position_noise_m": 0.01}})
    assert scene.warnings == ("trajectory.position_noise_m is ignored: only derivative 'smooth' uses it "
                              "(this one is 'spline5c')",)
