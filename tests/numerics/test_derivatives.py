"""Derivatives of sampled series: MATLAB's gradient by hand, convergence orders, large coordinates, resampling,
and the errors a user gets for bad input."""
import numpy as np
import pytest

from imu_emulator.numerics.derivatives import (METHODS, SampledSeries, matlab_gradient, unwrap_angles,
                                      wrap_angles)
from imu_emulator.errors import DataError


def smooth(t, d):
    """f = sin(2πt) + 0.3 cos(6πt) and its d-th derivative, by hand: each one advances the phase by π/2."""
    return ((2 * np.pi) ** d * np.sin(2 * np.pi * t + d * np.pi / 2)
            + 0.3 * (6 * np.pi) ** d * np.cos(6 * np.pi * t + d * np.pi / 2))


def loop(t, d, offset=0.0):
    """The spec's small loop (x, y, z) = (0.8 cos 2πt, 0.8 sin 2πt, 0.3 cos 6πt), d-th derivative, (n, 3)."""
    w = 2 * np.pi
    shift = d * np.pi / 2
    out = np.column_stack([0.8 * w ** d * np.cos(w * t + shift),
                           0.8 * w ** d * np.sin(w * t + shift),
                           0.3 * (3 * w) ** d * np.cos(3 * w * t + shift)])
    return out + offset if d == 0 else out


# --- gradient is MATLAB's ---------------------------------------------------------------------------------

def test_gradient_hand_case_uniform():
    t = np.arange(5.0)
    y = np.array([1.0, 4.0, 9.0, 16.0, 25.0])
    # ends: 4-1 = 3 and 25-16 = 9; inside (9-1)/2, (16-4)/2, (25-9)/2
    first = [3.0, 4.0, 6.0, 8.0, 9.0]
    # gradient of the above: ends 4-3, 9-8; inside (6-3)/2, (8-4)/2, (9-6)/2 -- the true value is 2 throughout
    second = [1.0, 1.5, 2.0, 1.5, 1.0]
    out = SampledSeries(t, y, "gradient", 2).evaluate(t, 2)[:, :, 0]
    np.testing.assert_array_equal(out[0], y)
    np.testing.assert_array_equal(out[1], first)
    np.testing.assert_array_equal(out[2], second)


def test_gradient_hand_case_nonuniform_follows_matlab_not_numpy():
    t = np.array([0.0, 1.0, 3.0, 4.0, 7.0])
    y = t ** 2
    # MATLAB: ends (1-0)/1, (49-16)/3; inside (9-0)/3, (16-1)/3, (49-9)/4
    expected = [1.0, 3.0, 5.0, 10.0, 11.0]
    np.testing.assert_allclose(SampledSeries(t, y, "gradient", 1).evaluate(t, 1)[1, :, 0], expected,
                               rtol=1e-15)
    np.testing.assert_allclose(matlab_gradient(y, t), expected, rtol=1e-15)
    # numpy's non-uniform interior formula is exact for a parabola (2t); MATLAB's is not: a documented choice
    np.testing.assert_allclose(np.gradient(y, t, edge_order=1)[1:-1], [2.0, 6.0, 8.0])


def test_gradient_equals_numpy_on_uniform_grid():
    rng = np.random.default_rng(7)
    h = 0.01
    t = 3.0 + h * np.arange(40)
    y = rng.normal(size=(40, 3))
    out = SampledSeries(t, y, "gradient", 3).evaluate(t, 3)
    reference = y
    for d in range(1, 4):
        reference = np.gradient(reference, h, axis=0, edge_order=1)
        np.testing.assert_allclose(out[d], reference, rtol=1e-11, atol=1e-11 * np.abs(reference).max())


# --- convergence orders ------------------------------------------------------------------------------------

INTERIOR_ORDER = {           # expected slope of log(max error) vs log(h), derivative orders 0..3
    "gradient": [2, 2, 2, 2],
    "central4": [4, 4, 4, 4],
    "central6": [6, 6, 6, 6],
    "spline5": [6, 5, 4, 3],
    "spline3": [4, 3, 2, 1],
    "spline5c": [6, 5, 4, 3],
}
STEPS = 1.0 / np.array([100, 141, 200, 283])


def error_slopes(method, t_out_for):
    errors = []
    for h in STEPS:
        t = h * np.arange(round(1 / h) + 1)
        t_out = t_out_for(h)
        got = SampledSeries(t, smooth(t, 0), method, 3).evaluate(t_out, 3)[:, :, 0]
        errors.append([np.abs(got[d] - smooth(t_out, d)).max() for d in range(4)])
    errors = np.array(errors)
    return np.array([np.polyfit(np.log(STEPS), np.log(errors[:, d]), 1)[0] for d in range(4)])


