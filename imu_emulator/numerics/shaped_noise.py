"""Filtered (shaped) Gaussian noise for the vibration effect (imu_emulator.effects.vibration), one chunk of
samples at a time, and the Hermite interpolants that evaluate it between samples.

`fill_chunk` computes rows `chunk * size - 1 .. chunk * size + size - 1` of y_o = h_o * w (o = 0 .. orders - 1: the
quantity and its integrals, one FIR each) from the counter-based normals w_j = normal(key, j + taps): every row is
a pure function of (key, run sample), so the chunk a block lands in, and the block sizes, never change a value.
The kernel calls it when a sample's chunk differs from the one cached in its state; nothing is allocated (the
noise scratch is state too), so the kernel runs without numba's runtime.
"""
from __future__ import annotations

from imu_emulator.native.lazy import jit
from imu_emulator.numerics.counter_rng import normal


# No fastmath: reassociated sums would vectorize, but differently in the kernel's machine code and in numba's
# dispatcher (tests/runtime/test_native_kernel.py holds the two to the bit)
@jit
def fill_chunk(key, chunk, size, taps, orders, prm, h_base, state, out_base, scratch_base):
    """Rows r = 0 .. size of chunk `chunk` (run sample chunk * size - 1 + r) into
    state[out_base + r * orders + o], orders 2 or 3; taps of order o, reversed (oldest noise first), at
    prm[h_base + o * taps]."""
    first = chunk * size - taps      # the run sample of scratch[0]: taps - 1 samples before row 0
    for i in range(size + taps):
        state[scratch_base + i] = normal(key, first + i + taps)
    # the orders in one pass over the noise (read once per row, not once per order), two partial sums per order
    # in a fixed order: independent chains the CPU overlaps, nothing reassociated
    h0, h1, h2 = h_base, h_base + taps, h_base + 2 * taps
    for r in range(size + 1):
        w = scratch_base + r
        y = out_base + r * orders
        a0, a1, a2, b0, b1, b2 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        third = orders == 3      # invariant: LLVM takes the test out of the loop
        for m in range(0, taps - 1, 2):
            x, z = state[w + m], state[w + m + 1]
            a0 += prm[h0 + m] * x
            b0 += prm[h0 + m + 1] * z
            a1 += prm[h1 + m] * x
            b1 += prm[h1 + m + 1] * z
            if third:
                a2 += prm[h2 + m] * x
                b2 += prm[h2 + m + 1] * z
        if taps % 2:     # an odd tap count: the last tap has no partner
            x = state[w + taps - 1]
            a0, a1 = a0 + prm[h0 + taps - 1] * x, a1 + prm[h1 + taps - 1] * x
            if third:
                a2 += prm[h2 + taps - 1] * x
        state[y] = a0 + b0
        state[y + 1] = a1 + b1
        if third:
            state[y + 2] = a2 + b2


@jit
def hermite5(u, h, d0, v0, a0, d1, v1, a1):
    """The quintic through (d, d', d'') at u = 0 and 1 (step h in seconds): (d, d', d'') at u in [0, 1]."""
    c1, c2 = h * v0, 0.5 * h * h * a0
    big_a, big_b, big_c = d1 - d0 - c1 - c2, h * v1 - c1 - 2.0 * c2, h * h * a1 - 2.0 * c2
    c3 = 10.0 * big_a - 4.0 * big_b + 0.5 * big_c
    c4 = -15.0 * big_a + 7.0 * big_b - big_c
    c5 = 6.0 * big_a - 3.0 * big_b + 0.5 * big_c
    d = d0 + u * (c1 + u * (c2 + u * (c3 + u * (c4 + u * c5))))
    v = (c1 + u * (2.0 * c2 + u * (3.0 * c3 + u * (4.0 * c4 + u * 5.0 * c5)))) / h
    a = (2.0 * c2 + u * (6.0 * c3 + u * (12.0 * c4 + u * 20.0 * c5))) / (h * h)
    return d, v, a


@jit
def hermite3(u, h, x0, r0, x1, r1):
    """The cubic through (x, x') at u = 0 and 1 (step h in seconds): (x, x') at u in [0, 1]."""
    c1 = h * r0
    big_a, big_b = x1 - x0 - c1, h * r1 - c1
    c2, c3 = 3.0 * big_a - big_b, -2.0 * big_a + big_b
    return x0 + u * (c1 + u * (c2 + u * c3)), (c1 + u * (2.0 * c2 + u * 3.0 * c3)) / h
