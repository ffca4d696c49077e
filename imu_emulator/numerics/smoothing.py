"""Removing the rounding floor of large coordinates: a least-squares spline whose knot spacing is chosen from
the noise level and the sample rate (issue 14).

Coordinates of ECEF size (6.4e6 m) reach us already rounded to float64: a uniform error over one ulp, 2.7e-10 m
RMS (`rounding_noise`). An interpolating spline passes through that noise and its second derivative multiplies
it by ~fs^2 (3.4e-3 m/s^2 on a 1 kHz track, against 6e-8 for the same track at the origin). FITPACK's smoothing
spline stops adding knots when the residual reaches n sigma^2 and leaves 2.9e-5. What works is a least-squares
spline of high degree on uniform knots (`DEGREE`), if the knot spacing is right: too fine and the noise comes
through (acceleration noise ~ sigma / (spacing^2 sqrt(spacing fs))), too coarse and the fit cannot follow the
motion (an error growing as spacing^(DEGREE-1)). The right spacing depends on the motion, which we do not know,
so it is chosen from the data by Lepski's rule (Lepski, Mammen & Spokoiny 1997, "Optimal spatial adaptation to
inhomogeneous smoothness"): candidates from the finest to the coarsest, each with its acceleration noise known
from the noise level and the sample rate (`acceleration_noise`, exact for the least-squares estimator); a
candidate is accepted while its acceleration differs from every finer candidate's by no more than
kappa * (the two noise levels), kappa = sqrt(2 ln N) for the maximum of N Gaussian differences. The first
candidate is the interpolating spline itself, with the noise its own gain gives: where the rounding is
negligible (coordinates near the origin), the next candidate already differs by more than the rounding can
explain and the interpolant is kept, unchanged. tools/smoothing_scan.py --ecef-floor prints the scan this
rule is measured against."""
from __future__ import annotations

import functools

import numpy as np
from scipy.interpolate import BSpline, make_interp_spline, make_lsq_spline

DEGREE = 9                  # 7: 7e-7 at best on the ECEF circle (12x the origin); 9: 1.7e-7; see the scan
GRID_RATIO = np.sqrt(2.0)   # ratio of successive knot spacings
FIRST_SPACING = 8           # finest candidate spacing, in mean sample steps (~DEGREE samples per knot interval,
                            # where acceleration_noise's 1/sqrt(samples per knot) scaling holds)
MIN_INTERVALS = 4           # coarsest candidate keeps at least this many knot intervals
# The rule runs only where the rounding's share of the interpolant's acceleration exceeds this: below it, what it
# could remove is under every accelerometer's resolution (the best resolve ~1e-7 of their range), and it would
# cost its fits on every oversampled smooth track (near the origin at 1 kHz the share is ~1e-11).
RELEVANT = 1e-9
WINDOW = 20_000             # samples the knot spacing is chosen on (the middle of a longer column)
_EDGE = 0.05                # the comparisons skip this fraction at each end, where any fit's noise is larger


def uniform_knots(span: float, degree: int, spacing: float) -> np.ndarray:
    """Knot vector on [0, span]: the ends repeated degree+1 times, interior knots about `spacing` apart."""
    m = max(1, int(round(span / spacing)))
    return np.r_[[0.0] * (degree + 1), np.linspace(0.0, span, m + 1)[1:-1], [span] * (degree + 1)]


@functools.lru_cache(maxsize=None)
def lsq_gain(degree: int, order: int) -> float:
    """Standard deviation of derivative `order` of a least-squares spline of `degree` on unit-spaced knots, fitted to
    unit white noise at one sample per unit, largest over a knot interval in the interior. Exact from the
    estimator's covariance sigma^2 b^T (B^T B)^-1 b, computed on 40 samples per knot (the 1/sqrt(samples per
    knot) scaling of `acceleration_noise` is the integral limit; at 2 samples per knot it is 10-20 % off)."""
    per, intervals = 40, 24
    tau = np.arange(intervals * per + 1) / per
    knots = uniform_knots(float(intervals), degree, 1.0)
    design = BSpline.design_matrix(tau, knots, degree).toarray()
    cov = np.linalg.inv(design.T @ design)
    at = np.linspace(intervals / 2, intervals / 2 + 1, 101)
    basis = np.eye(design.shape[1])
    rows = np.column_stack([BSpline(knots, basis[i], degree)(at, order) for i in range(design.shape[1])])
    return float(np.sqrt(np.einsum("ij,jk,ik->i", rows, cov, rows).max() * per))


