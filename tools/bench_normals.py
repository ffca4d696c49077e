"""Ways to draw the kernel's counter-based normals, timed against the one the kernel uses (issue 25).

    .venv/bin/python tools/bench_normals.py [--rounds 11] [--samples 262144]

A loop shaped like the full error model's draws: per sample, 6 random-walk and 6 white-noise normals of 12
streams at the run sample s, accumulated and stored. Variants, interleaved and timed in thread CPU time:
  - "scalar": counter_rng.normal called per draw, as the generated kernel does (LLVM inlines it here);
  - "chunk pass": every stream's normals of a 256-sample chunk first, in a loop LLVM vectorizes (with AVX-512:
    vpmullq for SplitMix64's products, gathers for the ziggurat tables), rare slow-path draws fixed after, then
    the per-sample loop reads them; its output is checked equal to the scalar one's;
  - "two per hash": both 32-bit halves of one SplitMix64 output, each a 128-layer ziggurat draw with a 24-bit
    mantissa (another stream, coarser numbers: timed only; its slow path is a stand-in).
Prints ns per sample (12 normals) min / median and each variant's per-round ratio to "scalar"; asserts nothing.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numba  # noqa: E402

from imu_emulator.native.lazy import realize  # noqa: E402
from imu_emulator.numerics import counter_rng as rng  # noqa: E402

realize()
normal, mix64 = rng.normal, rng.mix64
KI, WI = rng.KI, rng.WI
GAMMA, ONE, BIT, LOW8, LOW52 = rng._GAMMA, rng._ONE, rng._S1, rng._LOW8, rng._LOW52
CHUNK = 256
njit = numba.njit(nogil=True, error_model="numpy")


def _tables_128():
    """128-layer ziggurat (Marsaglia & Tsang 2000: r = 3.442619855899, v = 9.91256303526217e-3), 24-bit."""
    layers, r, v = 128, 3.442619855899, 9.91256303526217e-3
    f = lambda x: math.exp(-0.5 * x * x)  # noqa: E731
    edge = np.zeros(layers)
    edge[-1] = r
    for i in range(layers - 1, 1, -1):
        edge[i - 1] = math.sqrt(-2.0 * math.log(v / edge[i] + f(edge[i])))
    scale, base = 2.0 ** 24, v / f(r)
    k, w = np.empty(layers, np.uint64), np.empty(layers)
    k[0], w[0] = int(r / base * scale), base / scale
    for i in range(1, layers):
        w[i], k[i] = edge[i] / scale, int(edge[i - 1] / edge[i] * scale)
    return k, w


K2, W2 = _tables_128()
LOW32, LOW7, LOW24 = np.uint64(0xFFFFFFFF), np.uint64(0x7F), np.uint64(0xFFFFFF)
S7, S8, S32 = np.uint64(7), np.uint64(8), np.uint64(32)


@njit
def normal_pair(key, counter):
    r = mix64(key + (np.uint64(counter) + ONE) * GAMMA)
    a, b = r & LOW32, r >> S32
    ia, ib = int(a & LOW7), int(b & LOW7)
    ra, rb = (a >> S8) & LOW24, (b >> S8) & LOW24
    xa, xb = float(ra) * W2[ia], float(rb) * W2[ib]
    if (a >> S7) & BIT:
        xa = -xa
    if (b >> S7) & BIT:
        xb = -xb
    if ra < K2[ia] and rb < K2[ib]:
        return xa, xb
    return normal(key, counter), normal(~key, counter)     # stand-in for the pair's slow path


@njit
def _chunk(keys, s0, m, buf):
    for i in range(keys.shape[0]):
        key = keys[i]
        for jj in range(m):           # fast path only, branch-free: vectorizes
            r = mix64(key + (np.uint64(s0 + jj) + ONE) * GAMMA)
            idx = r & LOW8
            r = r >> S8
            rabs = (r >> BIT) & LOW52
            x = float(np.int64(rabs)) * WI[idx] * (1.0 - 2.0 * float(np.int64(r & BIT)))
            buf[i, jj] = x if rabs < KI[idx] else np.nan
        for jj in range(m):           # the 1 % outside a layer's rectangle
            if buf[i, jj] != buf[i, jj]:
                buf[i, jj] = normal(key, s0 + jj)


@njit
def scalar(keys, s0, n, sig, out):
    walk = np.zeros(6)
    for j in range(n):
        s = s0 + j
        for a in range(6):            # unrolled by LLVM: 12 independent draws per sample
            out[j, a] = walk[a] + sig[6 + a] * normal(keys[6 + a], s)
            walk[a] += sig[a] * normal(keys[a], s)


@njit
def chunk_pass(keys, s0, n, sig, out):
    walk = np.zeros(6)
    buf = np.empty((12, CHUNK))
    for c0 in range(0, n, CHUNK):
        m = min(CHUNK, n - c0)
        _chunk(keys, s0 + c0, m, buf)
        for jj in range(m):
            for a in range(6):
                out[c0 + jj, a] = walk[a] + sig[6 + a] * buf[6 + a, jj]
                walk[a] += sig[a] * buf[a, jj]


@njit
def two_per_hash(keys, s0, n, sig, out):
    walk = np.zeros(6)
    for j in range(n):
        s = s0 + j
        for a in range(6):
            w, x = normal_pair(keys[a], s)
            out[j, a] = walk[a] + sig[6 + a] * x
            walk[a] += sig[a] * w


def interleave(calls: dict, rounds: int, n: int) -> dict[str, list[float]]:
    """Thread CPU ns per sample of each call(round) of `calls` (n samples each), rounds 1.. interleaved."""
    times = {name: [] for name in calls}
    for r in range(1, rounds + 1):
        for name, call in calls.items():
            start = time.thread_time_ns()
            call(r)
            times[name].append((time.thread_time_ns() - start) / n)
    return times


def report(times: dict, base: str, title: str) -> None:
    """Print min / median and each variant's per-round ratio to the variant `base`."""
    ref = np.array(times[base])
    width = max(map(len, times))
    print(title)
    for name, values in times.items():
        v = np.array(values)
        print(f"  {name:{width}s} min {v.min():6.1f}  median {np.median(v):6.1f}   per-round ratio to {base}: "
              f"min {np.min(v / ref):.3f} median {np.median(v / ref):.3f} max {np.max(v / ref):.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=11)
    parser.add_argument("--samples", type=int, default=1 << 18)
    args = parser.parse_args()
    variants = {"scalar": scalar, "chunk pass": chunk_pass, "two per hash": two_per_hash}
    keys = np.array([rng.stream_key(1, 0, f"bench.{i}") for i in range(12)], dtype=np.uint64)
    sig, n = np.linspace(0.1, 1.2, 12), args.samples
    outs = {name: np.empty((n, 6)) for name in variants}
    for name, run in variants.items():       # compile, and check the chunk pass draws the same numbers
        run(keys, 5, n, sig, outs[name])
    assert np.array_equal(outs["chunk pass"], outs["scalar"])
    times = interleave({name: (lambda r, run=run, name=name: run(keys, 5 + r * n, n, sig, outs[name]))
                        for name, run in variants.items()}, args.rounds, n)
    report(times, "scalar", f"{n} samples x 12 normals, {args.rounds} interleaved rounds, thread CPU ns/sample")

if __name__ == "__main__":
    main()
