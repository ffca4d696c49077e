"""Filtered (shaped) Gaussian noise for the vibration effect (imu_emulator.effects.vibration), one chunk of
samples at a time, and the Hermite interpolants that evaluate it between samples.

`fill_chunk` computes rows `chunk * size - 1 .. chunk * size + size - 1` of y_o = h_o * w (o = 0 .. orders - 1: the
quantity and its integrals, one FIR of `taps` taps each) from the counter-based normals w_j = normal(key, j + taps):
every row is a pure function of (key, run sample), so the chunk a block lands in, and the block sizes, never
change a value. It convolves by FFT (overlap-save): the chunk's n = size + taps normals transformed once, times
each filter's spectrum, transformed back two orders at a time (the real and imaginary parts of one transform),
so a chunk costs three (two) transforms of n log2 n operations in place of orders x taps multiply-adds per
row (`fill_chunk_direct`, the direct form, is cheaper for short filters and fills the same rows to rounding).
The kernel calls it when a sample's chunk differs from the one cached in its state; nothing is allocated (the
transforms' scratch is state too, spectra and twiddles are parameters), so the kernel runs without numba's runtime.
"""
from __future__ import annotations

import numpy as np

from imu_emulator.native.lazy import jit
from imu_emulator.numerics.counter_rng import normal

#: the smallest transform: a chunk of n - taps rows costs about 3 n / 2 log2 n butterflies, so the per-row cost
#: falls while n - taps grows against n (at 256 taps, 768 rows of a 1024-point transform take 0.74 times the
#: butterflies per row of 256 rows of a 512-point one)
MIN_FFT = 1024


def fft_size(taps: int) -> int:
    """The transform length for filters of `taps` taps: a power of two, at least 2 taps (a chunk at least as long
    as the filter; longer would save at most a third of the butterflies per row, and the state grows with n) and
    MIN_FFT."""
    return max(MIN_FFT, 1 << (2 * taps - 1).bit_length())


