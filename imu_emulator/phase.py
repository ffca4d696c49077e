"""sin and cos of a phase given in CYCLES, inlined into kernels.

The kernel already holds every periodic phase exactly as a fraction of a turn, so range reduction is
a subtraction of the nearest quarter turn (exact by Sterbenz's lemma) and the rest is two short
polynomials on [-pi/4, pi/4]: no libm calls, one shared reduction for both values, and accuracy
within a couple of units in the last place.
"""
import math

import numba

TWO_PI = 2.0 * math.pi
# Taylor coefficients to x^17 (sin) and x^16 (cos): truncation < 1e-17 on |x| <= pi/4
_S = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(1, 9))
_C = tuple((-1.0) ** k / math.factorial(2 * k) for k in range(1, 9))
S1, S2, S3, S4, S5, S6, S7, S8 = _S
C1, C2, C3, C4, C5, C6, C7, C8 = _C


@numba.njit(cache=True, inline="always")
def sincos_cycles(c):
    """(sin(2 pi c), cos(2 pi c)) for any finite c."""
    q = math.floor(4.0 * c + 0.5)
    x = TWO_PI * (c - 0.25 * q)
    x2 = x * x
    s = x + x * x2 * (S1 + x2 * (S2 + x2 * (S3 + x2 * (S4 + x2 * (S5 + x2 * (S6 + x2 * (S7 + x2 * S8)))))))
    co = 1.0 + x2 * (C1 + x2 * (C2 + x2 * (C3 + x2 * (C4 + x2 * (C5 + x2 * (C6 + x2 * (C7 + x2 * C8)))))))
    quadrant = int(q - 4.0 * math.floor(0.25 * q))
    if quadrant == 0:
        return s, co
    if quadrant == 1:
        return co, -s
    if quadrant == 2:
        return -s, -co
    return -co, s
