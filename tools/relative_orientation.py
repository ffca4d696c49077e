"""Relative orientation (and lever arm) of two IMUs on one rigid body, from their time-synchronised data.

    .venv/bin/python tools/relative_orientation.py run.npz --a imu0 --b imu1

`run.npz` is what `imu-emulator generate SCENE -o run.npz` writes (or any NPZ with t, imu_names, accel,
gyro shaped (imu, n, 3)). Prints the rotation C that takes IMU B's sensor coordinates to IMU A's
(as roll, pitch, yaw in degrees, z-y-x) and the position of A relative to B in A's frame.

Method (the idea of seeds/003: estimate the DCM between the two sensors from normal-operation data):
both gyros see one body rate, w_A = C w_B, lever-arm free; the accelerometers differ by the lever arm,
f_A = C f_B + ([w_A]x^2 + [alpha_A]x) d. Given d, C is the solution of Wahba's problem over the pairs
(w_A, w_B) and (f_A - K d, f_B), found by SVD; given C, d is linear least squares. Alternating the two
converges in a few iterations from the lever-arm-free start. The motion must excite at least two
non-parallel directions (a body rotating about one fixed axis leaves a rotation about it unobservable).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from imu_emulator.rotations import matrix_to_euler  # noqa: E402


@dataclass
class RelativeOrientation:
    C: np.ndarray               # B sensor coordinates -> A sensor coordinates
    lever_m: np.ndarray         # position of A relative to B, A's frame
    residual_accel: float       # RMS, m/s^2
    residual_gyro: float        # RMS, rad/s
    iterations: int

    @property
    def rpy_deg(self) -> np.ndarray:
        return np.degrees(matrix_to_euler(self.C))


def _skew(v: np.ndarray) -> np.ndarray:
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def wahba(a: np.ndarray, b: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The rotation C minimising sum w |a_i - C b_i|^2 (SVD solution, proper rotation)."""
    B = (a * weights[:, None]).T @ b
    U, _, Vt = np.linalg.svd(B)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt))])
    return U @ D @ Vt


def estimate(accel_a, gyro_a, accel_b, gyro_b, dt: float, iterations: int = 20,
             with_lever_arm: bool = True) -> RelativeOrientation:
    accel_a, gyro_a, accel_b, gyro_b = (np.asarray(x, float) for x in (accel_a, gyro_a, accel_b, gyro_b))
    n = len(accel_a)
    if not (len(gyro_a) == len(accel_b) == len(gyro_b) == n) or n < 3:
        raise ValueError("the two IMUs need the same number (>= 3) of time-synchronised samples")
    alpha_a = np.gradient(gyro_a, dt, axis=0)
    K = _skew(gyro_a) @ _skew(gyro_a) + _skew(alpha_a)            # lever-arm operator, (n, 3, 3)
    # Both vector kinds count per unit: scale so their RMS magnitudes weigh equally.
    wg = 1.0 / max(np.mean(np.sum(gyro_a ** 2, 1)), 1e-30)
    wf = 1.0 / max(np.mean(np.sum(accel_a ** 2, 1)), 1e-30)
    pairs_a = np.concatenate([gyro_a, accel_a])
    pairs_b = np.concatenate([gyro_b, accel_b])
    weights = np.concatenate([np.full(n, wg), np.full(n, wf)])
    d = np.zeros(3)
    C = wahba(pairs_a, pairs_b, weights)
    done = 0
    for done in range(1, iterations + 1 if with_lever_arm else 1):
        rhs = accel_a - accel_b @ C.T
        d_new = np.linalg.lstsq(K.reshape(-1, 3), rhs.reshape(-1), rcond=None)[0]
        pairs_a[n:] = accel_a - np.einsum("nij,j->ni", K, d_new)
        C_new = wahba(pairs_a, pairs_b, weights)
        converged = np.abs(C_new - C).max() < 1e-13 and np.abs(d_new - d).max() < 1e-12
        C, d = C_new, d_new
        if converged:
            break
    accel_residual = accel_a - accel_b @ C.T - np.einsum("nij,j->ni", K, d)
    gyro_residual = gyro_a - gyro_b @ C.T
    return RelativeOrientation(C=C, lever_m=d, residual_accel=float(np.sqrt(np.mean(accel_residual ** 2))),
                               residual_gyro=float(np.sqrt(np.mean(gyro_residual ** 2))), iterations=done)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("npz", help="samples of two or more IMUs (imu-emulator generate ... -o run.npz)")
    parser.add_argument("--a", required=True, help="name of the reference IMU")
    parser.add_argument("--b", required=True, help="name of the IMU whose orientation relative to A is wanted")
    parser.add_argument("--no-lever-arm", action="store_true", help="assume the two IMUs sit at one point")
    args = parser.parse_args(argv)
    try:
        data = np.load(args.npz)
        names = [str(x) for x in data["imu_names"]]
        ia, ib = names.index(args.a), names.index(args.b)
    except (OSError, KeyError) as exc:
        print(f"error: {args.npz}: {exc}", file=sys.stderr)
        return 2
    except ValueError:
        print(f"error: {args.npz}: IMU names are {names}; got --a {args.a} --b {args.b}", file=sys.stderr)
        return 2
    t = data["t"]
    result = estimate(data["accel"][ia], data["gyro"][ia], data["accel"][ib], data["gyro"][ib],
                      float(np.median(np.diff(t))), with_lever_arm=not args.no_lever_arm)
    roll, pitch, yaw = result.rpy_deg
    print(f"orientation of {args.b} relative to {args.a} (z-y-x): roll {roll:.6f} deg, pitch {pitch:.6f} deg, "
          f"yaw {yaw:.6f} deg")
    print(f"position of {args.a} relative to {args.b}, in {args.a}'s frame: "
          + ", ".join(f"{v:+.6f}" for v in result.lever_m) + " m")
    print(f"residual RMS: accel {result.residual_accel:.3g} m/s^2, gyro {result.residual_gyro:.3g} rad/s "
          f"({result.iterations} iterations)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
