"""Body angular rate from SAMPLED attitude: three ways, for users with logged attitude and for the
accuracy study (tools/accuracy_study.py).

All three return omega_B, the rate of the body relative to the navigation frame in body coordinates,
[omega_B]x = R^T dR/dt, with R = Rz(yaw) Ry(pitch) Rx(roll) mapping body to navigation coordinates.

- `euler_rate`: omega_B = E(phi) dphi/dt, the angles' derivatives from a derivative method of
  imu_emulator.numerics.derivatives (spline5c by default). E itself is exact at any pitch (only E^-1 is singular),
  but sampled Euler angles themselves jump at gimbal lock (roll and yaw are then not separable), so this
  method needs data that stay away from pitch = +-90 deg.  What the kernel does for `attitude.mode = "file"`.
- `dcm_rate`: the original MATLAB tool's way: differentiate the nine elements of R numerically (MATLAB's
  `gradient` by default, as the original), form Omega_N = dR/dt R^T, take its skew part (Omega_N is skew
  only up to the differentiation error) and rotate to the body frame: omega_B = R^T omega_N.  The original
  stopped at Omega_N, the rate in navigation coordinates; a gyro measures the body-frame rate.
- `increment_rate`: rotation increments: for each sample k and each neighbour j of a finite-difference
  stencil, the rotation vector r_kj = 2 log(q_k^-1 q_j) of the relative rotation, then omega_B(t_k) =
  sum_j w_j r_kj with Fornberg weights for d/dt at t_k (central inside, one-sided of the same order at the
  ends, any time spacing).  Exact in the sense that d/dt log(q_k^-1 q(t)) at t_k is omega_B(t_k); never
  touches Euler angles, so gimbal lock and yaw wrapping do not exist for it.  Accepts quaternions directly.
  Order 2 is the classic 2 log(q_{k-1}^-1 q_{k+1}) / (2h).

Logarithms use atan2(|v|, w), never acos(w): w may exceed 1 by a rounding error.
"""
from __future__ import annotations

import numpy as np

from imu_emulator.numerics.derivatives import SampledSeries, fd_weights, unwrap_angles
from imu_emulator.errors import DataError
from imu_emulator.geo.rotations import euler_to_matrix, euler_to_quat

DEFAULT_METHOD = "spline5c"
INCREMENT_ORDERS = (2, 4, 6, 8)


def euler_matrix_e(euler: np.ndarray) -> np.ndarray:
    """(..., 3) roll, pitch, yaw -> (..., 3, 3) E with omega_B = E dphi/dt (z-y-x)."""
    e = np.asarray(euler, dtype=float)
    cr, sr = np.cos(e[..., 0]), np.sin(e[..., 0])
    cp, sp = np.cos(e[..., 1]), np.sin(e[..., 1])
    E = np.zeros(e.shape[:-1] + (3, 3))
    E[..., 0, 0] = 1.0
    E[..., 0, 2] = -sp
    E[..., 1, 1] = cr
    E[..., 1, 2] = sr * cp
    E[..., 2, 1] = -sr
    E[..., 2, 2] = cr * cp
    return E


def _check(t, values, width, where):
    t = np.asarray(t, dtype=float)
    values = np.asarray(values, dtype=float)
    if t.ndim != 1 or values.shape != (t.size, width):
        raise DataError(f"{where}: time stamps {t.shape} and values {values.shape} do not match "
                        f"(expected (n,) and (n, {width}))")
    return t, values


def euler_rate(t, euler, method: str = DEFAULT_METHOD, t_out=None) -> np.ndarray:
    """omega_B (n_out, 3) = E(phi) dphi/dt, Euler angles (n, 3) roll, pitch, yaw (unwrapped here)."""
    t, euler = _check(t, euler, 3, "euler_rate")
    series = SampledSeries(t, unwrap_angles(euler), method, 1, name="euler_rate")
    phi, dphi = series.evaluate(t if t_out is None else t_out, 1)
    return np.einsum("nij,nj->ni", euler_matrix_e(phi), dphi)