def twiddles(n: int) -> list[float]:
    """cos(2 pi k / n) for k < n / 2, then sin(2 pi k / n): the table `fft` reads."""
    angle = 2.0 * np.pi * np.arange(n // 2) / n
    return [float(x) for x in np.concatenate([np.cos(angle), np.sin(angle)])]


def correlation_spectrum(taps_reversed, n: int) -> list[float]:
    """The spectrum (real parts, then imaginary parts, n each) that `fill_chunk` multiplies a chunk's transform by
    for the FIR y_r = sum_m taps_reversed[m] w_(r + m), with the inverse transform's 1 / n folded in: the DFT of
    g_j = taps_reversed[-j mod n] (circular convolution with g is that correlation where it does not wrap)."""
    h = np.asarray(taps_reversed, dtype=float)
    g = np.zeros(n)
    g[0] = h[0]
    g[n - h.size + 1:] = h[:0:-1]
    spectrum = np.fft.fft(g) / n
    return [float(x) for x in np.concatenate([spectrum.real, spectrum.imag])]


# No fastmath (here and below): reassociated or contracted arithmetic could compile differently in the kernel's
# machine code and in numba's dispatcher (tests/runtime/test_native_kernel.py holds the two to the bit)
@jit
def fft(state, re, im, n, prm, tw):
    """In place, the DFT X_k = sum_j x_j exp(-2 pi i j k / n) of the n complex values (state[re + j],
    state[im + j]), n a power of two (decimation in time: radix 4, after one radix-2 pass when log2 n is odd;
    radix 4 takes 1.6 times less time than radix 2 here); twiddles at prm[tw] (`twiddles` of n)."""
    j = 0
    for i in range(1, n):        # bit-reversed order
        bit = n >> 1
        while j & bit:
            j ^= bit
            bit >>= 1
        j |= bit
        if i < j:
            state[re + i], state[re + j] = state[re + j], state[re + i]
            state[im + i], state[im + j] = state[im + j], state[im + i]
    half, span, bits = n // 2, 1, 0
    while (1 << bits) < n:
        bits += 1
    if bits % 2:                 # a radix-2 pass, whose twiddle is 1
        for i in range(0, n, 2):
            ar, ai, br, bi = state[re + i], state[im + i], state[re + i + 1], state[im + i + 1]
            state[re + i], state[im + i], state[re + i + 1], state[im + i + 1] = ar + br, ai + bi, ar - br, ai - bi
        span = 2
    while span < n:              # four transforms of length span into one of 4 span
        step = half // (2 * span)      # w^k = exp(-2 pi i k / (4 span)) is entry k step of the table
        for k in range(span):
            c1, s1 = prm[tw + k * step], prm[tw + half + k * step]
            c2, s2 = prm[tw + 2 * k * step], prm[tw + half + 2 * k * step]
            k3 = 3 * k * step
            if k3 < half:
                c3, s3 = prm[tw + k3], prm[tw + half + k3]
            else:                # exp(-2 pi i (m + n / 2) / n) = -exp(-2 pi i m / n)
                c3, s3 = -prm[tw + k3 - half], -prm[tw + k3]
            for a in range(k, n, 4 * span):
                # bit-reversed order: the transforms of the samples 0, 2, 1, 3 mod 4 at a, a + span, ...
                b, c, d = a + span, a + 2 * span, a + 3 * span
                x0r, x0i, x2r, x2i = state[re + a], state[im + a], state[re + b], state[im + b]
                x1r, x1i, x3r, x3i = state[re + c], state[im + c], state[re + d], state[im + d]
                t1r, t1i = c1 * x1r + s1 * x1i, c1 * x1i - s1 * x1r       # x1 w^k (w = c - i s)
                t2r, t2i = c2 * x2r + s2 * x2i, c2 * x2i - s2 * x2r       # x2 w^2k
                t3r, t3i = c3 * x3r + s3 * x3i, c3 * x3i - s3 * x3r       # x3 w^3k
                pr, pi, qr, qi = x0r + t2r, x0i + t2i, x0r - t2r, x0i - t2i
                ur, ui, vr, vi = t1r + t3r, t1i + t3i, t1r - t3r, t1i - t3i
                state[re + a], state[im + a] = pr + ur, pi + ui          # X_k
                state[re + c], state[im + c] = pr - ur, pi - ui          # X_k+2span
                state[re + b], state[im + b] = qr + vi, qi - vr          # X_k+span = q - i v
                state[re + d], state[im + d] = qr - vi, qi + vr          # X_k+3span = q + i v
        span *= 4


@jit
def fill_chunk(key, chunk, size, taps, orders, prm, spectra, tw, state, out_base, scratch_base):
    """Rows r = 0 .. size of chunk `chunk` (run sample chunk * size - 1 + r) into state[out_base + r * orders + o],
    orders 2 or 3; the spectrum of order o (`correlation_spectrum`, n = size + taps) at prm[spectra + 2 n o];
    4 n slots of scratch."""
    n = size + taps
    xr, xi, yr, yi = scratch_base, scratch_base + n, scratch_base + 2 * n, scratch_base + 3 * n
    for i in range(n):     # scratch i: run sample chunk * size - taps + i, taps - 1 samples before row 0
        state[xr + i] = normal(key, chunk * size + i)
        state[xi + i] = 0.0
    fft(state, xr, xi, n, prm, tw)
    for o in range(0, orders, 2):
        # Y = X G_o + i X G_o+1 (y_o, y_o+1 real: the real and imaginary parts of Y's inverse), inverted as
        # conj(DFT(conj(Y))) (1 / n is in the spectra): one transform routine, exact negations
        pair = o + 1 < orders
        g, h = spectra + 2 * n * o, spectra + 2 * n * (o + 1)
        for k in range(n):
            ar, ai = state[xr + k], state[xi + k]
            pr, pi = ar * prm[g + k] - ai * prm[g + n + k], ar * prm[g + n + k] + ai * prm[g + k]
            if pair:
                qr, qi = ar * prm[h + k] - ai * prm[h + n + k], ar * prm[h + n + k] + ai * prm[h + k]
                state[yr + k], state[yi + k] = pr - qi, -(pi + qr)
            else:
                state[yr + k], state[yi + k] = pr, -pi
        fft(state, yr, yi, n, prm, tw)
        for r in range(size + 1):
            state[out_base + r * orders + o] = state[yr + r]
            if pair:
                state[out_base + r * orders + o + 1] = -state[yi + r]


@jit
def fill_chunk_direct(key, chunk, size, taps, orders, prm, h_base, state, out_base, scratch_base):
    """`fill_chunk` by the direct-form FIR, cheaper for short filters (vibration.DIRECT_TAPS): taps of order o,
    reversed (oldest noise first), at prm[h_base + o * taps]; size + taps slots of scratch."""
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