@functools.lru_cache(maxsize=None)
def interpolant_gain(degree: int, order: int) -> float:
    """Standard deviation of derivative `order` of the interpolating spline of `degree` through unit white noise
    at unit steps, largest over a step in the interior (sum of squares of its impulse responses)."""
    n = 81
    x = np.arange(n, dtype=float)
    at = np.linspace(n // 2, n // 2 + 1, 51)
    responses = make_interp_spline(x, np.eye(n), k=degree)(at, order)      # (points, impulses)
    return float(np.sqrt((responses ** 2).sum(axis=1).max()))


def acceleration_noise(sigma: float, spacing: float, rate: float, degree: int = DEGREE) -> float:
    """Noise of the second derivative of the least-squares fit to samples at `rate` with noise `sigma`."""
    return sigma * lsq_gain(degree, 2) / (spacing ** 2 * np.sqrt(spacing * rate))


def candidate_spacings(span: float, n: int, degree: int = DEGREE) -> list[float]:
    h = span / (n - 1)
    out, spacing = [], FIRST_SPACING * h
    while spacing <= span / max(MIN_INTERVALS, degree + 1):
        out.append(spacing)
        spacing *= GRID_RATIO
    return out


def lepski_select(candidates, estimate, kappa: float, accepted=()):
    """Lepski's rule over `candidates` ordered from the least to the most smoothing: `estimate(c)` returns
    (fit, acceleration at the comparison points, its noise standard deviation there) or None when c cannot be
    fitted. Returns (fit, candidate) of the last one accepted, or (None, None) if none was; `accepted` holds
    (acceleration, noise) of estimates ranked before all candidates (the interpolant)."""
    accepted = list(accepted)
    chosen = (None, None)
    for c in candidates:
        got = estimate(c)
        if got is None:
            break
        fit, acc, noise = got
        if any(np.any(np.abs(acc - a) > kappa * (s + noise)) for a, s in accepted):
            break
        accepted.append((acc, noise))
        chosen = (fit, c)
    return chosen


def comparison_points(tau: np.ndarray, limit: int = 20_000) -> tuple[np.ndarray, float]:
    """The input times the rule compares candidates at (not the ends, at most `limit`), and kappa for them."""
    span = float(tau[-1] - tau[0])
    inner = tau[(tau > tau[0] + _EDGE * span) & (tau < tau[-1] - _EDGE * span)]
    if inner.size > limit:
        inner = inner[:: inner.size // limit + 1]
    return inner, float(np.sqrt(2.0 * np.log(max(inner.size, 2))))


def _lsq_fit(tau: np.ndarray, y: np.ndarray, spacing: float):
    """Least-squares spline of DEGREE on uniform knots over tau's span, or None where it cannot be fitted."""
    try:
        # normal equations: 25x faster than scipy's default QR at 100 000 samples, the same result on the
        # ECEF circle to 0.1 % (B-splines are well conditioned and the values are relative to the first sample)
        return make_lsq_spline(tau, y, uniform_knots(float(tau[-1] - tau[0]), DEGREE, spacing) + tau[0], k=DEGREE,
                               check_finite=False, method="norm-eq")
    except (np.linalg.LinAlgError, ValueError):      # too few samples under a knot interval (irregular stamps)
        return None


def choose_lsq_fit(tau: np.ndarray, y: np.ndarray, sigma: float, interpolant_acc, interpolant_degree: int = 5):
    """The least-squares spline Lepski's rule picks for one column, or None to keep the interpolant.

    `interpolant_acc(t)` is the interpolating spline's acceleration; `sigma` the noise of y (rounding or stated).
    The spacing is chosen on the middle WINDOW samples (a long log costs one full fit, not one per candidate),
    then the whole column is fitted with it. Returns (spline or None, knot spacing or None)."""
    n = tau.size
    span = float(tau[-1])
    if sigma <= 0.0 or n < 4 * (DEGREE + 1) or np.ptp(y) == 0.0:
        return None, None
    rate = (n - 1) / span
    lo = max(0, (n - WINDOW) // 2)
    part, part_y = tau[lo:lo + WINDOW], y[lo:lo + WINDOW]
    inner, kappa = comparison_points(part)
    interpolant = (interpolant_acc(inner), sigma * interpolant_gain(interpolant_degree, 2) * rate ** 2)
    if interpolant[1] <= RELEVANT * np.abs(interpolant[0]).max():
        return None, None

    def estimate(spacing):
        fit = _lsq_fit(part, part_y, spacing)
        return None if fit is None else (fit, fit(inner, 2), acceleration_noise(sigma, spacing, rate))

    fit, spacing = lepski_select(candidate_spacings(float(part[-1] - part[0]), part.size), estimate, kappa,
                                 [interpolant])
    if fit is None or part.size == n:
        return fit, spacing
    whole = _lsq_fit(tau, y, spacing)
    return (None, None) if whole is None else (whole, spacing)
