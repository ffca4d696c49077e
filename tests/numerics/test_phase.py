"""sincos_cycles (imu_emulator.numerics.phase) against mpmath at 50 digits: every quadrant, its edges, signed zeros."""
import math

import mpmath
import numpy as np
import pytest

from imu_emulator.native import lazy
from imu_emulator.numerics import phase


@pytest.fixture(scope="module")
def sincos_many():
    lazy.realize()
    import numba
    f = phase.sincos_cycles

    @numba.njit
    def many(cs):
        out = np.empty((2, cs.size))
        for i in range(cs.size):     # a loop of it, as the kernels' phase stage calls it
            out[0, i], out[1, i] = f(cs[i])
        return out
    return many


def _phases():
    rng = np.random.default_rng(20261122)
    quarter_edges = np.arange(-12, 13) / 8.0                  # exact quadrant boundaries and their midpoints
    near_edges = np.concatenate([np.nextafter(quarter_edges, np.inf), np.nextafter(quarter_edges, -np.inf)])
    return np.concatenate([rng.uniform(-1.0, 1.0, 4000), rng.uniform(-1e4, 1e4, 2000), quarter_edges, near_edges,
                           [0.0, -0.0, 1e-300, -1e-300, 0.125 + 1e-17]])


def test_sincos_cycles_within_its_error_bound_of_mpmath_in_every_quadrant(sincos_many):
    cs = _phases()
    got = sincos_many(cs)
    mpmath.mp.dps = 50
    for c, s, co in zip(cs, got[0], got[1]):
        if float(4 * c).is_integer():
            continue    # exact quarter turns: exactly 0 and +-1, the next test (mpmath's pi leaves 1e-50 there)
        angle = 2 * mpmath.pi * mpmath.mpf(float(c))     # the double c exactly, in cycles
        for value, exact in ((s, mpmath.sin(angle)), (co, mpmath.cos(angle))):
            # fdlibm's kernels on [-pi/4, pi/4] are within 1 ulp; the reduced angle x = 2 pi (c - q/4) carries two
            # roundings (2 pi as a double, the product): relative 2^-52, which moves sin x by |x cos x| 2^-52 and cos x
            # by |x sin x| 2^-52, at most 1.11 ulp of the result on |x| <= pi/4 (x / sin x <= 1.11) -> 2.11 ulp
            ulp = math.ulp(max(abs(float(exact)), 2.0 ** -1074))
            assert abs(mpmath.mpf(float(value)) - exact) <= 2.11 * ulp + mpmath.mpf(2.0 ** -1074), (c, value, exact)


def test_sincos_cycles_quadrant_signs_and_exact_quarter_turns(sincos_many):
    # sin(2 pi c), cos(2 pi c) at exact quarter turns: the reduced angle is exactly 0, so the polynomial gives
    # exactly (0, 1) and the quadrant alone sets which output holds 1 and its sign
    cs = np.array([0.0, 0.25, 0.5, 0.75, 1.0, -0.25, -0.5, -0.75, 3.25])
    s, co = sincos_many(cs)
    np.testing.assert_array_equal(np.abs(s), [0, 1, 0, 1, 0, 1, 0, 1, 1])
    np.testing.assert_array_equal(np.abs(co), [1, 0, 1, 0, 1, 0, 1, 0, 0])
    assert s[1] == s[8] == 1.0 and s[3] == s[5] == -1.0 and s[7] == 1.0        # 1/4, 13/4, -3/4 turns: +1
    assert co[0] == co[4] == 1.0 and co[2] == co[6] == -1.0
