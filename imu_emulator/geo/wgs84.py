"""WGS-84 constants (NIMA TR8350.2) and normal gravity, in numpy, for anything that needs the Earth.

The kernel's Earth effects (imu_emulator/effects/_earth.py) print the same formulas as straight-line code with
these constants as literals; imu_emulator.geo.frames converts coordinates with them.
"""
from __future__ import annotations

import numpy as np

A = 6378137.0                       # semi-major axis, m
F = 1.0 / 298.257223563             # flattening
E2 = F * (2.0 - F)                  # first eccentricity squared (6.69437999014e-3)
B = A * (1.0 - F)                   # semi-minor axis, m
EP2 = E2 / (1.0 - E2)               # second eccentricity squared
OMEGA_IE = 7.292115e-5              # Earth rotation rate, rad/s
GM = 3.986004418e14                 # m^3/s^2
GAMMA_E = 9.7803253359              # normal gravity at the equator, m/s^2
GAMMA_P = 9.8321849378              # normal gravity at the poles, m/s^2
K_SOMIGLIANA = B * GAMMA_P / (A * GAMMA_E) - 1.0      # 0.00193185265241
M_RATIO = OMEGA_IE ** 2 * A ** 2 * B / GM             # 0.00344978650684


def normal_gravity(lat_rad, h_m):
    """|g| of the normal field (gravitation plus centrifugal) at geodetic latitude and ellipsoidal height:
    Somigliana's formula with the height correction of TR8350.2 eq. 4-3. Exactly GAMMA_E at the equator and
    GAMMA_P at the poles on the ellipsoid."""
    s2 = np.sin(lat_rad) ** 2
    gamma0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / np.sqrt(1.0 - E2 * s2)
    return gamma0 * (1.0 - (2.0 / A) * (1.0 + F + M_RATIO - 2.0 * F * s2) * h_m + (3.0 / A ** 2) * h_m * h_m)


def radii(lat_rad):
    """(R_N meridian, R_E transverse) radii of curvature, m."""
    w2 = 1.0 - E2 * np.sin(lat_rad) ** 2
    return A * (1.0 - E2) / w2 ** 1.5, A / np.sqrt(w2)


#: g_N = -NORTH_GRAVITY_COEF * sin 2L * (K w^2 + (1 + K sin^2 L) E2 / 2) * h (see normal_gravity_north)
NORTH_GRAVITY_COEF = GAMMA_E / (A * (1.0 - E2))


def normal_gravity_north(lat_rad, h_m):
    """North component of normal gravity at height h above the ellipsoid, m/s^2 (zero on it, where gravity is
    along the ellipsoid normal). The field is curl-free, so dg_N/dh = dg_up/dx_N = -(1/R_N) dgamma_0/dL, to
    first order in h/R: g_N = -h/R_N dgamma_0/dL with Somigliana's gamma_0, i.e.
    -gamma_e sin 2L (k w^2 + (1 + k sin^2 L) e2/2) h / (a (1 - e2)), w^2 = 1 - e2 sin^2 L: about -8.14e-9 h sin 2L
    (Groves 2nd ed. eq. 2.142 rounds it to -8.08e-9 h sin 2L; tests/geo/test_earth_gravity_north.py checks it
    against the J2 + J4 gravitational potential)."""
    s = np.sin(lat_rad)
    s2 = s * s
    return (-NORTH_GRAVITY_COEF * 2.0 * s * np.cos(lat_rad)
            * (K_SOMIGLIANA * (1.0 - E2 * s2) + (1.0 + K_SOMIGLIANA * s2) * (0.5 * E2)) * h_m)
