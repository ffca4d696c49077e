"""Logged velocity as data in the position fit: one least-squares spline fitted jointly to the logged positions
and the logged velocities (its derivative), each weighted by the inverse variance of its noise.

PX4's `vehicle_local_position` and ArduPilot's EKF log a velocity beside the position; its errors are
independent of the position's. A least-squares spline s(t) on uniform knots minimises

    sum_i |p_i - s(t_i)|^2 / sigma_p^2  +  sum_k |v_k - s'(u_k)|^2 / sigma_v^2

(weighted least squares, the maximum-likelihood fit under independent Gaussian noise). Its coefficients'
covariance is (B^T W B)^-1 with B the stacked design rows (values at t_i, derivatives at u_k) and W the
weights, so the variance of any derivative of the fit is known in closed form (`acceleration_std`); with
velocities the acceleration's variance is lower than from positions alone, by how much depends on the two
noise levels, the rates and the knot spacing (tests/scene/logs/test_joint_fit.py states and checks it)."""
from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import BSpline
from scipy.sparse.linalg import spsolve

from imu_emulator.errors import DataError
from imu_emulator.numerics.smoothing import uniform_knots

DEGREE = 5          # quintic, as `smooth`: jerk stays continuous for tangent attitude


def _design(x: np.ndarray, knots: np.ndarray, degree: int, order: int) -> sp.csr_matrix:
    """Rows b^(order)(x) of the B-spline basis: the derivative of a spline of degree k is a spline of degree k-1
    on the inner knots with coefficients k (c_i - c_{i-1}) / (t_{i+k} - t_i), applied `order` times."""
    ncoef = knots.size - degree - 1
    transform = sp.identity(ncoef, format="csr")
    k, t = degree, knots
    for _ in range(order):
        scale = k / (t[k + 1:-1] - t[1:-k - 1])
        diff = sp.diags([-scale, scale], [0, 1], shape=(scale.size, scale.size + 1), format="csr")
        transform = diff @ transform
        k, t = k - 1, t[1:-1]
    return (BSpline.design_matrix(x, t, k) @ transform).tocsr()


class JointFit:
    """Weighted least-squares spline through positions (n, m) and velocities (l, m) on their own time stamps.

    `spacing` is the knot spacing in s. `evaluate(t, order)` returns (order+1, len(t), m) like SampledSeries."""

    def __init__(self, t_pos, pos, sigma_pos: float, t_vel=None, vel=None, sigma_vel: float | None = None,
                 spacing: float = 0.1, degree: int = DEGREE):
        t_pos = np.asarray(t_pos, dtype=float)
        pos = np.asarray(pos, dtype=float).reshape(t_pos.size, -1)
        if sigma_pos <= 0 or (vel is not None and (sigma_vel is None or sigma_vel <= 0)):
            raise DataError("joint position/velocity fit: the noise levels must be > 0")
        self.degree = degree
        self.knots = uniform_knots(float(t_pos[-1] - t_pos[0]), degree, spacing) + t_pos[0]
        rows, weights, data = [_design(t_pos, self.knots, degree, 0)], [np.full(t_pos.size, sigma_pos ** -2)], [pos]
        if vel is not None:
            t_vel = np.asarray(t_vel, dtype=float)
            inside = (t_vel >= t_pos[0]) & (t_vel <= t_pos[-1])
            rows.append(_design(t_vel[inside], self.knots, degree, 1))
            weights.append(np.full(int(inside.sum()), sigma_vel ** -2))
            data.append(np.asarray(vel, dtype=float).reshape(t_vel.size, -1)[inside])
        design, w = sp.vstack(rows).tocsc(), sp.diags(np.concatenate(weights))
        self._normal = (design.T @ w @ design).tocsc()
        rhs = design.T @ (w @ np.vstack(data))
        with warnings.catch_warnings():
            # a singular system (knot intervals without data) gives non-finite coefficients, checked by callers
            warnings.simplefilter("ignore", sp.linalg.MatrixRankWarning)
            coef = spsolve(self._normal, rhs)
        self.spline = BSpline(self.knots, coef.reshape(-1, pos.shape[1]), degree)

    def evaluate(self, t, order: int) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return np.stack([self.spline(t, nu=d) for d in range(order + 1)])

    def derivative_std(self, t, order: int) -> np.ndarray:
        """Standard deviation of derivative `order` of the fit at t, per column, from the coefficients'
        covariance (B^T W B)^-1 (exact for the estimator when the stated noise levels are the true ones)."""
        rows = _design(np.atleast_1d(np.asarray(t, dtype=float)), self.knots, self.degree, order).toarray()
        cov = np.linalg.inv(self._normal.toarray())
        return np.sqrt(np.einsum("ij,jk,ik->i", rows, cov, rows))


def _acceleration_noise(spacing: float, pos_rate: float, vel_rate: float | None, sigma_pos: float,
                        sigma_vel: float | None, degree: int) -> float:
    """Largest acceleration standard deviation over an interior knot interval of the joint fit, from its exact
    covariance on a stand-in problem of 24 knot intervals at the same rates and noise (uniform knots make the
    interior stationary; the whole log's covariance would need a dense inverse of its size)."""
    span = 24 * spacing
    t_pos = np.arange(int(span * pos_rate) + 1) / pos_rate
    zeros = np.zeros((t_pos.size, 1))
    if vel_rate is None:
        fit = JointFit(t_pos, zeros, sigma_pos, spacing=spacing, degree=degree)
    else:
        t_vel = np.arange(int(span * vel_rate) + 1) / vel_rate
        fit = JointFit(t_pos, zeros, sigma_pos, t_vel, np.zeros((t_vel.size, 1)), sigma_vel, spacing, degree)
    return float(fit.derivative_std(np.linspace(12 * spacing, 13 * spacing, 41), 2).max())


def choose_joint_fit(position, velocity, sigma_pos: float, sigma_vel: float, where: str,
                     degree: int = DEGREE) -> tuple[JointFit, float]:
    """The joint fit of position and velocity Series whose knot spacing Lepski's rule picks (as for the
    rounding of large coordinates, imu_emulator.numerics.smoothing): (fit, spacing in s)."""
    from imu_emulator.numerics.smoothing import comparison_points, lepski_select
    t = position.t
    span = float(t[-1] - t[0])
    pos_rate = (t.size - 1) / span
    vel_rate = (velocity.t.size - 1) / float(velocity.t[-1] - velocity.t[0])
    inner, kappa = comparison_points(t)
    candidates, spacing = [], 2.0 / pos_rate
    while spacing <= span / 4:
        candidates.append(spacing)
        spacing *= np.sqrt(2.0)

    def estimate(spacing):
        try:
            fit = JointFit(t, position.values, sigma_pos, velocity.t, velocity.values, sigma_vel, spacing, degree)
        except (RuntimeError, ValueError):
            return None
        if not np.isfinite(fit.spline.c).all():          # a singular system: knot intervals without data
            return None
        noise = _acceleration_noise(spacing, pos_rate, vel_rate, sigma_pos, sigma_vel, degree)
        return fit, fit.evaluate(inner, 2)[2], noise

    fit, spacing = lepski_select(candidates, estimate, kappa)
    if fit is None:
        raise DataError(f"{where}: no knot spacing from {candidates[0] if candidates else 0:.3g} s up fits the "
                        "position and velocity jointly (too few samples?)")
    return fit, spacing
