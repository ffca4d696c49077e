"""With more than INLINE_IMUS IMUs, each IMU's stages are a function (compile time linear in the IMU count): every
IMU of a many-IMU scene gives exactly what the same IMU gives alone, where its lines sit in the kernel's loop
(the single-IMU form is the oracle for the per-IMU functions: independent code paths of the generator)."""
from __future__ import annotations


import numpy as np
import pytest

from imu_emulator import scene_from_dict
from imu_emulator.effects import EFFECTS, all_params
from imu_emulator.codegen.generate import INLINE_IMUS, generate_source
from imu_emulator.runtime.simulation import Simulation

from tests.effects.test_effects_mechanism import _imu_with, _sample_value  # noqa: E402

DETERMINISTIC = [name for name, effect in EFFECTS.items() if not effect.random]


def _scene(imus: list[dict]):
    # every deterministic effect includes the Earth's, which need the tangent point
    return scene_from_dict({"scene": {"rate_hz": 200, "duration_s": 2.0,
                                      "origin": {"lat_deg": 47.4, "lon_deg": 8.5, "height_m": 400.0}},
                            "trajectory": {"x": "3*cos(t)", "y": "2*sin(1.3*t)", "z": "0.2*t*t"},
                            "attitude": {"roll": "0.1*sin(t)", "pitch": "0.05*t", "yaw": "0.2*t"},
                            "imu": imus, "effects": {name: True for name in DETERMINISTIC}})


def _imu(i: int) -> dict:
    """IMU i with every deterministic effect's parameters, scaled differently for each IMU."""
    params = {p: _sample_value(p, 1.0 + 0.37 * i) for effect, p in all_params() if effect.name in DETERMINISTIC}
    imu = _imu_with(params)
    imu["name"] = f"imu{i}"
    return imu


def _compare_with_each_alone(n_imu: int, check: list[int]) -> None:
    imus = [_imu(i) for i in range(n_imu)]
    many = Simulation(_scene(imus), truth=True)
    source = generate_source(many.scene, True, True)
    assert all(f"def imu_{i}(" in source for i in range(n_imu))
    together = many.run()
    counts = many.counts()
    for i in check:
        alone_sim = Simulation(_scene([imus[i]]), truth=True)
        assert "def imu_0(" not in generate_source(alone_sim.scene, True, True)    # inline form
        alone = alone_sim.run()
        for name in ("accel", "gyro", "quat"):
            assert np.array_equal(getattr(together, name)[i], getattr(alone, name)[0]), (i, name)
        assert counts.get(f"imu{i}", {}) == alone_sim.counts().get(f"imu{i}", {})


def test_each_imu_of_many_equals_the_same_imu_alone():
    _compare_with_each_alone(INLINE_IMUS + 1, [0, 7, INLINE_IMUS])


def test_a_few_imus_stay_inline():
    imus = [_imu(i) for i in range(INLINE_IMUS)]
    assert "def imu_" not in generate_source(_scene(imus), True, True)


@pytest.mark.slow
def test_a_hundred_imus_compile_and_run():
    # issue 15: 100 IMUs did not compile in 400 s with the loop-body form
    _compare_with_each_alone(100, [0, 57, 99])
