"""sin and cos of a phase given in CYCLES, inlined into kernels.

The kernel already holds every periodic phase exactly as a fraction of a turn, so range reduction is
a subtraction of the nearest quarter turn (exact by Sterbenz's lemma) and what is left is the fdlibm
kernel polynomials on [-pi/4, pi/4] (Sun's minimax fits, as carried by musl and glibc), evaluated in
musl's split form: shorter dependency chains than Horner, since numba does not fuse mul+add. No libm
calls, one shared reduction for both values, error within about one unit in the last place.
"""
import math

from imu_emulator.native.lazy import jit

TWO_PI = 2.0 * math.pi
S1 = -1.66666666666666324348e-01
S2 = 8.33333333332248946124e-03
S3 = -1.98412698298579493134e-04
S4 = 2.75573137070700676789e-06
S5 = -2.50507602534068634195e-08
S6 = 1.58969099521155010221e-10
C1 = 4.16666666666666019037e-02
C2 = -1.38888888888741095749e-03
C3 = 2.48015872894767294178e-05
C4 = -2.75573143513906633035e-07
C5 = 2.08757232129817482790e-09
C6 = -1.13596475577881948265e-11


@jit(cache=True, inline="always")
def sincos_cycles(c):
    """(sin(2 pi c), cos(2 pi c)) for any finite c."""
    q = math.floor(4.0 * c + 0.5)
    x = TWO_PI * (c - 0.25 * q)
    z = x * x
    w = z * z
    rs = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6)
    s = x + z * x * (S1 + z * rs)
    rc = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6))
    hz = 0.5 * z
    one_minus = 1.0 - hz
    co = one_minus + (((1.0 - one_minus) - hz) + z * rc)
    quadrant = int(q) & 3          # two's complement: also right for negative q
    # quadrants 0..3 give (s, co), (co, -s), (-s, -co), (-co, s): one swap and exact sign flips (x * -1.0 is -x,
    # signed zeros included) instead of four returns, so that a loop of these vectorizes (numba's four returns
    # became a jump table on the quadrant, and the phase loop ran scalar)
    a, b = s, co
    if quadrant & 1:
        a, b = co, s
    return a * (1.0 - 2.0 * (quadrant >> 1)), b * (1.0 - 2.0 * (((quadrant + 1) >> 1) & 1))
