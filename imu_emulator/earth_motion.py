"""ECI and geodetic trajectories as ECEF expressions, so the kernel's Earth prelude (effects/_earth.py) sees one frame.

ECI here has its axes on ECEF's at scene time t = 0 and turns by the Earth rotation angle theta = omega_ie t
about z (no precession, nutation or polar motion: the issue's ECI). The rotation is applied to the sympy
expressions, so velocity and acceleration are differentiated exactly and sin/cos(omega_ie t) take the motion's
exact phase reduction (imu_emulator.motion): t far from zero stays exact.
"""
from __future__ import annotations


def eci_to_ecef(xyz, t):
    """[x, y, z] sympy expressions of t in ECI -> the same point in ECEF: r_e = R_z(-theta) r_i."""
    import sympy
    # omega_ie as the exact decimal WGS-84 states, so the phase constants are formed from it exactly
    theta = sympy.Rational("7.292115e-5") * t
    c, s = sympy.cos(theta), sympy.sin(theta)
    x, y, z = xyz
    return [c * x + s * y, -s * x + c * y, z]


def geodetic_to_ecef(llh):
    """[lat_deg, lon_deg, height_m] sympy expressions of t -> WGS-84 ECEF x, y, z (closed form; sympy
    differentiates it exactly, and sin/cos of a latitude or longitude linear in t take the exact phase
    reduction)."""
    import sympy

    from imu_emulator import wgs84
    lat, lon = (sympy.pi / 180 * e for e in llh[:2])
    h = llh[2]
    a, e2 = sympy.Float(wgs84.A, 30), sympy.Float(wgs84.E2, 30)
    n = a / sympy.sqrt(1 - e2 * sympy.sin(lat) ** 2)
    return [(n + h) * sympy.cos(lat) * sympy.cos(lon), (n + h) * sympy.cos(lat) * sympy.sin(lon),
            (n * (1 - e2) + h) * sympy.sin(lat)]
