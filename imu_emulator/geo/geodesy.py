"""Local navigation-frame positions to WGS-84 geodetic coordinates, for devices that report where they are.

The scene's navigation frame (ENU or NED) is a local tangent plane at [scene] origin; a scene without one uses
DEFAULT_ORIGIN: PX4 SITL's default home (47.397742 N, 8.545594 E, 488 m above the ellipsoid),
a point users of those drivers recognise. Conversion is exact (tangent plane -> ECEF -> geodetic,
imu_emulator.geo.frames), not a flat-Earth approximation; tests/geo/test_geodesy.py checks it against pymap3d.
"""
from __future__ import annotations

import numpy as np

from imu_emulator.geo.frames import ecef_to_geodetic, local_to_ecef, ned_from_ecef_matrix

DEFAULT_ORIGIN = (47.397742, 8.545594, 488.0)     # lat deg, lon deg, height m


def to_ned(vectors: np.ndarray, frame: str) -> np.ndarray:
    """Navigation-frame vectors (n, 3) as north, east, down."""
    if frame == "NED":
        return vectors
    return np.stack([vectors[:, 1], vectors[:, 0], -vectors[:, 2]], axis=-1)


def local_to_geodetic(position: np.ndarray, frame: str, origin=None) -> np.ndarray:
    """(n, 3) positions in the scene's frame (ENU or NED tangent at `origin`, default DEFAULT_ORIGIN, or
    ECEF) -> (n, 3) lat deg, lon deg, height m."""
    return ecef_to_geodetic(local_to_ecef(position, frame, DEFAULT_ORIGIN if origin is None else origin))


def device_navigation(position, velocity, specific_force, frame: str, gravity: float, origin=None,
                      gravity_model: str = "constant", positions: str | None = None) -> dict:
    """What a device reports about where it is, from the run's truth: geodetic position, NED velocity and
    linear acceleration (specific force in the level axes the attitude refers to, plus gravity).

    `positions` is the frame of the truth position and velocity (scene.earth.position_frame: ECEF for ECEF,
    ECI and geodetic scenes); ECEF and ECI attitudes refer to local NED at the current position."""
    from imu_emulator.geo import wgs84
    earth = (positions or frame) == "ECEF"
    llh = ecef_to_geodetic(position) if earth else local_to_geodetic(position, frame, origin)
    if earth:
        velocity_ned = np.einsum("nij,nj->ni", ned_from_ecef_matrix(llh[:, 0], llh[:, 1]), velocity)
    else:
        velocity_ned = to_ned(velocity, frame)
    down = (wgs84.normal_gravity(np.radians(llh[:, 0]), llh[:, 2]) if gravity_model == "wgs84"
            else np.full(len(llh), gravity))
    accel_ned = to_ned(specific_force, "ENU" if frame == "ENU" else "NED").copy()
    accel_ned[:, 2] += down
    return {"position_llh": llh, "velocity_ned": velocity_ned, "linear_accel_ned": accel_ned}
