"""Angular rate from sampled attitude (imu_emulator.motion.attitude_rates) against the independent sympy oracle."""
import numpy as np
import pytest
import sympy as sp

from imu_emulator.motion.attitude_rates import (dcm_rate, euler_matrix_e, euler_rate, increment_rate,
                                         increment_rate_from_quaternions, quat_log)
from imu_emulator.numerics.derivatives import wrap_angles
from imu_emulator.errors import DataError
from imu_emulator.geo.rotations import euler_to_matrix, euler_to_quat
from tests.support.reference import imu_functions, t as T

# the original tool's example 4: large roll and pitch together, where omega_N and omega_B differ a lot
EULER = [0.8 * sp.cos(2 * sp.pi * T), 0.8 * sp.sin(2 * sp.pi * T), 0.3 * sp.cos(2 * sp.pi * T)]
_oracle = imu_functions([0, 0, 0], EULER)
_angles = sp.lambdify(T, EULER, "numpy")


def sampled(rate, duration=2.0):
    t = np.arange(int(duration * rate) + 1) / rate
    return t, np.column_stack(_angles(t)), _oracle(t)[1]


def max_error(got, truth):
    return np.linalg.norm(got - truth, axis=1).max()


def test_euler_rate_formula_with_default_method():
    t, e, truth = sampled(200)
    assert max_error(euler_rate(t, e), truth) < 1e-8
    # resampled output times as well
    t_out = np.linspace(0.0, 2.0, 777)
    assert max_error(euler_rate(t, e, t_out=t_out), _oracle(t_out)[1]) < 1e-8


def test_dcm_rate_is_the_body_rate_not_the_navigation_rate():
    t, e, truth = sampled(1000)
    got = dcm_rate(t, e, "spline5c")
    assert max_error(got, truth) < 1e-8
    omega_n = np.einsum("nij,nj->ni", euler_to_matrix(e), truth)
    assert max_error(got, omega_n) > 0.5        # the original's Omega_N is a different vector here


def test_dcm_rate_with_gradient_is_second_order_inside_first_order_at_the_ends():
    errors = []
    for rate in (200, 400, 800):
        t, e, truth = sampled(rate)
        err = np.linalg.norm(dcm_rate(t, e) - truth, axis=1)
        errors.append((err[5:-5].max(), max(err[0], err[-1])))
    errors = np.array(errors)
    inner = np.log2(errors[:-1, 0] / errors[1:, 0])
    ends = np.log2(errors[:-1, 1] / errors[1:, 1])
    np.testing.assert_allclose(inner, 2.0, atol=0.2)
    np.testing.assert_allclose(ends, 1.0, atol=0.2)


@pytest.mark.parametrize("order", [2, 4, 6])
def test_increment_rate_converges_at_its_order_everywhere(order):
    errors = []
    for rate in (200, 400, 800):
        t, e, truth = sampled(rate)
        errors.append(max_error(increment_rate(t, e, order), truth))
    slopes = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(slopes > order - 0.4), slopes


def test_increment_rate_on_irregular_time_stamps():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.004, 0.006, 400))
    e = np.column_stack(_angles(t))
    assert max_error(increment_rate(t, e, 6), _oracle(t)[1]) < 1e-5


def test_all_methods_ignore_yaw_wrapping_and_quaternion_sign():
    t = np.arange(401) / 200
    e = np.column_stack([0.2 * np.sin(t), 0.1 * np.cos(t), 3.0 + 2.0 * t])     # yaw crosses +pi
    roll, pitch, yaw = sp.Float(0.2) * sp.sin(T), sp.Float(0.1) * sp.cos(T), 3 + 2 * T
    truth = imu_functions([0, 0, 0], [roll, pitch, yaw])(t)[1]
    wrapped = e.copy()
    wrapped[:, 2] = wrap_angles(e[:, 2])
    assert max_error(euler_rate(t, wrapped), truth) < 1e-9
    assert max_error(dcm_rate(t, wrapped, "spline5c"), truth) < 1e-9
    q = euler_to_quat(wrapped)
    q[::3] *= -1.0                                   # the same attitudes, other sign
    assert max_error(increment_rate_from_quaternions(t, q, 6), truth) < 1e-9


def test_euler_matrix_maps_angle_rates_to_body_rates():
    e = np.array([0.3, -0.4, 2.0])
    E = euler_matrix_e(e)
    rates = np.array([0.5, -1.0, 2.0])
    expected = [rates[0] - np.sin(e[1]) * rates[2],
                np.cos(e[0]) * rates[1] + np.sin(e[0]) * np.cos(e[1]) * rates[2],
                -np.sin(e[0]) * rates[1] + np.cos(e[0]) * np.cos(e[1]) * rates[2]]
    np.testing.assert_allclose(E @ rates, expected, rtol=1e-15)


def test_quat_log_small_large_and_rounded_past_one():
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    for angle in (0.0, 1e-12, 1e-6, 1.0, np.pi - 1e-9):
        q = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])
        np.testing.assert_allclose(quat_log(q), angle * axis, rtol=1e-12, atol=1e-20)
        np.testing.assert_allclose(quat_log(-q), angle * axis, rtol=1e-12, atol=1e-20)
    assert np.array_equal(quat_log(np.array([1.0 + 2.2e-16, 0.0, 0.0, 0.0])), [0.0, 0.0, 0.0])


def test_bad_input_is_a_clear_error():
    t = np.arange(5) / 100.0
    with pytest.raises(DataError, match="order 6 needs at least 7 samples, got 5"):
        increment_rate(t, np.zeros((5, 3)), 6)
    with pytest.raises(DataError, match="do not match"):
        euler_rate(t, np.zeros((4, 3)))
    with pytest.raises(DataError, match="needs at least 14 samples"):
        euler_rate(t, np.zeros((5, 3)))
    bad_t = np.arange(10) / 100.0
    bad_t[4] = bad_t[3]
    with pytest.raises(DataError, match="sample 4: time stamp .* not after previous"):
        increment_rate(bad_t, np.zeros((10, 3)), 2)
    with pytest.raises(ValueError):
        increment_rate(np.arange(10.0), np.zeros((10, 3)), 3)