def dcm_rate(t, euler, method: str = "gradient", t_out=None) -> np.ndarray:
    """omega_B (n_out, 3) from dR/dt R^T (the original tool's Omega_N), rotated into the body frame."""
    t, euler = _check(t, euler, 3, "dcm_rate")
    R = euler_to_matrix(euler).reshape(-1, 9)
    series = SampledSeries(t, R, method, 1, name="dcm_rate")
    Rs, dR = series.evaluate(t if t_out is None else t_out, 1)
    Rs = Rs.reshape(-1, 3, 3)
    omega_n_x = dR.reshape(-1, 3, 3) @ np.swapaxes(Rs, 1, 2)        # [omega_N]x, skew up to the error
    skew = 0.5 * (omega_n_x - np.swapaxes(omega_n_x, 1, 2))
    omega_n = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], axis=-1)
    return np.einsum("nji,nj->ni", Rs, omega_n)                     # R^T omega_N


def quat_log(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (scalar first) -> (..., 3) rotation vectors, angle in [0, pi]."""
    q = np.asarray(q, dtype=float)
    q = np.where(q[..., :1] < 0, -q, q)                             # the shorter of the two rotations
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    angle = 2.0 * np.arctan2(s, q[..., 0])                          # never acos: w may round above 1
    # angle / s -> 2 / w as s -> 0; the series keeps full precision for tiny rotations
    small = s < 1e-8
    factor = np.where(small, 2.0 / np.where(small, q[..., 0], 1.0), angle / np.where(small, 1.0, s))
    return v * factor[..., None]


def _conj_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a^-1 b for unit quaternions, scalar first, along the last axis."""
    aw, ax, ay, az = -a[..., 0], a[..., 1], a[..., 2], a[..., 3]     # -conj(a): same rotation, sign flip
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return -np.stack([aw * bw - ax * bx - ay * by - az * bz,
                      aw * bx + ax * bw + ay * bz - az * by,
                      aw * by - ax * bz + ay * bw + az * bx,
                      aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def increment_rate_from_quaternions(t, q, order: int = 4) -> np.ndarray:
    """omega_B (n, 3) at the sample times from quaternions (n, 4), scalar first, body -> navigation."""
    if order not in INCREMENT_ORDERS:
        raise ValueError(f"order must be one of {INCREMENT_ORDERS}, got {order}")
    t, q = _check(t, q, 4, "increment_rate")
    n = t.size
    if n < order + 1:
        raise DataError(f"increment_rate: order {order} needs at least {order + 1} samples, got {n}")
    if not np.isfinite(q).all() or not np.isfinite(t).all():
        raise DataError("increment_rate: non-finite time stamp or quaternion")
    if np.any(np.diff(t) <= 0):
        i = int(np.argmax(np.diff(t) <= 0)) + 1
        raise DataError(f"increment_rate: sample {i}: time stamp {t[i]!r} not after previous {t[i - 1]!r}")
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    tau = t - t[0]
    half = order // 2
    out = np.zeros((n, 3))
    # interior: central stencil k-half .. k+half (weights per sample: time steps may vary)
    k = np.arange(half, n - half)
    offsets = np.arange(-half, half + 1)
    for j in offsets:
        if j == 0:
            continue
        r = quat_log(_conj_mul(q[k], q[k + j]))
        x = tau[k[:, None] + offsets] - tau[k][:, None]              # (m, stencil)
        w = _weights_rows(x, list(offsets).index(j))
        out[k] += w[:, None] * r
    # ends: one-sided stencil of order+1 samples
    for i in (*range(half), *range(n - half, n)):
        s = min(max(i - half, 0), n - order - 1)
        nodes = np.arange(s, s + order + 1)
        w = fd_weights(tau[nodes] - tau[i], 1)
        r = quat_log(_conj_mul(np.broadcast_to(q[i], (nodes.size, 4)), q[nodes]))
        out[i] = w @ r
    return out


def _weights_rows(x: np.ndarray, column: int) -> np.ndarray:
    """First-derivative weight of stencil node `column` for each row of offsets x (m, p)."""
    if np.allclose(x, x[0], rtol=1e-9, atol=0):
        return np.full(x.shape[0], fd_weights(x[0], 1)[column])
    return np.array([fd_weights(row, 1)[column] for row in x])


def increment_rate(t, euler, order: int = 4) -> np.ndarray:
    """omega_B (n, 3) at the sample times from Euler angles (n, 3), via quaternions and rotation increments."""
    t, euler = _check(t, euler, 3, "increment_rate")
    return increment_rate_from_quaternions(t, euler_to_quat(euler), order)


METHODS = {
    "euler": euler_rate,
    "dcm": dcm_rate,
    "increment": increment_rate,
}
