"""Derivatives of sampled motion: position and attitude given on a time vector, evaluated at output times.

A `SampledSeries` is fitted once and then asked, block by block, for the value and its derivatives at the
kernel's output times (which need not be input times, nor at the input rate).  Position needs derivatives
up to the third (tangent attitude turns acceleration into angular rate and jerk into angular acceleration),
attitude angles up to the second.

Methods (`METHODS`), with the error orders measured by tests/numerics/test_derivatives.py on a smooth signal,
uniform input step h, d = derivative order:

=========  ===========================================================  ==================================
method     how                                                          max error, interior / at the ends
=========  ===========================================================  ==================================
gradient   MATLAB's `gradient`, applied d times (as the original tool    O(h^2) / d=1: O(h), d=2: O(1),
           did); values between samples by linear interpolation.         d=3: O(1/h) -- grows as h shrinks
central4   4th-order finite differences on a uniform grid: central       O(h^4) / O(h^4)
           stencils inside, one-sided stencils of the same order near
           the ends, a direct stencil for each d; cubic (4-point)
           Lagrange interpolation between samples.
central6   as central4 with 6th-order stencils and quintic (6-point)     O(h^6) / O(h^6)
           Lagrange interpolation.
spline5    quintic interpolating spline, not-a-knot ends.                O(h^(6-d)) / O(h^(6-d))
spline3    cubic interpolating spline, not-a-knot ends; the jerk is      O(h^(4-d)) / O(h^(4-d))
           piecewise constant and jumps at every sample.
=========  ===========================================================  ==================================

Measured slopes of log(max error) vs log(h) for d = 0..3, h = 1/100 .. 1/283 s on sin 2πt + 0.3 cos 6πt:
gradient 2.0 2.0 2.0 2.0 inside, 2.0 1.0 0.0 -1.0 over the whole span; central4 4.0 4.0 4.0 4.0 (whole span
>= 3.9); central6 6.0 6.0 6.0 6.0 (whole span >= 5.8); spline5 6.0 5.0 4.0 3.0; spline3 4.0 3.0 2.0 1.0.
The error constants are larger near the ends (spline5 jerk ~150x, central6 jerk ~35x the interior error),
and so is the gain on noise in the input: central6's one-sided 9-point jerk stencil at the first and last
sample has sum |w| = 956/h^3, its central stencil inside 7.5/h^3.

Choices worth knowing:

- `gradient` is MATLAB's function exactly, also on non-uniform time: interior (y[i+1]-y[i-1])/(t[i+1]-t[i-1]),
  one-sided first differences at the two ends.  On a uniform grid that equals numpy.gradient(edge_order=1);
  on a non-uniform grid numpy uses a different (second-order) interior formula, MATLAB's is first order.
  We follow MATLAB so that results match the original tool's.  Repeating it multiplies the end error by 1/h
  per derivative order; the first and last few samples of acceleration and jerk are not to be trusted.
- Finite-difference derivatives are computed on the input grid; between grid points each derivative array
  is interpolated by a local Lagrange polynomial through the nearest p samples (p = the method's order), so
  interpolation costs no order and grid times return the grid values exactly (the node's weight is exactly
  one, the others exactly zero).
- central4/central6 assume a uniform grid and refuse a non-uniform one (DataError naming the first
  irregular sample) rather than silently resampling: use spline5 or gradient for irregular time stamps.
  Spacing counts as uniform when every step is within 1e-6*h (plus a few ulps of |t|, the float
  resolution of the time stamps themselves) of the median step; the differences then use the mean step h.
- Spline boundary conditions are not-a-knot: the first two (last two) spans share one polynomial.  This
  assumes nothing about the motion at the ends; "natural" conditions would force zero high derivatives
  (zero jerk for spline5) at both ends and cost accuracy there.
- Large coordinates (ECEF, ~6.4e6 m): the first sample is subtracted before fitting or differencing and
  added back to the values only, so no precision is lost here. The input values themselves carry the
  rounding of their magnitude (2.7e-10 m at 6.4e6 m), which interpolation amplifies; spline5c (the default)
  and smooth without stated noise therefore apply the rounding rule (imu_emulator/numerics/smoothing.py).
  Likewise time is measured from the first time stamp.
- Output times may lie up to 1e-6 of a mean step outside the input span (t0 + k*dt rounding); further out
  is a DataError -- there is no extrapolation.

Angles: differentiate `unwrap_angles(angles)`, never wrapped angles (a jump of 2*pi is a huge false rate);
`wrap_angles` brings yaw back to (-pi, pi] for output.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.interpolate import make_interp_spline

from imu_emulator.errors import DataError

METHODS: dict[str, str] = {
    "gradient": "MATLAB's gradient applied repeatedly (2nd order inside, 1st order at the ends), as the original",
    "central4": "4th-order central differences, same-order one-sided at the ends; uniform time steps only",
    "central6": "6th-order central differences, same-order one-sided at the ends; uniform time steps only",
    "spline5": "quintic interpolating spline (not-a-knot): smooth jerk, error O(h^(6-d)) for derivative d",
    "spline3": "cubic interpolating spline (not-a-knot), as most simulators: jerk piecewise constant",
    "spline5c": "quintic interpolating spline clamped at the ends: first and second derivatives there from a "
                "degree-9 least-squares polynomial through the 14 end samples; ends about as accurate as inside; "
                "where the rounding of large coordinates dominates, a least-squares spline (rounding rule)",
    "smooth": "quintic smoothing spline for noisy data (logs): residual sum of squares = n * sigma^2 of the stated "
              "noise (position_noise_m, attitude_noise_rad), plus the float rounding of the data's magnitude",
}

# Relative tolerance on the step for central4/6 (see module docstring) and on output times past the ends.
_UNIFORM_RTOL = 1e-6
_SPAN_RTOL = 1e-6


@dataclass(frozen=True)
class _MethodSpec:
    kind: str       # "matlab", "central" or "spline"
    order: int      # accuracy order p of the differences / degree k of the spline
    end_fit: tuple[int, int] | None = None   # spline clamped with d=1,2 from a (degree, points) end fit

    def min_samples(self, max_order: int) -> int:
        if self.kind == "matlab":
            return 3                            # at least one central difference
        if self.kind == "central":
            return self.order + max_order       # the one-sided stencil for the highest derivative
        if self.end_fit is not None:
            return self.end_fit[1]              # the end fit's points
        return self.order + 1                   # one polynomial piece of degree k


_SPECS = {
    "gradient": _MethodSpec("matlab", 2),
    "central4": _MethodSpec("central", 4),
    "central6": _MethodSpec("central", 6),
    "spline5": _MethodSpec("spline", 5),
    "spline3": _MethodSpec("spline", 3),
    "spline5c": _MethodSpec("spline", 5, end_fit=(9, 14)),
    "smooth": _MethodSpec("smooth", 5),
}
assert _SPECS.keys() == METHODS.keys()


def min_samples(method: str, max_order: int) -> int:
    """Fewest samples `method` needs for derivatives up to `max_order` (checked before any fit)."""
    return _SPECS[method].min_samples(max_order)


def unwrap_angles(angles: np.ndarray) -> np.ndarray:
    """Remove 2*pi jumps along time (axis 0), so that the angles can be differentiated."""
    return np.unwrap(np.asarray(angles, dtype=float), axis=0)


def wrap_angles(angles: np.ndarray) -> np.ndarray:
    """Map angles to (-pi, pi]; -pi itself becomes +pi."""
    return np.pi - np.mod(np.pi - np.asarray(angles, dtype=float), 2.0 * np.pi)


def matlab_gradient(values: np.ndarray, t: np.ndarray) -> np.ndarray:
    """MATLAB's gradient(values, t) along axis 0, including its interior formula on non-uniform t."""
    y = np.asarray(values, dtype=float)
    t = np.asarray(t, dtype=float)
    shape = (-1,) + (1,) * (y.ndim - 1)
    g = np.empty_like(y)
    g[0] = (y[1] - y[0]) / (t[1] - t[0])
    g[-1] = (y[-1] - y[-2]) / (t[-1] - t[-2])
    g[1:-1] = (y[2:] - y[:-2]) / (t[2:] - t[:-2]).reshape(shape)
    return g