# The interpolating methods; "smooth" trades fidelity to the samples for noise rejection and has its own
# tests (tests/numerics/test_smoothing.py).
INTERPOLATING = tuple(m for m in METHODS if m != "smooth")


@pytest.mark.parametrize("method", INTERPOLATING)
def test_interior_convergence_order(method):
    # off the grid, so that the interpolation between samples is part of what is measured
    slopes = error_slopes(method, lambda h: np.linspace(0.2, 0.8, 1201) + 0.1234 * h)
    np.testing.assert_allclose(slopes, INTERIOR_ORDER[method], atol=0.6)


@pytest.mark.parametrize("method", ["central4", "central6", "spline5", "spline3", "spline5c"])
def test_end_error_no_worse_in_order(method):
    slopes = error_slopes(method, lambda h: np.linspace(0.0, 1.0, 2001))
    assert np.all(slopes >= np.array(INTERIOR_ORDER[method]) - 0.6), slopes


def test_gradient_end_error_grows_with_each_derivative():
    # one-sided first differences at the ends (O(h)); every further application divides by h once more
    slopes = error_slopes("gradient", lambda h: np.linspace(0.0, 1.0, 2001))
    np.testing.assert_allclose(slopes, [2, 1, 0, -1], atol=0.6)


# --- what the kernel relies on ------------------------------------------------------------------------------

@pytest.mark.parametrize("method", INTERPOLATING)
def test_grid_times_reproduce_input_and_blocks_do_not_matter(method):
    t = 0.01 * np.arange(101)
    y = loop(t, 0, offset=np.array([10.0, -20.0, 5.0]))
    series = SampledSeries(t, y, method, 3)
    np.testing.assert_allclose(series.evaluate(t, 0)[0], y, rtol=0, atol=4 * np.spacing(20.0))
    t_out = np.linspace(0.0, 1.0, 997)
    whole = series.evaluate(t_out, 3)
    pieces = np.concatenate([series.evaluate(chunk, 3) for chunk in np.array_split(t_out, [1, 90, 91, 500])],
                            axis=1)
    np.testing.assert_array_equal(pieces, whole)


def test_finite_differences_return_grid_derivatives_at_grid_times():
    t = 0.01 * np.arange(101)
    y = loop(t, 0)
    out = SampledSeries(t, y, "gradient", 3).evaluate(t, 3)
    reference = y
    for d in range(1, 4):
        reference = matlab_gradient(reference, t)
        # equal up to the rounding of subtracting the first sample before differencing
        np.testing.assert_allclose(out[d], reference, rtol=0, atol=1e-13 * np.abs(reference).max())


def test_resampling_100hz_to_1khz_with_spline5():
    t = 0.01 * np.arange(501)
    series = SampledSeries(t, loop(t, 0), "spline5", 3)
    t_out = 0.001 * np.arange(5001)
    out = series.evaluate(t_out, 3)
    inner = (t_out >= 0.5) & (t_out <= 4.5)
    # relative errors measured: inside 1e-9, 5e-8, 2e-6, 5e-5; within two samples of the ends ~150x more
    for d, inside, anywhere in zip(range(4), [1e-8, 5e-7, 2e-5, 5e-4], [2e-6, 2e-4, 5e-3, 5e-2]):
        truth = loop(t_out, d)
        scale = np.abs(truth).max()
        assert np.abs(out[d] - truth)[inner].max() < inside * scale
        assert np.abs(out[d] - truth).max() < anywhere * scale
    np.testing.assert_allclose(out[0, ::10], loop(t, 0), rtol=0, atol=1e-15)


def test_spline5c_ends_as_accurate_as_the_interior():
    # not-a-knot spline5: ends ~150-500x the interior error; the clamped ends (first and second derivatives
    # from a degree-9 least-squares fit through 14 end samples) bring that to 4x at 100 Hz (this loop has a
    # 3 Hz harmonic: 33 samples per period) and below 2x at 200 Hz
    for rate, limit in ((100, 5.0), (200, 2.0)):
        t = np.arange(5 * rate + 1) / rate
        t_out = np.linspace(0.0, 5.0, 5001)
        inner = (t_out > 0.25) & (t_out < 4.75)
        ratios = {}
        for method in ("spline5", "spline5c"):
            out = SampledSeries(t, loop(t, 0, offset=np.array([3.0, -2.0, 1.0])), method, 3).evaluate(t_out, 3)
            ratios[method] = [np.abs(out[d] - loop(t_out, d)).max() / np.abs(out[d] - loop(t_out, d))[inner].max()
                              for d in (1, 2, 3)]
        assert max(ratios["spline5c"]) < limit, ratios
        assert min(ratios["spline5"]) > 20, ratios


