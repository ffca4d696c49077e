"""Quaternion arithmetic the formats need at their edge (frame changes, alignment rotations), in numpy on
blocks: scalar-first unit quaternions (w, x, y, z), Hamilton product, q rotating vectors v -> q v q*.

firmware_protocols stands below the simulation in the import order, so it keeps these few lines of its own
rather than reaching up into imu_emulator.geo.rotations.
"""
from __future__ import annotations

import numpy as np

# ENU <-> NED: x_ned = (y_enu, x_enu, -z_enu), the rotation by pi about (1, 1, 0)/sqrt(2): its own inverse.
Q_NED_FROM_ENU = np.array([0.0, 1.0, 1.0, 0.0]) / np.sqrt(2.0)


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a (x) b of (n, 4) or (4,) quaternions (broadcast)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def conjugate(q: np.ndarray) -> np.ndarray:
    return np.asarray(q, dtype=np.float64) * np.array([1.0, -1.0, -1.0, -1.0])


def matrix(q) -> np.ndarray:
    """The rotation matrix of one unit quaternion (normalised first: wire values are float32)."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def to_euler(q: np.ndarray) -> np.ndarray:
    """(n, 4) body -> navigation quaternions -> (n, 3) roll, pitch, yaw (z-y-x Tait-Bryan, rad)."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - x * z), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)


def from_euler(euler: np.ndarray) -> np.ndarray:
    """(n, 3) roll, pitch, yaw (z-y-x, rad) -> (n, 4) quaternions, the inverse of to_euler."""
    half = 0.5 * np.asarray(euler, dtype=np.float64)
    cr, cp, cy = np.cos(half).T
    sr, sp, sy = np.sin(half).T
    return np.stack([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy], axis=-1)


def rotate(q, vectors: np.ndarray) -> np.ndarray:
    """(n, 3) vectors rotated by the one quaternion q: q v q*."""
    return np.asarray(vectors, dtype=np.float64) @ matrix(q).T


def canonical(q: np.ndarray) -> np.ndarray:
    """The sign of each quaternion with w >= 0 (q and -q are one rotation; readers compare values)."""
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)


def to_ned(quat: np.ndarray, frame: str) -> np.ndarray:
    """Sensor -> navigation attitude in the scene's frame ("ENU" or "NED") -> sensor -> NED. Only the
    reference side changes: the sensor frame is the one the accelerometer and gyro data are expressed in,
    so f_ned = R(q_ned) f_sensor holds for what goes on the wire."""
    if frame == "NED":
        return quat
    return canonical(multiply(Q_NED_FROM_ENU, quat))


def from_ned(quat: np.ndarray, frame: str) -> np.ndarray:
    """Sensor -> NED attitude -> sensor -> `frame` ("NED", "ENU" or "NWU"), for formats that declare another
    reference frame (Xsens)."""
    if frame == "NED":
        return quat
    reference = Q_NED_FROM_ENU if frame == "ENU" else np.array([0.0, 1.0, 0.0, 0.0])  # both are their own inverse
    return canonical(multiply(reference, quat))


def from_rotation_vector(theta: np.ndarray) -> np.ndarray:
    """(n, 3) rotation vectors -> (n, 4) unit quaternions (w, x, y, z); exact near zero via sinc."""
    theta = np.asarray(theta, dtype=np.float64)
    angle = np.sqrt(np.einsum("...i,...i->...", theta, theta))
    half = 0.5 * angle
    # sin(half) / angle = 0.5 * sinc(half / pi), with numpy's sinc(x) = sin(pi x) / (pi x)
    k = 0.5 * np.sinc(half / np.pi)
    return np.concatenate((np.cos(half)[..., None], theta * k[..., None]), axis=-1)


def to_rotation_vector(q: np.ndarray) -> np.ndarray:
    """(n, 4) unit quaternions -> (n, 3) rotation vectors of angle <= pi (the inverse of from_rotation_vector)."""
    q = canonical(np.asarray(q, dtype=np.float64))
    vector = q[..., 1:]
    sine = np.sqrt(np.einsum("...i,...i->...", vector, vector))
    angle = 2.0 * np.arctan2(sine, q[..., 0])
    # angle / sin(angle / 2), by its series below 1e-4 rad (the division loses digits there)
    scale = np.where(sine > 1e-8, angle / np.where(sine > 1e-8, sine, 1.0), 2.0 + angle ** 2 / 12.0)
    return vector * scale[..., None]


def attitude_change(quat: np.ndarray, quat_before: np.ndarray, dtheta: np.ndarray, dtheta_before: np.ndarray,
                    gyro_errors: bool = True) -> np.ndarray:
    """The sensor's attitude change over each sample interval, q(t_k-1)^-1 (x) q(t_k), as Xsens' DeltaQ
    defines it: (n, 4), from the true attitudes at the interval's ends (sensor -> navigation frame, any fixed
    reference: it cancels) and the measured increments.

    The true attitudes give the exact change, coning included, which the rotation by the summed increment
    Δθ misses (for two non-commuting rotations the two differ by ½∫α×ω dt, the coning term). Without
    gyro_errors (the caller knows the gyro senses exactly the true attitude's rate) that is the answer.
    Otherwise what the gyro adds to the truth (its errors; the navigation frame's rotation when the gyros
    sense the Earth's rate) enters as the rotation vector ε = Δθ − (φ − c), where φ is the true change's
    rotation vector and c = Δθ_k−1 × Δθ_k / 12 the two-sample coning estimate of φ − ∫ω dt (Savage,
    Strapdown Analytics §7.1.1.1): ε is the increment's error to first order, plus the estimate's residual
    (c's error, small against c itself while the motion is slow against the sample rate).
    quat_before, dtheta_before: the samples before each row."""
    exact = multiply(conjugate(quat_before), quat)
    if not gyro_errors:
        return canonical(exact)
    coning = np.cross(dtheta_before, dtheta) / 12.0
    error = dtheta - (to_rotation_vector(exact) - coning)
    return canonical(multiply(exact, from_rotation_vector(error)))


def increments_in_reference(quat: np.ndarray, dtheta: np.ndarray, dvel: np.ndarray) -> tuple:
    """One interval's increments (sensor axes) re-expressed in the reference frame of `quat` (sensor ->
    reference at the interval's end), as an integrating device does in a fixed frame: ∫C(t)ω dt and ∫C(t)f dt.

    With the rate and the specific force constant in sensor axes over the interval, C(t) = C_k exp([φ×](t −
    t_k)/T) and ∫C f dt = C_k J(−φ) Δv, where φ = Δθ and J(x) = I + (1 − cos θ)/θ² [x×] + (θ − sin θ)/θ³ [x×]²
    (the integral of the rotation over the interval: exact for that motion, the closed form the tests use);
    J(−φ) φ = φ, so the angle increment is C_k Δθ. (3,) arrays in, (3,) arrays out."""
    matrix_k = matrix(quat)
    dtheta, dvel = np.asarray(dtheta, dtype=np.float64), np.asarray(dvel, dtype=np.float64)
    angle = float(np.sqrt(dtheta @ dtheta))
    if angle < 1e-4:     # the series, to where its next terms (θ⁴/720, θ⁴/5040) are below 1e-19
        first, second = 0.5 - angle ** 2 / 24.0, 1.0 / 6.0 - angle ** 2 / 120.0
    else:
        first, second = (1.0 - np.cos(angle)) / angle ** 2, (angle - np.sin(angle)) / angle ** 3
    cross = np.cross(dtheta, dvel)
    integral = dvel - first * cross + second * np.cross(dtheta, cross)
    return matrix_k @ dtheta, matrix_k @ integral
