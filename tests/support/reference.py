"""An independent oracle for the kinematics: sympy derives everything from the rotation MATRIX
(omega_B from R^T dR/dt, alpha by differentiating that), never from the kernel's Euler-rate formula,
and tangent attitude from the spec's atan2/asin formulas, not the kernel's algebraic form."""
from __future__ import annotations

import numpy as np
import sympy as sp

t = sp.Symbol("t", real=True)


def _rot(roll, pitch, yaw):
    rx = sp.Matrix([[1, 0, 0], [0, sp.cos(roll), -sp.sin(roll)], [0, sp.sin(roll), sp.cos(roll)]])
    ry = sp.Matrix([[sp.cos(pitch), 0, sp.sin(pitch)], [0, 1, 0], [-sp.sin(pitch), 0, sp.cos(pitch)]])
    rz = sp.Matrix([[sp.cos(yaw), -sp.sin(yaw), 0], [sp.sin(yaw), sp.cos(yaw), 0], [0, 0, 1]])
    return rz * ry * rx


def imu_functions(position, euler=None, *, frame="ENU", g0=9.80665, lever=(0, 0, 0), gravity=True):
    """position: 3 sympy expressions in t; euler: 3 expressions (roll, pitch, yaw) or None for tangent.
    Returns f(t_array) -> (accel (n,3), gyro (n,3)) in the body frame at the lever arm."""
    s = sp.Matrix(position)
    v = s.diff(t)
    a = v.diff(t)
    if euler is None:
        speed = sp.sqrt(v.dot(v))
        euler = (0, -sp.asin(v[2] / speed), sp.atan2(v[1], v[0]))
    R = _rot(*euler)
    W = R.T * R.diff(t)            # [w_B]x
    w = sp.Matrix([W[2, 1], W[0, 2], W[1, 0]])
    al = w.diff(t)
    g = sp.Matrix([0, 0, (-g0 if frame == "ENU" else g0) if gravity else 0])
    r = sp.Matrix(lever)
    f = R.T * (a - g) + w.cross(w.cross(r)) + al.cross(r)
    fa = sp.lambdify(t, list(f), "numpy")
    fw = sp.lambdify(t, list(w), "numpy")

    def evaluate(times):
        times = np.asarray(times, float)
        acc = np.array([np.broadcast_to(np.asarray(c, float), times.shape) for c in fa(times)]).T
        gyro = np.array([np.broadcast_to(np.asarray(c, float), times.shape) for c in fw(times)]).T
        return acc, gyro
    return evaluate