def test_end_derivative_weights_are_finite_differences_when_points_equal_degree_plus_one():
    from imu_emulator.numerics.derivatives import end_derivative_weights, fd_weights
    x = 0.01 * np.arange(10)
    for d in (1, 2):
        np.testing.assert_allclose(end_derivative_weights(x, 9, d), fd_weights(x, d), rtol=1e-6)
    # least squares over more points is still exact for polynomials of the degree
    x = 0.01 * np.arange(14)
    y = 1.0 + 2.0 * x - 3.0 * x ** 2 + 5.0 * x ** 9
    assert abs(end_derivative_weights(x, 9, 1) @ y - 2.0) < 1e-9
    assert abs(end_derivative_weights(x, 9, 2) @ y + 6.0) < 1e-6


def test_large_coordinates_differentiate_like_the_origin_exactly_representable():
    # positions on a 2^-30 m lattice: adding 6.4e6 m (ulp 2^-30) is exact, so the data are the same track
    t = 0.005 * np.arange(1001)
    near = np.round(loop(t, 0) * 2.0 ** 30) / 2.0 ** 30
    far = near + 6.4e6
    assert np.array_equal(far - 6.4e6, near)
    t_out = np.linspace(0.0, 5.0, 2345)
    # not spline5c: the default takes values of 6.4e6 m as rounded to their ulp and smooths them (the rounding
    # rule, tests/numerics/test_smoothing.py); here the lattice makes that rounding exact, which the rule cannot know
    for method in (m for m in INTERPOLATING if m != "spline5c"):
        a = SampledSeries(t, near, method, 3).evaluate(t_out, 3)
        b = SampledSeries(t, far, method, 3).evaluate(t_out, 3)
        np.testing.assert_allclose(b[0], a[0] + 6.4e6, rtol=0, atol=2 * np.spacing(6.4e6))
        for d in range(1, 4):
            np.testing.assert_allclose(b[d], a[d], rtol=0, atol=1e-12 * np.abs(a[d]).max(), err_msg=method)


def test_large_coordinates_only_lose_the_input_rounding():
    # unrounded: the far track's samples carry up to half an ulp of 6.4e6 m; the derivatives may differ by
    # that amplified by the method's gain (~1/h^d), by nothing else.  Measured gains: <= 20 inside; at the
    # very ends the one-sided stencils gain more (central6's 9-point jerk stencil: sum |w| = 956 h^-3).
    h = 0.005
    t = h * np.arange(1001)
    t_out = np.linspace(0.0, 5.0, 2345)
    inner = (t_out > 0.2) & (t_out < 4.8)
    rounding = np.spacing(6.4e6) / 2
    for method in INTERPOLATING:
        a = SampledSeries(t, loop(t, 0), method, 3).evaluate(t_out, 3)
        b = SampledSeries(t, loop(t, 0, offset=6.4e6), method, 3).evaluate(t_out, 3)
        for d in range(1, 4):
            diff = np.abs(b[d] - a[d])
            assert diff[inner].max() < 50 * rounding / h ** d, (method, d)
            assert diff.max() < 1000 * rounding / h ** d, (method, d)


def test_ten_minutes_at_1khz_at_ecef_size_differentiate_like_the_origin():
    """The size of a long log (600 001 samples at 1 kHz, ECEF-sized coordinates) changes nothing: on a 2^-30 m
    lattice adding 6.4e6 m is exact, so both fits see the same track and agree as in the short case above. How
    long the fit takes is a figure of tools/bench_derivatives.py, not asserted here."""
    t = 1e-3 * np.arange(600_001)
    near = np.round(loop(t, 0) * 2.0 ** 30) / 2.0 ** 30
    far = near + 6.4e6
    assert np.array_equal(far - 6.4e6, near)
    t_out = t[1000:11000] + 2e-4
    # smooth and spline5c: see the short case above and tools/smoothing_scan.py --timing
    for method in (m for m in INTERPOLATING if m != "spline5c"):
        a = SampledSeries(t, near, method, 3).evaluate(t_out, 3)
        b = SampledSeries(t, far, method, 3).evaluate(t_out, 3)
        np.testing.assert_allclose(b[0], a[0] + 6.4e6, rtol=0, atol=2 * np.spacing(6.4e6), err_msg=method)
        for d in range(1, 4):
            np.testing.assert_allclose(b[d], a[d], rtol=0, atol=1e-12 * np.abs(a[d]).max(), err_msg=method)


# --- angles ------------------------------------------------------------------------------------------------