def fd_weights(offsets: np.ndarray, order: int) -> np.ndarray:
    """Weights w with sum_j w_j f(x_j) ~ f^(order)(0) for nodes x_j = offsets (Fornberg 1988).

    Exact for polynomials of degree < len(offsets); stable for the small stencils used here.
    """
    x = np.asarray(offsets, dtype=float)
    c = np.zeros((x.size, order + 1))
    c[0, 0] = 1.0
    c1 = 1.0
    c4 = x[0]
    for i in range(1, x.size):
        mn = min(i, order)
        c2 = 1.0
        c5 = c4
        c4 = x[i]
        for j in range(i):
            c3 = x[i] - x[j]
            c2 *= c3
            if j == i - 1:
                for k in range(mn, 0, -1):
                    c[i, k] = c1 * (k * c[i - 1, k - 1] - c5 * c[i - 1, k]) / c2
                c[i, 0] = -c1 * c5 * c[i - 1, 0] / c2
            for k in range(mn, 0, -1):
                c[j, k] = (c4 * c[j, k] - k * c[j, k - 1]) / c3
            c[j, 0] = c4 * c[j, 0] / c3
        c1 = c2
    return c[:, order]


def _central_derivative(y: np.ndarray, h: float, d: int, p: int) -> np.ndarray:
    """d-th derivative of uniformly sampled y (axis 0) with accuracy O(h^p) at every sample.

    A direct stencil per derivative order rather than a first-derivative stencil applied d times: the
    repeated one-sided end stencils would lose an order per application.
    """
    n = y.shape[0]
    half = (d + 1) // 2 + p // 2 - 1    # the central stencil has 2*half+1 points
    scale = h ** -d
    w = fd_weights(np.arange(-half, half + 1), d) * scale
    out = np.empty_like(y)
    inner = n - 2 * half
    acc = w[0] * y[0:inner]
    for j in range(1, 2 * half + 1):
        acc = acc + w[j] * y[j:j + inner]
    out[half:n - half] = acc
    width = d + p                       # one-sided stencil of accuracy p
    for i in (*range(half), *range(n - half, n)):
        s = min(max(i - width // 2, 0), n - width)
        out[i] = (fd_weights(np.arange(s, s + width) - i, d) * scale) @ y[s:s + width]
    return out


def _lagrange_weights(tau: np.ndarray, tau_out: np.ndarray, npts: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices (N, npts) of the nearest npts samples around each output time and their Lagrange weights."""
    n = tau.size
    i = np.clip(np.searchsorted(tau, tau_out, side="right") - 1, 0, n - 2)
    start = np.clip(i - (npts // 2 - 1), 0, n - npts)
    idx = start[:, None] + np.arange(npts)
    nodes = tau[idx]
    dt = tau_out[:, None] - nodes
    w = np.ones_like(nodes)
    for j in range(npts):
        for k in range(npts):
            if k != j:
                w[:, j] *= dt[:, k] / (nodes[:, j] - nodes[:, k])
    return idx, w


class _GridFit:
    """Derivatives precomputed on the input grid, interpolated to output times."""

    def __init__(self, tau: np.ndarray, y: np.ndarray, spec: _MethodSpec, max_order: int, h: float):
        self.tau = tau
        self.npts = spec.order
        self.arrays = [y]
        for d in range(1, max_order + 1):
            if spec.kind == "matlab":
                self.arrays.append(matlab_gradient(self.arrays[-1], tau))
            else:
                self.arrays.append(_central_derivative(y, h, d, spec.order))

    def evaluate(self, tau_out: np.ndarray, order: int) -> np.ndarray:
        idx, w = _lagrange_weights(self.tau, tau_out, self.npts)
        return np.stack([np.einsum("nj,njm->nm", w, a[idx]) for a in self.arrays[:order + 1]])


def end_derivative_weights(offsets: np.ndarray, degree: int, d: int) -> np.ndarray:
    """Weights w with sum_j w_j f(x_j) ~ f^(d)(0): derivative at 0 of the least-squares polynomial of `degree`
    through the nodes x_j = offsets (len(offsets) >= degree + 1; equal: Fornberg's finite differences).

    Legendre basis on the nodes scaled to [-1, 1], so the fit stays well conditioned at degree 11.
    """
    x = np.asarray(offsets, dtype=float)
    scale = float(np.abs(x).max())
    basis = np.polynomial.legendre.legvander(x / scale, degree)
    at_zero = np.array([np.polynomial.legendre.legval(0.0, np.polynomial.legendre.legder(np.eye(degree + 1)[j], d))
                        for j in range(degree + 1)])
    return (at_zero @ np.linalg.pinv(basis)) / scale ** d


def _end_derivatives(x: np.ndarray, y: np.ndarray, degree: int) -> list[tuple[int, np.ndarray]]:
    """First and second derivatives at offset 0 of the end fit through (x, y), y relative to the end sample.

    The chord through the window's two outer samples is taken out first and its slope added back: the
    pinv weights annihilate constants and slopes only to ~1e-12 of their gain (w2 @ x = -5.9e-8 instead
    of 0 at h = 1/8000 s), which a fast ramp turned into end errors proportional to its slope
    (2000 deg/s of yaw: 2e-6 rad/s^2 where the residual after the chord leaves 3e-7).
    """
    far = int(np.argmax(np.abs(x)))
    slope = y[far] / x[far]
    rest = y - np.multiply.outer(x, slope)
    return [(1, slope + end_derivative_weights(x, degree, 1) @ rest),
            (2, end_derivative_weights(x, degree, 2) @ rest)]


def _clamped_ends(tau: np.ndarray, y: np.ndarray, degree: int, points: int):
    """bc_type for make_interp_spline: first and second derivatives at both ends from the end fit."""
    # Relative to the end sample: the weights sum to zero only up to rounding times their gain (~1e2/h^2).
    left = _end_derivatives(tau[:points] - tau[0], y[:points] - y[0], degree)
    right = _end_derivatives(tau[-points:] - tau[-1], y[-points:] - y[-1], degree)
    return left, right


def rounding_noise(magnitude: float) -> float:
    """Standard deviation of the rounding of a float64 of this magnitude: a uniform error over one ulp."""
    return float(np.spacing(abs(magnitude))) / np.sqrt(12.0)


def smoothing_condition(n: int, sigma: float) -> float:
    """FITPACK's s for n samples of noise sigma: the expected residual sum of squares n*sigma^2, raised by one
    standard deviation of that chi-square sum (sqrt(2n) sigma^2). Below n*sigma^2 the fit starts to follow
    the noise (knots multiply, acceleration errors grow a hundredfold: see tools/smoothing_scan.py)."""
    return (n + np.sqrt(2.0 * n)) * sigma ** 2


class _SmoothFit:
    """A quintic smoothing spline per column (FITPACK's curfit through scipy's UnivariateSpline: knots
    placed where the residuals need them, smoothing condition sum of squared residuals <= s). Quintic, so
    that jerk, which tangent attitude needs, is smooth. A column whose stated noise is not above the rounding
    of its own magnitude (none stated; coordinates of ECEF size) is left to the rounding rule
    (`_rounding_fits`): FITPACK stops at 2.9e-5 m/s^2 on a 1 kHz ECEF-sized circle, the rule reaches 1.7e-7."""

    def __init__(self, tau: np.ndarray, y: np.ndarray, noise: float, magnitude: np.ndarray):
        from scipy.interpolate import UnivariateSpline
        self.splines = []
        for j in range(y.shape[1]):
            rounding = rounding_noise(magnitude[j])
            if noise <= rounding:
                interpolant = make_interp_spline(tau, y[:, j], k=5, check_finite=False)
                self.splines.append(_rounding_fits(tau, y[:, [j]], magnitude[[j]], interpolant).get(0, interpolant))
                continue
            sigma = float(np.hypot(noise, rounding))
            if sigma <= 1e-12 * float(np.ptp(y[:, j])):
                # nothing to smooth; FITPACK would add knots up to one per sample, slowly, to get there
                self.splines.append(make_interp_spline(tau, y[:, j], k=5, check_finite=False))
                continue
            with warnings.catch_warnings():
                # "s too small" and friends: FITPACK then returns its best approximation, which we keep
                warnings.simplefilter("ignore", UserWarning)
                self.splines.append(UnivariateSpline(tau, y[:, j], k=5,
                                                     s=smoothing_condition(tau.size, sigma)))

    def evaluate(self, tau_out: np.ndarray, order: int) -> np.ndarray:
        return np.stack([np.column_stack([s(tau_out, nu=d) for s in self.splines]) for d in range(order + 1)])


def _rounding_fits(tau: np.ndarray, y: np.ndarray, magnitude: np.ndarray, interpolant) -> dict:
    """{column: least-squares spline} for the columns where the float rounding of the data's magnitude (ECEF
    coordinates) is what the interpolant's derivatives show; the knot spacing is chosen by Lepski's rule from
    that rounding and the sample rate (imu_emulator.numerics.smoothing). Other columns keep the interpolant."""
    from imu_emulator.numerics.smoothing import choose_lsq_fit
    fits = {}
    for j in range(y.shape[1]):
        acc = (lambda t, j=j: interpolant(t, 2)[:, j]) if interpolant.c.ndim > 1 else (lambda t: interpolant(t, 2))
        fit, _ = choose_lsq_fit(tau, y[:, j], rounding_noise(magnitude[j]), acc)
        if fit is not None:
            fits[j] = fit
    return fits


class _SplineFit:
    """An interpolating spline over all columns; for spline5c (the default) columns whose rounding dominates are
    replaced by the rounding rule's least-squares spline (`_rounding_fits`)."""

    def __init__(self, tau: np.ndarray, y: np.ndarray, spec: _MethodSpec, magnitude: np.ndarray):
        bc = "not-a-knot" if spec.end_fit is None else _clamped_ends(tau, y, *spec.end_fit)
        self.spline = make_interp_spline(tau, y, k=spec.order, bc_type=bc, check_finite=False)
        self.rounding = _rounding_fits(tau, y, magnitude, self.spline) if spec.end_fit is not None else {}

    def evaluate(self, tau_out: np.ndarray, order: int) -> np.ndarray:
        out = np.stack([self.spline(tau_out, nu=d) for d in range(order + 1)])
        for j, fit in self.rounding.items():
            out[:, :, j] = np.stack([fit(tau_out, nu=d) for d in range(order + 1)])
        return out


def _default_row_label(i: int) -> str:
    return f"sample {i}"


def validate_samples(t: np.ndarray, values: np.ndarray, *, where: str, columns: tuple[str, ...],
                     row_label: Callable[[int], str] = _default_row_label) -> None:
    """DataError for the first non-finite cell or time stamp that does not increase.

    `row_label(i)` turns a 0-based sample index into what the user should look for ("row 17" in a CSV).
    Shared with the track loader so that both speak of rows and columns the same way.
    """
    bad_t = ~np.isfinite(t)
    bad_v = ~np.isfinite(values)
    bad_rows = bad_t | bad_v.any(axis=1)
    if bad_rows.any():
        i = int(np.argmax(bad_rows))
        if bad_t[i]:
            raise DataError(f"{where}: {row_label(i)}: time stamp {float(t[i])!r} is not finite")
        j = int(np.argmax(bad_v[i]))
        raise DataError(f"{where}: {row_label(i)}, column '{columns[j]}': value {float(values[i, j])!r} "
                        "is not finite")
    not_after = np.diff(t) <= 0
    if not_after.any():
        i = int(np.argmax(not_after)) + 1
        raise DataError(f"{where}: {row_label(i)}: time stamp {float(t[i])!r} not after previous "
                        f"{float(t[i - 1])!r}")


class SampledSeries:
    """Values sampled at times t (n,), shape (n, m) or (n,), with derivatives up to `max_order`.

    `evaluate(t_out, order)` returns an array (order+1, len(t_out), m): the values, then derivatives 1..order.
    `columns` names the m columns and `row_label` the samples in error messages (defaults: "column j",
    "sample i").
    """

    def __init__(self, t, values, method: str, max_order: int, name: str = "sampled series",
                 columns: tuple[str, ...] | None = None,
                 row_label: Callable[[int], str] = _default_row_label, noise: float = 0.0):
        if method not in _SPECS:
            raise DataError(f"{name}: unknown derivative method '{method}' (known: {', '.join(METHODS)})")
        spec = _SPECS[method]
        if not 0 <= max_order <= 3:
            raise ValueError(f"max_order must be 0..3, got {max_order}")
        t = np.asarray(t, dtype=float)
        y = np.asarray(values, dtype=float)
        if y.ndim == 1:
            y = y[:, None]
        if t.ndim != 1 or y.ndim != 2 or y.shape[0] != t.shape[0]:
            raise DataError(f"{name}: time stamps {t.shape} and values {y.shape} do not match "
                            "(expected (n,) and (n, m))")
        if columns is None:
            columns = tuple(f"column {j}" for j in range(y.shape[1]))
        need = spec.min_samples(max_order)
        if t.size < need:
            raise DataError(f"{name}: method '{method}' needs at least {need} samples for derivatives "
                            f"up to order {max_order}, got {t.size}")
        validate_samples(t, y, where=name, columns=columns, row_label=row_label)

        self.name = name
        self.method = method
        self.max_order = max_order
        self.t_start = float(t[0])
        self.t_end = float(t[-1])
        tau = t - t[0]
        h = float(tau[-1]) / (t.size - 1)
        self._span_tol = _SPAN_RTOL * h
        if spec.kind == "central":
            self._require_uniform(tau, h, t, row_label)
        self._origin = y[0].copy()
        local = y - self._origin
        if spec.kind == "smooth":
            self._fit = _SmoothFit(tau, local, noise, np.abs(y).max(axis=0))
        elif spec.kind == "spline":
            self._fit = _SplineFit(tau, local, spec, np.abs(y).max(axis=0))
        else:
            self._fit = _GridFit(tau, local, spec, max_order, h)

    def _require_uniform(self, tau, h, t, row_label) -> None:
        steps = np.diff(tau)
        # compared with the median step, so that the message points at the irregular sample itself
        usual = float(np.median(steps))
        tol = _UNIFORM_RTOL * h + 4 * np.spacing(max(abs(t[0]), abs(t[-1])))
        off = np.abs(steps - usual) > tol
        if off.any():
            i = int(np.argmax(off)) + 1
            raise DataError(f"{self.name}: method '{self.method}' needs uniformly spaced time stamps; "
                            f"{row_label(i)} is {float(steps[i - 1])!r} s after the previous one, the usual "
                            f"step is {usual!r} s (use spline5 or gradient for irregular time stamps)")

    def evaluate(self, t_out, order: int | None = None) -> np.ndarray:
        t_out = np.atleast_1d(np.asarray(t_out, dtype=float))
        return self.evaluate_relative(t_out - self.t_start, order)

    def evaluate_relative(self, tau_out, order: int | None = None) -> np.ndarray:
        """As `evaluate`, with output times given relative to the first time stamp (`t_start`).

        Far from t = 0 an absolute time t0 + k*dt carries the rounding of t0's magnitude (1.9e-9 s at
        1e7 s), which becomes an error of rate x 1.9e-9 s in every value; (t0 - t_start) + k*dt does not.
        """
        if order is None:
            order = self.max_order
        if not 0 <= order <= self.max_order:
            raise ValueError(f"order must be 0..{self.max_order} (the max_order fitted), got {order}")
        tau_out = np.atleast_1d(np.asarray(tau_out, dtype=float))
        t_out = tau_out + self.t_start
        span = self.t_end - self.t_start
        inside = (tau_out >= -self._span_tol) & (tau_out <= span + self._span_tol)
        if not inside.all():
            i = int(np.argmin(inside))
            raise DataError(f"{self.name}: output time {float(t_out[i])!r} s is outside the input time span "
                            f"[{self.t_start!r}, {self.t_end!r}] s")
        out = self._fit.evaluate(np.clip(tau_out, 0.0, span), order)
        out[0] += self._origin
        return out
