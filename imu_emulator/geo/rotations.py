"""Attitude conversions: Tait-Bryan z-y-x (roll, pitch, yaw), rotation matrices (body -> navigation),
quaternions (scalar first, Hamilton, q ⊗ v ⊗ q* maps body to navigation).

Derived here rather than copied: the DCM -> quaternion branches use the largest of the four candidates
(Shepperd's method) and divide by 4 times THAT component, which stays accurate near 180 degrees where
the trace method loses all digits.
"""
from __future__ import annotations

import math

from imu_emulator.native.lazy import jit
import numpy as np


@jit(cache=True, inline="always")
def matrix_to_quat_scalar(r00, r01, r02, r10, r11, r12, r20, r21, r22):
    trace = r00 + r11 + r22
    # 4*q_i^2 for each component; the largest is computed from its diagonal, the rest from off-diagonals.
    if trace >= r00 and trace >= r11 and trace >= r22:
        s = 2.0 * math.sqrt(max(1.0 + trace, 0.0))
        w, x, y, z = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(max(1.0 + r00 - r11 - r22, 0.0))
        w, x, y, z = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 >= r22:
        s = 2.0 * math.sqrt(max(1.0 + r11 - r00 - r22, 0.0))
        w, x, y, z = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * math.sqrt(max(1.0 + r22 - r00 - r11, 0.0))
        w, x, y, z = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s
    # One sign for the double cover: w >= 0, so equal attitudes give equal bytes on the wire.
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    return w, x, y, z


@jit(cache=True, inline="always")
def quat_multiply_scalar(aw, ax, ay, az, bw, bx, by, bz):
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def euler_to_matrix(euler) -> np.ndarray:
    """(..., 3) roll, pitch, yaw -> (..., 3, 3) R = Rz(yaw) Ry(pitch) Rx(roll), body -> navigation."""
    e = np.asarray(euler, dtype=float)
    cr, sr = np.cos(e[..., 0]), np.sin(e[..., 0])
    cp, sp = np.cos(e[..., 1]), np.sin(e[..., 1])
    cy, sy = np.cos(e[..., 2]), np.sin(e[..., 2])
    R = np.empty(e.shape[:-1] + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def matrix_to_euler(R) -> np.ndarray:
    """(..., 3, 3) -> (..., 3) roll, pitch, yaw. Pitch via atan2 of the full column norm, which stays
    accurate at +-90 degrees where asin(-r20) loses half its digits; there roll and yaw are not separable
    and their sum/difference is put into yaw with roll 0."""
    R = np.asarray(R, dtype=float)
    pitch = np.arctan2(-R[..., 2, 0], np.hypot(R[..., 2, 1], R[..., 2, 2]))
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    # Roll from O(1) elements: atan2(r21, r22) divides two elements of size cos(pitch), so near
    # +-90 degrees ordinary rounding of R would swing it by eps/cos(pitch).
    cy, sy = np.cos(yaw), np.sin(yaw)
    roll = np.arctan2(sy * R[..., 0, 2] - cy * R[..., 1, 2], cy * R[..., 1, 1] - sy * R[..., 0, 1])
    locked = np.hypot(R[..., 0, 0], R[..., 1, 0]) < 1e-12
    if np.any(locked):
        # R = Rz(yaw) Ry(+-90) Rx(roll) depends only on yaw -+ roll: report it as yaw, roll 0.
        sign = np.sign(-R[..., 2, 0])
        combined = np.arctan2(-R[..., 0, 1], R[..., 1, 1])
        roll = np.where(locked, 0.0, roll)
        yaw = np.where(locked, combined, yaw)
        pitch = np.where(locked, sign * np.pi / 2, pitch)
    return np.stack([roll, pitch, yaw], axis=-1)


@jit(cache=True)
def _matrices_to_quats(R, out):
    for i in range(R.shape[0]):
        q = matrix_to_quat_scalar(R[i, 0, 0], R[i, 0, 1], R[i, 0, 2], R[i, 1, 0], R[i, 1, 1], R[i, 1, 2],
                                  R[i, 2, 0], R[i, 2, 1], R[i, 2, 2])
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = q


def matrix_to_quat(R) -> np.ndarray:
    R = np.asarray(R, dtype=float)
    flat = np.ascontiguousarray(R.reshape(-1, 3, 3))
    out = np.empty((flat.shape[0], 4))
    _matrices_to_quats(flat, out)
    return out.reshape(R.shape[:-2] + (4,))


def quat_to_matrix(q) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def euler_to_quat(euler) -> np.ndarray:
    return matrix_to_quat(euler_to_matrix(euler))


def quat_to_euler(q) -> np.ndarray:
    return matrix_to_euler(quat_to_matrix(q))


def quat_multiply(a, b) -> np.ndarray:
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    return np.stack(quat_multiply_scalar(*np.moveaxis(a, -1, 0), *np.moveaxis(b, -1, 0)), axis=-1)


def continuous_quaternions(q) -> np.ndarray:
    """(n, 4) unit quaternions with the sign of each chosen so that neighbours are on the same sheet of the
    double cover (q and -q are one attitude): logs flip signs freely (PX4 keeps w >= 0, so its sign jumps
    as a rotation passes 180 degrees), and a curve fitted through both signs would pass near zero."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    flips = np.concatenate([[False], np.einsum("ij,ij->i", q[1:], q[:-1]) < 0])
    sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
    return q * sign[:, None]