def test_unwrapped_yaw_has_the_true_rate_and_wraps_back():
    t = 0.01 * np.arange(300)
    yaw = 2.5 + 1.7 * t                              # crosses +pi and 3pi
    wrapped = wrap_angles(yaw)
    assert np.all((wrapped > -np.pi) & (wrapped <= np.pi))
    series = SampledSeries(t, unwrap_angles(wrapped), "central4", 2)
    out = series.evaluate(t, 2)[:, :, 0]
    np.testing.assert_allclose(out[1], 1.7, rtol=1e-9)
    np.testing.assert_allclose(wrap_angles(out[0]), wrapped, atol=1e-12)
    np.testing.assert_array_equal(wrap_angles([-np.pi, np.pi, 0.0]), [np.pi, np.pi, 0.0])


# --- bad input ---------------------------------------------------------------------------------------------

def bad(match, t, values, method="spline5", max_order=3, **kw):
    with pytest.raises(DataError, match=match):
        SampledSeries(t, values, method, max_order, name="track", **kw)


def test_non_finite_value_names_column_and_row():
    t = np.arange(10.0)
    y = np.zeros((10, 3))
    y[6, 1] = np.nan
    bad(r"^track: sample 6, column 'y': value nan is not finite$", t, y, columns=("x", "y", "z"))
    y[6, 1] = np.inf
    bad(r"^track: row 8, column 'column 1': value inf is not finite$", t, y, row_label=lambda i: f"row {i + 2}")


def test_non_finite_time_names_row():
    t = np.arange(10.0)
    t[3] = np.nan
    bad(r"^track: sample 3: time stamp nan is not finite$", t, np.zeros(10))


@pytest.mark.parametrize("previous", [0.35, 0.4])
def test_time_not_increasing_names_row(previous):
    t = np.arange(10.0) * 0.05
    t[7] = previous
    t[8] = 0.35
    bad(rf"^track: sample 8: time stamp 0.35 not after previous {previous}$", t, np.zeros(10))


@pytest.mark.parametrize("method, max_order, minimum", [
    ("gradient", 3, 3), ("central4", 1, 5), ("central4", 3, 7), ("central6", 3, 9), ("central6", 2, 8),
    ("spline5", 3, 6), ("spline3", 3, 4), ("spline5c", 3, 14), ("spline5c", 1, 14)])
def test_too_few_samples_names_method_and_minimum(method, max_order, minimum):
    t = np.arange(float(minimum - 1))
    bad(rf"^track: method '{method}' needs at least {minimum} samples for derivatives up to order "
        rf"{max_order}, got {minimum - 1}$", t, np.zeros(minimum - 1), method, max_order)
    SampledSeries(np.arange(float(minimum)), np.zeros(minimum), method, max_order)


@pytest.mark.parametrize("method", ["central4", "central6"])
def test_central_differences_refuse_irregular_time(method):
    t = 0.01 * np.arange(50)
    t[20:] += 0.002
    bad(rf"^track: method '{method}' needs uniformly spaced time stamps; sample 20 is 0\.012\d* s after "
        r"the previous one, the usual step is 0\.01\d* s \(use spline5 or gradient for irregular time "
        r"stamps\)$", t, np.zeros(50), method)
    for tolerated in ("gradient", "spline5", "spline3"):
        SampledSeries(t, np.zeros(50), tolerated, 3)


def test_central_differences_accept_time_stamps_with_rounding_only():
    t = 1e6 + 0.001 * np.arange(1000)        # float steps vary by ~1e-10 s around 1e6 s
    SampledSeries(t, np.zeros(1000), "central6", 3)


def test_output_time_outside_span():
    t = 0.01 * np.arange(11)
    series = SampledSeries(t, np.zeros(11), "spline5", 3, name="track")
    with pytest.raises(DataError, match=r"^track: output time 0\.11 s is outside the input time span "
                                        r"\[0\.0, 0\.1\] s$"):
        series.evaluate([0.05, 0.11], 1)
    with pytest.raises(DataError, match=r"output time nan"):
        series.evaluate([np.nan], 1)
    series.evaluate([-1e-12, 0.1 + 1e-12], 3)    # rounding of t0 + k*dt is not "outside"


def test_unknown_method_and_shape_mismatch():
    bad(r"^track: unknown derivative method 'spline7' \(known: gradient, central4, central6, spline5, "
        r"spline3, spline5c, smooth\)$", np.arange(10.0), np.zeros(10), "spline7")
    bad(r"^track: time stamps \(10,\) and values \(9, 3\) do not match", np.arange(10.0), np.zeros((9, 3)))


def test_order_beyond_fit_is_a_programming_error():
    series = SampledSeries(np.arange(10.0), np.zeros(10), "spline5", 2)
    with pytest.raises(ValueError):
        series.evaluate([1.0], 3)
