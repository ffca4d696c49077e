"""Local navigation-frame positions to WGS-84 geodetic coordinates, for devices that report where they are.

The scene's navigation frame (ENU or NED) is a local tangent plane at an origin. Scenes carry no origin yet,
so DEFAULT_ORIGIN is used: PX4 SITL's default home (47.397742 N, 8.545594 E, 488 m above the ellipsoid),
a point users of those drivers recognise. Conversion is exact (tangent plane -> ECEF -> geodetic by
Bowring's method iterated to convergence), not a flat-Earth approximation; tests/test_geodesy.py checks it
against pymap3d.
"""
from __future__ import annotations

import numpy as np

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
DEFAULT_ORIGIN = (47.397742, 8.545594, 488.0)     # lat deg, lon deg, height m


def geodetic_to_ecef(lat_deg, lon_deg, h_m) -> np.ndarray:
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.stack([(n + h_m) * np.cos(lat) * np.cos(lon), (n + h_m) * np.cos(lat) * np.sin(lon),
                     (n * (1.0 - WGS84_E2) + h_m) * np.sin(lat)], axis=-1)


def ecef_to_geodetic(xyz: np.ndarray) -> np.ndarray:
    """(n, 3) ECEF metres -> (n, 3) latitude deg, longitude deg, height m."""
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(6):      # converges to < 1e-12 rad in 3 for any height on Earth; 6 costs nothing
        n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        h = p / np.cos(lat) - n
        lat = np.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    h = p / np.cos(lat) - n
    return np.stack([np.degrees(lat), np.degrees(np.arctan2(y, x)), h], axis=-1)


def to_ned(vectors: np.ndarray, frame: str) -> np.ndarray:
    """Navigation-frame vectors (n, 3) as north, east, down."""
    if frame == "NED":
        return vectors
    return np.stack([vectors[:, 1], vectors[:, 0], -vectors[:, 2]], axis=-1)


def local_to_geodetic(position: np.ndarray, frame: str, origin=DEFAULT_ORIGIN) -> np.ndarray:
    """(n, 3) positions in the scene's ENU or NED frame at `origin` -> (n, 3) lat deg, lon deg, height m."""
    ned = to_ned(np.asarray(position, dtype=np.float64), frame)
    lat, lon = np.radians(origin[0]), np.radians(origin[1])
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    # columns: ECEF directions of north, east, down at the origin
    rotation = np.array([[-sl * co, -so, -cl * co], [-sl * so, co, -cl * so], [cl, 0.0, -sl]])
    ecef = geodetic_to_ecef(*origin) + ned @ rotation.T
    return ecef_to_geodetic(ecef)
