"""Noisy sampled positions: how much acceleration error each derivative method leaves, and how the `smooth`
method's noise-derived smoothing compares with the best fixed smoothing a scan finds.

    python tools/smoothing_scan.py [--seconds 20]

Track: a 5 m circle at 0.2 Hz plus a 0.5 m vertical weave at 0.5 Hz, sampled at 10/50/100 Hz with Gaussian
noise of 1 mm and 1 cm (fixed seeds). For each: RMS of the acceleration error (interior 90 %, m/s^2) of
spline5c, spline3, smooth (s = (n + sqrt(2n)) sigma^2 from the stated sigma), and of the same quintic FITPACK
spline with s = c n sigma^2 for c on a grid from 0.25 to 30 (the scan); the best of the scan and the ratios.
Then the rounding floor: a 1 kHz circle at the origin and at 6.4e6 m, noise-free, spline5c and smooth.
With --ecef-floor, where the ECEF floor comes from (issue 14): the same 1 kHz circle at 6.4e6 m carries the
rounding of its input values (2.7e-10 m RMS, a uniform error over one ulp), which no subtraction of a reference
point afterwards can remove (SampledSeries already fits relative to the first sample); what is left is how well
a smoother separates 2.7e-10 m of white noise from a 5 m, 1 Hz circle. Printed: FITPACK with s = c n sigma^2
over c, least-squares splines of degree 5 to 11 on fixed uniform knots over their spacing, and what the rule
of imu_emulator/numerics/smoothing.py (used by spline5c and smooth) chooses.
With --timing, the cost of fitting `smooth`: one column of 15 k, 60 k and 240 k samples (100 Hz, 1 cm noise),
wall time and the CPU time of the fitting thread (FITPACK is single-threaded; on a shared machine the wall time
is mostly waiting).
Prints figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.interpolate import UnivariateSpline

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from imu_emulator.numerics.derivatives import SampledSeries  # noqa: E402

W_CIRCLE, W_WEAVE = 2 * np.pi * 0.2, 2 * np.pi * 0.5
SCAN = (0.25, 0.5, 0.8, 1.0, 1.2, 1.5, 2, 3, 5, 10, 30)


def track(t):
    pos = np.column_stack([5 * np.cos(W_CIRCLE * t), 5 * np.sin(W_CIRCLE * t), 0.5 * np.sin(W_WEAVE * t)])
    acc = np.column_stack([-5 * W_CIRCLE ** 2 * np.cos(W_CIRCLE * t), -5 * W_CIRCLE ** 2 * np.sin(W_CIRCLE * t),
                           -0.5 * W_WEAVE ** 2 * np.sin(W_WEAVE * t)])
    return pos, acc


def rms_error(t, got, truth):
    inner = (t > t[-1] * 0.05) & (t < t[-1] * 0.95)
    return float(np.sqrt(np.mean(np.sum((got - truth) ** 2, axis=1)[inner])))


def noisy_case(rate, sigma, seconds, seed=0):
    t = np.arange(int(seconds * rate) + 1) / rate
    pos, _ = track(t)
    noisy = pos + np.random.default_rng(seed).normal(0, sigma, pos.shape)
    t_out = np.linspace(0, t[-1], 4001)
    truth = track(t_out)[1]
    out = {}
    for method in ("spline5c", "spline3", "smooth"):
        start = time.perf_counter()
        series = SampledSeries(t, noisy, method, 2, noise=sigma)
        out[method] = (rms_error(t_out, series.evaluate(t_out, 2)[2], truth), time.perf_counter() - start)
    scan = {}
    for c in SCAN:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            fits = [UnivariateSpline(t, noisy[:, j] - noisy[0, j], k=5, s=c * t.size * sigma ** 2) for j in range(3)]
        scan[c] = rms_error(t_out, np.column_stack([f(t_out, nu=2) for f in fits]), truth)
    return out, scan


def ecef_case(offset, method):
    """Max interior |acceleration error| (m/s^2) of `method` on a noise-free 1 kHz circle (5 m, 1 Hz) at offset."""
    t = np.arange(5001) * 1e-3
    w = 2 * np.pi
    pos = np.column_stack([offset + 5 * np.cos(w * t), offset + 5 * np.sin(w * t), np.full_like(t, offset)])
    truth = np.column_stack([-5 * w * w * np.cos(w * t), -5 * w * w * np.sin(w * t), 0 * t])
    inner = (t > 0.25) & (t < 4.75)
    got = SampledSeries(t, pos, method, 2, noise=0.0).evaluate(t, 2)[2]
    return float(np.abs(got - truth)[inner].max())


def ecef_floor_scan():
    from scipy.interpolate import make_interp_spline, make_lsq_spline

    from imu_emulator.numerics.smoothing import DEGREE, choose_lsq_fit
    t = np.arange(5001) * 1e-3
    w = 2 * np.pi
    truth = -5 * w * w * np.cos(w * t)
    inner = (t > 0.25) & (t < 4.75)
    sigma = float(np.spacing(6.4e6)) / np.sqrt(12.0)
    print("\nECEF floor: 1 kHz circle at 6.4e6 m, max interior |acceleration error| (m/s^2)")
    print(f"  origin, spline5c / smooth: {ecef_case(0.0, 'spline5c'):.3g} / {ecef_case(0.0, 'smooth'):.3g}; "
          f"6.4e6 m: {ecef_case(6.4e6, 'spline5c'):.3g} / {ecef_case(6.4e6, 'smooth'):.3g} (with the rounding rule)")
    y = 6.4e6 + 5 * np.cos(w * t)
    y = y - y[0]
    line = []
    for c in (0.5, 1, 2, 5, 10):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            fit = UnivariateSpline(t, y, k=5, s=c * t.size * sigma ** 2)
        line.append(f"c={c:g} {np.abs(fit(t, 2) - truth)[inner].max():.2g}")
    print("  FITPACK quintic, s = c n sigma^2: " + ", ".join(line))
    interpolant = make_interp_spline(t, y, k=5)
    print(f"  quintic interpolant alone (no rule): {np.abs(interpolant(t, 2) - truth)[inner].max():.2g}")
    fit, chosen = choose_lsq_fit(t, y, sigma, lambda x: interpolant(x, 2))
    print(f"  the rule (degree {DEGREE}, Lepski): knot spacing {chosen * 1e3:.3g} ms, "
          f"{np.abs(fit(t, 2) - truth)[inner].max():.2g}")
    for k in (5, 7, 9, 11):
        line = []
        for spacing in (0.01, 0.02, 0.03, 0.045, 0.064, 0.09, 0.128):
            m = int(round(t[-1] / spacing))
            knots = np.r_[[0.0] * (k + 1), np.linspace(0, t[-1], m + 1)[1:-1], [t[-1]] * (k + 1)]
            fit = make_lsq_spline(t, y, knots, k=k)
            line.append(f"{spacing * 1e3:g} ms {np.abs(fit(t, 2) - truth)[inner].max():.2g}")
        print(f"  least squares, degree {k}, uniform knots: " + ", ".join(line))


def timing(sizes=(15_000, 60_000, 240_000)):
    print("\nsmooth fit of one column, 100 Hz, 1 cm noise: wall / thread CPU (s), knots FITPACK placed")
    for n in sizes:
        t = np.arange(n) * 0.01
        y = 5 * np.cos(W_CIRCLE * t)[:, None] + np.random.default_rng(0).normal(0, 0.01, (n, 1))
        wall, cpu = time.perf_counter(), time.thread_time()
        series = SampledSeries(t, y, "smooth", 2, noise=0.01)
        wall, cpu = time.perf_counter() - wall, time.thread_time() - cpu
        print(f"  {n} samples: {wall:.2f} / {cpu:.2f} s, {len(series._fit.splines[0].get_knots())} knots")
    print("spline5c with the rounding rule, 1 kHz circle at 6.4e6 m, three columns: wall / thread CPU (s); "
          "the same at the origin (the rule's check only)")
    for n in (60_000, 600_000):
        t = np.arange(n) * 1e-3
        line = []
        for offset in (6.4e6, 0.0):
            pos = offset + 5 * np.column_stack([np.cos(2 * np.pi * t), np.sin(2 * np.pi * t), np.cos(np.pi * t)])
            wall, cpu = time.perf_counter(), time.thread_time()
            SampledSeries(t, pos, "spline5c", 3)
            line.append(f"{time.perf_counter() - wall:.2f} / {time.thread_time() - cpu:.2f}")
        print(f"  {n} samples: {line[0]} s; at the origin {line[1]} s")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--timing", action="store_true", help="only the fitting cost (see above)")
    parser.add_argument("--ecef-floor", action="store_true", help="only the ECEF floor study (see above)")
    args = parser.parse_args(argv)
    if args.timing or args.ecef_floor:
        if args.ecef_floor:
            ecef_floor_scan()
        if args.timing:
            timing()
        return
    print("acceleration error, RMS over the interior (m/s^2); smooth's fit time in s")
    print("| rate | noise | spline3 | spline5c | smooth | fit s | best fixed (c) | smooth / best | spline5c / smooth |")
    print("|---|---|---|---|---|---|---|---|---|")
    scans = []
    for sigma in (1e-3, 1e-2):
        for rate in (10, 50, 100):
            out, scan = noisy_case(rate, sigma, args.seconds)
            best_c = min(scan, key=scan.get)
            scans.append((rate, sigma, scan))
            print(f"| {rate} Hz | {sigma * 1e3:g} mm | {out['spline3'][0]:.3g} | {out['spline5c'][0]:.3g} | "
                  f"{out['smooth'][0]:.3g} | {out['smooth'][1]:.2f} | {scan[best_c]:.3g} ({best_c:g}) | "
                  f"{out['smooth'][0] / scan[best_c]:.2f} | {out['spline5c'][0] / out['smooth'][0]:.0f} |")
    print("\nscan: s = c n sigma^2, RMS acceleration error (m/s^2)")
    print("| rate | noise | " + " | ".join(f"c={c:g}" for c in SCAN) + " |")
    print("|---|---|" + "---|" * len(SCAN))
    for rate, sigma, scan in scans:
        print(f"| {rate} Hz | {sigma * 1e3:g} mm | " + " | ".join(f"{scan[c]:.2g}" for c in SCAN) + " |")
    print("\nrounding floor, 1 kHz circle, max interior |acceleration error| (m/s^2)")
    for offset in (0.0, 6.4e6):
        print(f"  offset {offset:g} m: spline5c {ecef_case(offset, 'spline5c'):.3g}, "
              f"smooth {ecef_case(offset, 'smooth'):.3g}")


if __name__ == "__main__":
    main()
