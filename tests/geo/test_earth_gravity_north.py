"""The north component of WGS-84 normal gravity off the ellipsoid against the gravitational potential.

Reference: the normal field's potential to degree 4 (GM and the WGS-84 normal ellipsoid's zonal coefficients
J2 = 1.082626683553e-3, J4 = -2.37091222e-6, TR8350.2 ch. 3) plus the centrifugal potential, differentiated by sympy, at points placed with pymap3d's WGS-84 geometry and projected on
pymap3d's local north. Degree 4 leaves a near-constant north residue on the ellipsoid itself (~1e-7 m/s^2,
the omitted J6 and up), so the slope dg_N/dh is compared: (g_N(h) - g_N(0)) / h.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_emulator.geo import wgs84

GM, A, OMEGA = 3.986004418e14, 6378137.0, 7.292115e-5
J2, J4 = 1.082626683553151e-3, -2.37091222e-6


@pytest.fixture(scope="module")
def potential_gradient():
    import sympy
    x, y, z = sympy.symbols("x y z", real=True)
    r = sympy.sqrt(x * x + y * y + z * z)
    s = z / r
    p2, p4 = (3 * s ** 2 - 1) / 2, (35 * s ** 4 - 30 * s ** 2 + 3) / 8
    v = GM / r * (1 - J2 * (A / r) ** 2 * p2 - J4 * (A / r) ** 4 * p4) + OMEGA ** 2 * (x * x + y * y) / 2
    return [sympy.lambdify((x, y, z), sympy.diff(v, c)) for c in (x, y, z)]


def _north_component(grad, lat, lon, h):
    pymap3d = pytest.importorskip("pymap3d")
    r = np.array(pymap3d.geodetic2ecef(lat, lon, h))
    north = np.array(pymap3d.ned2ecef(1.0, 0.0, 0.0, lat, lon, h)) - r
    return float(np.dot([g(*r) for g in grad], north))


@pytest.mark.parametrize("lat", [-70.0, -30.0, 10.0, 45.0, 80.0])
def test_north_gravity_slope_matches_the_potential(potential_gradient, lat):
    """dg_N/dh from the potential vs wgs84.normal_gravity_north / h, relative 3e-3: the formula is first order in
    h/R (1.6e-4 at the 1 km used) and Somigliana's dgamma/dL vs the degree-4 field differ by the omitted
    J6 terms and the e^4 terms of the first-order derivation (~1e-3, the size seen at all latitudes)."""
    h = 1000.0
    slope = (_north_component(potential_gradient, lat, 33.0, h) - _north_component(potential_gradient, lat, 33.0, 0.0)) / h
    ours = wgs84.normal_gravity_north(math.radians(lat), h) / h
    assert ours == pytest.approx(slope, rel=3e-3)
    assert slope < 0 if lat > 0 else slope > 0    # northern hemisphere: gravity leans south with height


def test_north_gravity_closed_form_of_groves():
    """Groves 2nd ed. eq. 2.142: g_N = -8.08e-9 h sin 2L m/s^2; his coefficient is rounded (and spherical), so
    within 1 %; exactly zero on the ellipsoid, at the equator and at the poles."""
    lat = np.radians([-60.0, 15.0, 45.0, 75.0])
    h = np.array([1e3, 1e4, 3e4, 5e3])
    np.testing.assert_allclose(wgs84.normal_gravity_north(lat, h), -8.08e-9 * h * np.sin(2 * lat), rtol=1e-2)
    assert wgs84.normal_gravity_north(0.7, 0.0) == 0.0 and wgs84.normal_gravity_north(0.0, 1e4) == 0.0
    assert abs(wgs84.normal_gravity_north(math.pi / 2, 1e4)) < 1e-20
