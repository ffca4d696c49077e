"""Presets: `model = "NAME"` loads a datasheet's figures, keys beside it override; each preset's generated Allan
deviation (allantools as the oracle) shows its datasheet N and B.

The datasheet lines: white noise N/sqrt(tau) and the flicker floor 0.664 B, summed in quadrature
(independent processes add their Allan variances): sigma(tau)^2 = N^2/tau + (0.664 B)^2.
Tolerances (specs/sensor-errors.md, issue 9 §5): sigma(1 s) within 3 %, the floor region within 15 %.
Why they hold for one 2 h record (fast test): the overlapping-ADEV 1-sigma relative error is 0.68 % at 1 s
(white), so 3 % is > 4 sigma; at tau = 10 .. 30 s it is at most 7.8 % * sqrt(30 / 100) = 4.3 % (flicker, the
worst case, scaling as sqrt(tau / T)), and the realization of the floor is within -5.4 % / +0.9 % of
0.664 B: 15 % leaves > 2 sigma beyond that bias at 30 s and > 3.5 sigma at 10 s. The slow test averages 3
seeds (sigma / sqrt(3)) and covers tau = 10 .. 100 s as the issue states, at 100 Hz and 1 kHz.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_emulator.scene import presets
from imu_emulator.commands.models import cmd_models
from imu_emulator.errors import SceneError
from imu_emulator.runtime.simulation import Simulation
from tests.support.scenes import scene

allantools = pytest.importorskip("allantools")

FLOOR = 0.664    # Allan floor of flicker noise per unit of B (IEEE 952)


def preset_scene(models, rate_hz, duration_s, seed=1, effects=("noise", "bias_instability"), x_only=False, **extra):
    """x_only: the y and z axes lose their bias instability (the x axes keep the preset's), so the kernel has a
    third of the Gauss-Markov poles and compiles in a third of the time; what is checked is the x axis."""
    imus = []
    for i, name in enumerate(models):
        imu = {"name": f"imu{i}", "model": name, **extra}
        if x_only:
            for triad in ("gyro", "accel"):
                b = presets.describe(name)[triad].get("bias_instability")
                if b:
                    imu.setdefault(triad, {})["bias_instability"] = [b, 0, 0]
        imus.append(imu)
    return scene(rate_hz=rate_hz, duration_s=duration_s, seed=seed, imus=imus, effects=effects)


def expected(n: float, b: float, taus) -> np.ndarray:
    return np.sqrt(n ** 2 / np.asarray(taus) + (FLOOR * b) ** 2)


def allan(samples: np.ndarray, rate_hz: float, taus) -> np.ndarray:
    taus_out, adev, _, _ = allantools.oadev(samples, rate=rate_hz, data_type="freq", taus=np.asarray(taus, float))
    assert np.allclose(taus_out, taus)
    return adev


def check_presets(rate_hz, seeds, floor_taus, x_only=False):
    names = presets.names()
    sums = {}
    for seed in seeds:
        out = Simulation(preset_scene(names, rate_hz, 7200.0, seed=seed, x_only=x_only), attitude=False).run()
        for m, name in enumerate(names):
            for triad, data in (("gyro", out.gyro), ("accel", out.accel)):
                adev = allan(data[m, :, 0], rate_hz, [1.0, *floor_taus])
                sums[name, triad] = sums.get((name, triad), 0.0) + adev / len(seeds)
    for (name, triad), adev in sums.items():
        n, b = presets.datasheet_lines(name, triad)
        want = expected(n, b, [1.0, *floor_taus])
        assert abs(adev[0] / want[0] - 1) < 0.03, (name, triad, "tau = 1 s", adev[0], want[0])
        ratio = adev[1:] / want[1:]
        assert np.all(np.abs(ratio - 1) < 0.15), (name, triad, dict(zip(floor_taus, ratio)))


def test_each_presets_allan_curve_shows_its_datasheet_n_and_b():
    check_presets(100.0, seeds=(1,), floor_taus=(10.0, 20.0, 30.0), x_only=True)


@pytest.mark.slow
@pytest.mark.parametrize("rate_hz", [100.0, 1000.0])
def test_each_presets_allan_curve_over_the_floor_band_averaged_over_seeds(rate_hz):
    check_presets(rate_hz, seeds=(1, 2, 3), floor_taus=(10.0, 20.0, 50.0, 100.0))


def test_keys_beside_the_model_override_it_and_presets_do_not_warn():
    base = preset_scene(["xsens-mti-3"], 100, 1.0, effects=("noise",))
    assert base.warnings == ()      # bias_instability, range are in the preset but off: a datasheet, no request
    values = base.imus[0].values
    assert values["imu.gyro.noise_density"] == pytest.approx((math.radians(0.007),) * 3)
    assert values["imu.accel.range"] == pytest.approx((16 * 9.80665,) * 3)
    over = preset_scene(["xsens-mti-3"], 100, 1.0, effects=("noise",), gyro={"arw": "0.6 deg/sqrt(h)"})
    assert over.imus[0].values["imu.gyro.noise_density"] == pytest.approx((math.radians(0.01),) * 3)
    assert over.imus[0].values["imu.accel.noise_density"] == values["imu.accel.noise_density"]


@pytest.mark.parametrize("name,triad", [(n, t) for n in presets.names() for t in ("gyro", "accel")
                                         if "resolution" in presets.describe(n)[t]])
def test_preset_resolution_is_one_count_of_a_16_bit_word_at_full_scale(name, triad):
    """The vendors' drivers read these parts' 16-bit two's-complement words as full scale / 2**15 per count
    (Bosch BMI08x Sensor API lsb_to_dps / lsb_to_mps2, PX4's ICM42688P driver), so one LSB is range / 32768
    exactly; a datasheet's rounded sensitivity (16.4 LSB/(deg/s) for 16.384) would be off by 0.1 %."""
    from imu_emulator.scene.units import to_unit
    table = presets.describe(name)[triad]
    unit = "rad/s" if triad == "gyro" else "m/s^2"
    lsb, full_scale = to_unit(table["resolution"], unit, name), to_unit(table["range"], unit, name)
    assert lsb == pytest.approx(full_scale / 2 ** 15, rel=1e-12)


def test_unknown_model_is_an_error_naming_the_key():
    with pytest.raises(SceneError, match=r"imu\[0\]\.model: unknown model 'mpu-6050' \(known: .*xsens-mti-3"):
        preset_scene(["mpu-6050"], 100, 1.0)


def test_models_lists_every_preset_with_its_figures(capsys):
    class Args:
        sources = True
    assert cmd_models(Args()) == 0
    text = capsys.readouterr().out
    assert len(presets.names()) >= 4
    for name in presets.names():
        info = presets.describe(name)
        assert name in text and info["part"] in text and info["source"] in text
        assert "rev" in info["source"].lower() or "revision" in info["source"].lower()
        assert str(info["gyro"].get("noise_density", info["gyro"].get("arw"))) in text
