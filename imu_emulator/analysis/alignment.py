"""Relative orientation and time offset of two IMUs on one rigid body, from their own records (seed 003).

Conventions (the seed's matrix): C maps B's measurements into A's frame, ω_A = C·ω_B, so with A mounted like
the body C is B's mounting matrix (its Euler angles are B's `mounting_rpy_deg`). Each sensor has its own
clock: for one physical instant, B's stamp minus A's stamp is

    t_B − t_A = Δ + d·(t_A − t_ref)          (Δ = time_offset_s at t_ref, d = drift, reported in ppm)

with t_ref the middle of the overlap on A's clock; d is the rate of change of t_B − t_A. If B samples at
t_k = k·Δt·(1 + 50e-6) while its stamps say k·Δt (the clock of specs/sensor-errors.md at +50 ppm) and A's
clock is true, B's stamps fall behind: d = −50 ppm.

Pipeline:
1. coarse Δ from the cross-correlation of the rotation-invariant |ω| of both sensors (both resampled to the
   finer of the two sample periods), refined to sub-sample precision by a parabola through the peak; with
   drift, the same on each half of the overlap gives the starting slope;
2. the lower-rate sensor's stamps are the common base; the other sensor is a quintic interpolating spline
   evaluated at the mapped stamps (an error of order (ωh)^6: far below any sensor's noise);
3. C from the centred gyro pairs by SVD (Kabsch/Wahba): the lever arm does not enter the gyros;
4. Levenberg–Marquardt (MINPACK through scipy) over a rotation vector θ (C = exp([θ]×)·C₀, re-centred until
   θ vanishes, so the Euler angles never meet a singularity inside the fit), Δ (and d) and the gyro bias
   difference b_g, on r_g = ω_A − C·ω_B − b_g; with the lever arm, also on
   r_f = C·f_B − f_A − ([α_A]× + [ω_A]×²)·l − b_f, l being B's position relative to A in A's frame;
   each residual group weighted by its own RMS (one re-weighting pass);
5. covariance (JᵀJ)⁻¹ of the whitened final Jacobian, i.e. scaled by the residual variance, and the 1σ of
   every estimate; then the observability verdict (`_verdicts`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import make_interp_spline, make_lsq_spline
from scipy.signal import correlate, correlation_lags, savgol_filter
from scipy.spatial.transform import Rotation

from imu_emulator.errors import DataError
from imu_emulator.analysis.imulog import ImuLog

MIN_SAMPLES = 32            # per record and in the overlap: a quintic spline and a dozen parameters need room
MIN_OVERLAP_FRACTION = 0.5  # a candidate offset must leave half of the shorter record overlapping
MIN_RATE_CHANGE = 0.01      # rad/s RMS of |ω| about its mean: less is too little motion to find a time offset
LOWPASS_ORDER = 4
REGULAR_STAMPS = 0.01       # low-pass only records whose sample steps stay within 1 % of their median
LOWPASS_EDGE = 10.0         # after the low-pass, drop this many 1/f_c seconds at each end (start-up transients)
MIN_CORRELATION = 0.8       # of |ω_A| and |ω_B| at the coarse offset; one body's motion gives ~1 unless noise
                            # dominates the rate changes, where the offset could not be trusted anyway
# Noise floors for the observability verdict only: perfect (simulated) data would otherwise make a weakly
# excited direction look certain. Both sit below the white noise of any MEMS part per sample at 100 Hz
# (BMI088 gyro: 0.014 °/s/√Hz -> 2.4e-3 rad/s; accel 160 µg/√Hz -> 1.6e-2 m/s²).
GYRO_FLOOR = 1e-4           # rad/s
ACCEL_FLOOR = 1e-3          # m/s²


@dataclass(frozen=True)
class AlignOptions:
    lever_arm: bool = False         # add the accelerometer residual, the lever arm and the accel bias difference
    drift: bool = False             # estimate a linear clock drift
    max_offset_s: float | None = None   # search |Δ| up to this; default half the shorter record
    # Window of the Savitzky–Golay derivative giving α for the lever-arm term: wider windows let less gyro
    # noise into α (noise in a regressor shrinks the lever arm: 2.8 mm at 0.05 s, 0.4 mm at 0.1 s with
    # BMI088-class noise, tools/bench_align.py case w); motion much faster than 1/window would be smoothed.
    alpha_span_s: float = 0.1
    # Zero-phase low-pass (Butterworth, order 4, forward and backward) of both records before the fit, at this
    # fraction of the lower-rate record's Nyquist frequency; None: off. Interpolating white noise gives it a
    # variance that depends on where between two samples the interpolation falls (least midway), so the
    # least-squares fit is pulled toward half-sample offsets, and with a drift sweeping that position through
    # the run the drift is biased: 1.1–1.3 ppm (2.6–3σ) with BMI088-class noise in tools/bench_align.py case d,
    # 0.06–0.3 ppm with the low-pass. Noise limited to half the Nyquist band interpolates evenly.
    lowpass: float | None = 0.5
    # Verdict thresholds (see _verdicts): a direction is unobservable when its 1σ (with the noise floors)
    # exceeds the maximum, or when it is excited less than min_excitation times the best direction of its kind.
    min_excitation: float = 0.1
    max_sigma_deg: float = 0.5
    max_sigma_time_s: float = 1e-3
    max_sigma_drift_ppm: float = 10.0
    max_sigma_lever_m: float = 0.01


@dataclass
class Alignment:
    C: np.ndarray                       # B's frame -> A's frame
    quaternion_wxyz: np.ndarray         # of C, scalar first, w >= 0
    euler_deg: np.ndarray               # roll, pitch, yaw of C (z-y-x), degrees
    time_offset_s: float                # t_B - t_A at time_reference_s (A's clock)
    time_reference_s: float
    drift_ppm: float | None
    gyro_bias_diff: np.ndarray          # b_A - C·b_B, rad/s, A's frame
    accel_bias_diff: np.ndarray | None  # C·b_B - b_A, m/s², A's frame (with the lever arm)
    lever_arm_m: np.ndarray | None      # B's position relative to A, A's frame
    sigma: dict                         # 1σ of each estimate, same keys and units
    observable: dict                    # True/False per reported quantity
    reasons: list[str]                  # why something is unobservable, one sentence each
    notes: list[str]                    # other facts a user should know (gimbal lock, iterations)
    residual_rms: dict                  # gyro rad/s, accel m/s²
    n_rows: int                         # samples in the common base
    overlap_s: float
    coarse_offset_s: float | None       # from the cross-correlation; None: too little motion to search
    base: str                           # which sensor's stamps are the common base: "A" or "B"
    extra: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        def clean(x):
            if isinstance(x, dict):
                return {k: clean(v) for k, v in x.items()}
            if isinstance(x, (list, tuple, np.ndarray)):
                return [clean(v) for v in np.asarray(x, dtype=object).tolist()]
            if isinstance(x, (float, np.floating)):
                return float(x) if math.isfinite(x) else None
            return x.item() if isinstance(x, np.generic) else x
        return clean({
            "quaternion_wxyz": self.quaternion_wxyz, "dcm": self.C, "euler_deg": self.euler_deg,
            "time_offset_s": self.time_offset_s, "time_reference_s": self.time_reference_s,
            "clock_drift_ppm": self.drift_ppm, "gyro_bias_diff_rad_s": self.gyro_bias_diff,
            "accel_bias_diff_mps2": self.accel_bias_diff, "lever_arm_m": self.lever_arm_m,
            "sigma": self.sigma, "observable": self.observable, "unobservable_reasons": self.reasons,
            "notes": self.notes, "residual_rms": self.residual_rms, "samples": self.n_rows,
            "overlap_s": self.overlap_s, "coarse_time_offset_s": self.coarse_offset_s, "base": self.base})


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) with skew(v) @ x = v × x."""
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def kabsch(a: np.ndarray, b: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """The proper rotation C minimising Σ w·|a_i − C·b_i|² (SVD; the sign fix keeps det C = +1)."""
    w = np.ones(len(a)) if weights is None else weights
    H = (a * w[:, None]).T @ b
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0])
    return U @ D @ Vt


def _uniform(t: np.ndarray, x: np.ndarray, h: float) -> tuple[float, np.ndarray]:
    grid = t[0] + h * np.arange(int(np.floor((t[-1] - t[0]) / h)) + 1)
    return float(t[0]), np.interp(grid, t, x)


def coarse_time_offset(ta, wa, tb, wb, lo: float, hi: float, min_overlap_s: float, where: str) -> float | None:
    """Δ = t_B − t_A maximising the normalised cross-correlation of the rate magnitudes wa(ta), wb(tb),
    searched in [lo, hi] among shifts that overlap by at least min_overlap_s; sub-sample by a parabola.
    None when either rate magnitude changes by less than MIN_RATE_CHANGE RMS (nothing to correlate)."""
    h = min(np.median(np.diff(ta)), np.median(np.diff(tb)))
    a0, xa = _uniform(ta, wa, h)
    b0, xb = _uniform(tb, wb, h)
    xa, xb = xa - xa.mean(), xb - xb.mean()
    if min(_rms(xa), _rms(xb)) < MIN_RATE_CHANGE:
        return None
    corr = correlate(xb, xa, mode="full", method="fft")
    lags = correlation_lags(len(xb), len(xa), mode="full")     # xb[n + lag] pairs with xa[n]
    # Energies of the overlapping parts, for a normalisation that does not favour long overlaps.
    ca, cb = np.concatenate([[0], np.cumsum(xa ** 2)]), np.concatenate([[0], np.cumsum(xb ** 2)])
    n_a, n_b = len(xa), len(xb)
    start_a = np.clip(-lags, 0, n_a)
    stop_a = np.clip(n_b - lags, 0, n_a)
    count = stop_a - start_a
    ea = ca[stop_a] - ca[start_a]
    eb = cb[np.clip(stop_a + lags, 0, n_b)] - cb[np.clip(start_a + lags, 0, n_b)]
    delta = (b0 - a0) + lags * h
    ok = (count * h >= min_overlap_s) & (delta >= lo) & (delta <= hi) & (ea > 0) & (eb > 0)
    if not ok.any():
        raise DataError(f"{where}: no time offset within [{lo:.6g}, {hi:.6g}] s leaves {min_overlap_s:.6g} s "
                        "of the two records overlapping with any change of angular rate in it")
    score = np.full(len(corr), -np.inf)
    score[ok] = corr[ok] / np.sqrt(ea[ok] * eb[ok])
    i = int(np.argmax(score))
    if score[i] < MIN_CORRELATION:
        raise DataError(f"{where}: the angular rate magnitudes correlate at most {score[i]:.2f} at the time "
                        f"offsets searched ([{lo:.6g}, {hi:.6g}] s): the records do not show the same motion there;"
                        " if the offset lies beyond, widen the search with --max-offset-s")
    if not (0 < i < len(score) - 1 and ok[i - 1] and ok[i + 1]):
        raise DataError(f"{where}: the best match of the angular rates lies at the edge of the offsets searched "
                        f"({delta[i]:.6g} s in [{lo:.6g}, {hi:.6g}] s with at least {min_overlap_s:.6g} s of overlap):"
                        " the true offset may lie beyond; widen the search with --max-offset-s if the records "
                        "overlap enough")
    shift = 0.0
    den = score[i - 1] - 2 * score[i] + score[i + 1]
    if den < 0:
        shift = 0.5 * (score[i - 1] - score[i + 1]) / den
    return float(delta[i] + shift * h)


def _derivative_spline(t: np.ndarray, y: np.ndarray, span_s: float):
    """dy/dt as a spline: a Savitzky–Golay derivative (degree 5 over about span_s) on a uniform grid, for
    α = dω/dt, where differentiating the interpolating spline would amplify sensor noise by 1/h and so bias
    the lever arm (noise in a regressor); exact for polynomials of degree 5 over the window."""
    h = float(np.median(np.diff(t)))
    grid = t[0] + h * np.arange(int(np.floor((t[-1] - t[0]) / h + 1e-9)) + 1)
    uniform = len(grid) == len(t) and np.allclose(grid, t, rtol=0, atol=1e-9 * h)
    values = y if uniform else make_interp_spline(t, y, k=5)(grid)
    window = max(7, 2 * int(round(span_s / h / 2)) + 1)
    if window > len(grid):
        return make_interp_spline(t, y, k=5).derivative()
    alpha = savgol_filter(values, window, 5, deriv=1, delta=h, axis=0, mode="interp")
    return make_interp_spline(grid, alpha, k=5)


class _Problem:
    """Residuals and Jacobian on the common base. Parameter vector: θ (3, rad), Δ (s), [d (ppm)], b_g (3),
    [b_f (3), l (3)]."""

    def __init__(self, a: ImuLog, b: ImuLog, base_is_a: bool, delta0: float, drift0: float, t_ref: float,
                 with_accel: bool, with_drift: bool, alpha_span_s: float):
        self.base_is_a, self.t_ref, self.with_accel, self.with_drift = base_is_a, t_ref, with_accel, with_drift
        base, other = (a, b) if base_is_a else (b, a)
        self.other_t = other.t
        margin = 3 * max(np.median(np.diff(a.t)), np.median(np.diff(b.t)))
        mapped = self._map(base.t, delta0, drift0)
        rows = (mapped >= other.t[0] + margin) & (mapped <= other.t[-1] - margin)
        self.t = base.t[rows]
        self.base_gyro, self.base_accel = base.gyro[rows], base.accel[rows]
        self.spline = make_interp_spline(other.t, np.hstack([other.gyro, other.accel]), k=5)
        self.dspline = self.spline.derivative()
        self.alpha_a = _derivative_spline(a.t, a.gyro, alpha_span_s) if with_accel else None
        self.alpha_base = self.alpha_a(self.t) if with_accel and base_is_a else None
        self.dalpha = self.alpha_a.derivative() if with_accel and not base_is_a else None
        names = ["rot"] * 3 + ["dt"] + (["drift"] if with_drift else []) + ["bg"] * 3
        if with_accel:
            names += ["bf"] * 3 + ["lever"] * 3
        self.names = names
        self.index = {k: slice(names.index(k), len(names) - names[::-1].index(k)) for k in dict.fromkeys(names)}
        self.scale = np.array([1.0, 1.0])    # residual weights 1/σ of gyro and accel groups
        self.noise_bandwidth = 1.0           # fraction of white noise variance the low-pass passes (base grid)

    def __len__(self):
        return len(self.t)

    def _map(self, t_base, delta, drift_ppm):
        d = drift_ppm * 1e-6
        if self.base_is_a:
            return t_base + delta + d * (t_base - self.t_ref)
        return self.t_ref + (t_base - delta - self.t_ref) / (1.0 + d)

    def sides(self, delta, drift_ppm):
        """ω_A, f_A, α_A, ω_B, f_B, t_A − t_ref on the base rows, for this clock model."""
        tm = self._map(self.t, delta, drift_ppm)
        other = self.spline(tm)
        og, of = other[:, :3], other[:, 3:]
        if self.base_is_a:
            return self.base_gyro, self.base_accel, self.alpha_base, og, of, self.t - self.t_ref
        alpha = self.alpha_a(tm) if self.with_accel else None
        return og, of, alpha, self.base_gyro, self.base_accel, tm - self.t_ref

    def unpack(self, p):
        ix = self.index
        return (p[ix["rot"]], p[ix["dt"].start], p[ix["drift"].start] if self.with_drift else 0.0, p[ix["bg"]],
                p[ix["bf"]] if self.with_accel else None, p[ix["lever"]] if self.with_accel else None)

    def groups(self, C0, p):
        """Unweighted residual groups (gyro (n, 3), accel (n, 3) or None) and the rotated B vectors."""
        theta, delta, drift, bg, bf, lever = self.unpack(p)
        C = Rotation.from_rotvec(theta).as_matrix() @ C0
        wa, fa, alpha, wb, fb, _ = self.sides(delta, drift)
        cwb = wb @ C.T
        rg = wa - cwb - bg
        if not self.with_accel:
            return rg, None, cwb, None
        cfb = fb @ C.T
        lever_term = np.cross(alpha, lever) + np.cross(wa, np.cross(wa, lever))
        return rg, cfb - fa - lever_term - bf, cwb, cfb

    def residual(self, p, C0):
        rg, rf, _, _ = self.groups(C0, p)
        parts = [rg.ravel() * self.scale[0]]
        if rf is not None:
            parts.append(rf.ravel() * self.scale[1])
        return np.concatenate(parts)

    def jacobian(self, p, C0):
        n, P, ix = len(self), len(p), self.index
        theta, delta, drift, _, _, lever = self.unpack(p)
        C = Rotation.from_rotvec(theta).as_matrix() @ C0
        wa, fa, alpha, wb, fb, ta = self.sides(delta, drift)
        # Time: only the interpolated side moves with Δ; d(mapped time)/dΔ is 1 (B interpolated) or −1/(1+d).
        tm = self._map(self.t, delta, drift)
        rate = self.dspline(tm)
        if self.base_is_a:
            dg = -rate[:, :3] @ C.T
            df = rate[:, 3:] @ C.T if self.with_accel else None
        else:
            s = -1.0 / (1.0 + drift * 1e-6)
            dg = rate[:, :3] * s
            if self.with_accel:
                w_dot, alpha_dot = rate[:, :3], self.dalpha(tm)
                wl = np.cross(wa, lever)
                df = -(rate[:, 3:] + np.cross(alpha_dot, lever) + np.cross(w_dot, wl)
                       + np.cross(wa, np.cross(w_dot, lever))) * s
        J = np.zeros((2 if self.with_accel else 1, n, 3, P))
        _fill_skew(J[0, :, :, ix["rot"]], wb @ C.T, 1.0)
        J[0, :, :, ix["bg"]] = -np.eye(3)
        J[0, :, :, ix["dt"].start] = dg
        J[0] *= self.scale[0]
        if self.with_accel:
            _fill_skew(J[1, :, :, ix["rot"]], fb @ C.T, -1.0)
            J[1, :, :, ix["bf"]] = -np.eye(3)
            J[1, :, :, ix["lever"]] = -(skew(alpha) + skew(wa) @ skew(wa))
            J[1, :, :, ix["dt"].start] = df
            J[1] *= self.scale[1]
        if self.with_drift:
            # t_B − t_A = Δ + d·(t_A − t_ref): a ppm of d moves each row's time like (t_A − t_ref)·1e-6 of Δ.
            J[..., ix["drift"].start] = J[..., ix["dt"].start] * (ta * 1e-6)[None, :, None]
        return J.reshape(-1, P)


def _fill_skew(out: np.ndarray, v: np.ndarray, sign: float) -> None:
    """out (n, 3, 3) = sign·skew(v) (out[:, i, j]), written in place."""
    out[:, 0, 1], out[:, 0, 2] = -sign * v[:, 2], sign * v[:, 1]
    out[:, 1, 0], out[:, 1, 2] = sign * v[:, 2], -sign * v[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -sign * v[:, 1], sign * v[:, 0]


def align(a: ImuLog, b: ImuLog, options: AlignOptions = AlignOptions()) -> Alignment:
    for log in (a, b):
        if len(log.t) < MIN_SAMPLES:
            raise DataError(f"{log.label}: too short: {len(log.t)} samples (need at least {MIN_SAMPLES})")
    where = f"{a.label} and {b.label}"
    span = min(a.t[-1] - a.t[0], b.t[-1] - b.t[0])
    max_offset = span / 2 if options.max_offset_s is None else float(options.max_offset_s)
    lo_a, hi_a = b.t[0] - a.t[-1], b.t[-1] - a.t[0]       # offsets for which the stamps overlap at all
    if not (max(lo_a, -max_offset) < min(hi_a, max_offset)):
        raise DataError(f"{where}: no overlap in time: A covers {a.t[0]:.6g}..{a.t[-1]:.6g} s, B covers "
                        f"{b.t[0]:.6g}..{b.t[-1]:.6g} s, and time offsets are searched within ±{max_offset:.6g} s "
                        "(--max-offset-s)")
    wa, wb = np.linalg.norm(a.gyro, axis=1), np.linalg.norm(b.gyro, axis=1)
    notes = []
    coarse = coarse_time_offset(a.t, wa, b.t, wb, -max_offset, max_offset, MIN_OVERLAP_FRACTION * span, where)
    delta0 = coarse
    if delta0 is None:
        delta0 = float(np.clip(0.0, max(lo_a, -max_offset), min(hi_a, max_offset)))
        notes.append(f"the angular rate magnitude changes by less than {MIN_RATE_CHANGE:g} rad/s RMS: too little "
                     f"motion to search a time offset; the fit starts at {delta0:g} s")
    lo, hi = max(a.t[0], b.t[0] - delta0), min(a.t[-1], b.t[-1] - delta0)    # overlap on A's clock
    t_ref = 0.5 * (lo + hi)
    drift0 = 0.0
    if options.drift:
        mid = a.t[(a.t >= lo) & (a.t <= hi)]
        halves = [mid[: len(mid) // 2], mid[len(mid) // 2:]]
        window = 0.1 * (hi - lo)
        offsets = []
        for half in halves:
            sel = (a.t >= half[0]) & (a.t <= half[-1])
            found = coarse_time_offset(a.t[sel], wa[sel], b.t, wb, delta0 - window, delta0 + window,
                                       0.9 * (half[-1] - half[0]), where)
            offsets.append(delta0 if found is None else found)
        centres = [0.5 * (h[0] + h[-1]) for h in halves]
        drift0 = (offsets[1] - offsets[0]) / (centres[1] - centres[0]) * 1e6
        delta0 = float(np.mean(offsets) + drift0 * 1e-6 * (t_ref - np.mean(centres)))
    base_is_a = a.rate_hz <= b.rate_hz
    bandwidth = 1.0
    if options.lowpass is not None:
        a, b, bandwidth = _lowpassed(a, b, options.lowpass, notes)
    problem = _Problem(a, b, base_is_a, delta0, drift0, t_ref, options.lever_arm, options.drift,
                       options.alpha_span_s)
    problem.noise_bandwidth = bandwidth
    if len(problem) < MIN_SAMPLES:
        raise DataError(f"{where}: too short: {len(problem)} samples overlap (need at least {MIN_SAMPLES})")
    # Closed-form start: Kabsch on the centred gyro pairs (centring removes the bias difference).
    wa0, fa0, _, wb0, fb0, _ = problem.sides(delta0, drift0)
    pairs_a, pairs_b = [wa0 - wa0.mean(0)], [wb0 - wb0.mean(0)]
    weights = [np.full(len(problem), 1.0 / max(np.mean(np.sum(pairs_a[0] ** 2, 1)), 1e-300))]
    if options.lever_arm:   # gravity fixes the axes the gyros may leave open (rotation about one axis)
        pairs_a.append(fa0)
        pairs_b.append(fb0)
        weights.append(np.full(len(problem), 1e-3 / max(np.mean(np.sum(fa0 ** 2, 1)), 1e-300)))
    C0 = kabsch(np.concatenate(pairs_a), np.concatenate(pairs_b), np.concatenate(weights))
    p = np.zeros(len(problem.names))
    p[problem.index["dt"].start] = delta0
    if options.drift:
        p[problem.index["drift"].start] = drift0
    p[problem.index["bg"]] = np.mean(wa0 - wb0 @ C0.T, axis=0)
    if options.lever_arm:
        p[problem.index["bf"]] = np.mean(fb0 @ C0.T - fa0, axis=0)
    evaluations = 0
    for weighting in range(2):
        # Each residual group weighted by 1/its RMS: after the start, then once more after the first fit if
        # the ratio of the two moved by more than 10 % (the gyro-only fit needs no second pass).
        rg, rf, _, _ = problem.groups(C0, p)
        scale = np.array([1.0 / max(_rms(rg), 1e-6 * GYRO_FLOOR),
                          1.0 / max(_rms(rf), 1e-6 * ACCEL_FLOOR) if rf is not None else 1.0])
        if weighting and abs(math.log((scale[1] / scale[0]) / (problem.scale[1] / problem.scale[0]))) < 0.1:
            break
        problem.scale = scale
        # Rounding floor of the weighted cost: 1e-14 of each group's signal RMS per residual.
        floor = 3 * len(problem) * ((1e-14 * _rms(wa0) * scale[0]) ** 2
                                    + ((1e-14 * _rms(fa0) * scale[1]) ** 2 if rf is not None else 0.0))
        p, C0, n, converged = levenberg_marquardt(problem, p, C0, floor)
        evaluations += n
        if not converged:
            notes.append("Levenberg–Marquardt stopped at its iteration limit before converging: treat the "
                         "estimates with suspicion")
    return _result(problem, p, C0, options, coarse, hi - lo, evaluations, notes)


def _lowpassed(a: ImuLog, b: ImuLog, fraction: float, notes: list[str]) -> tuple[ImuLog, ImuLog, float]:
    """Both records low-passed at one cutoff in Hz (fraction of the lower rate's Nyquist frequency) with zero
    phase, their ends trimmed by LOWPASS_EDGE / f_c; and the fraction of white noise's variance the filter passes
    on the lower-rate (base) grid, by which the residual variance understates the noise the estimates carry
    (the signal lies in the pass band, where the filter is 1). Records too short to trim stay as they are."""
    from scipy.signal import butter, sosfiltfilt
    if not 0 < fraction < 1:
        raise DataError(f"low-pass: the fraction of the Nyquist frequency must lie in (0, 1), got {fraction!r}")
    low = min(a.rate_hz, b.rate_hz)
    cutoff = fraction * 0.5 * low
    edge = LOWPASS_EDGE / cutoff
    if min(a.t[-1] - a.t[0], b.t[-1] - b.t[0]) < 10 * edge:
        notes.append(f"records shorter than {10 * edge:.3g} s: not low-passed before the fit")
        return a, b, 1.0
    for log in (a, b):
        # a digital filter assumes even spacing; jittered stamps already scatter the interpolation positions
        steps = np.diff(log.t)
        if np.max(np.abs(steps - np.median(steps))) > REGULAR_STAMPS * np.median(steps):
            notes.append(f"{log.label}: stamps not evenly spaced (within {REGULAR_STAMPS:.0%}): not low-passed "
                         "before the fit")
            return a, b, 1.0
    out = []
    for log in (a, b):
        sos = butter(LOWPASS_ORDER, cutoff, fs=log.rate_hz, output="sos")
        keep = (log.t >= log.t[0] + edge) & (log.t <= log.t[-1] - edge)
        out.append(ImuLog(log.label, log.t[keep], sosfiltfilt(sos, log.accel, axis=0)[keep],
                          sosfiltfilt(sos, log.gyro, axis=0)[keep]))
    sos = butter(LOWPASS_ORDER, cutoff, fs=low, output="sos")
    n = 2 * int(20 * low / cutoff) + 1
    impulse = np.zeros(n)
    impulse[n // 2] = 1.0
    response = sosfiltfilt(sos, impulse)
    notes.append(f"both records low-passed at {cutoff:.4g} Hz (zero phase) before the fit")
    return out[0], out[1], float(response @ response)


def levenberg_marquardt(problem: _Problem, p: np.ndarray, C0: np.ndarray, floor: float,
                        max_iterations: int = 100):
    """Marquardt's method (damping λ·diag(JᵀJ), so the step does not depend on the parameters' units) on the
    normal equations, which for a dozen parameters cost a fraction of a QR of the tall Jacobian. After every
    accepted step the rotation is moved into C0 and θ set back to 0, so the Jacobian is always exact.
    `floor` is the cost that rounding errors of the residual elements alone would make; a step gaining less
    than 1e-10 of the cost or less than the rounding noise of the cost itself (about 2·√(cost·floor)) ends
    the iteration: beyond that, accepted steps only shuffle rounding errors.
    Returns the parameters, C0, the number of residual evaluations and whether it converged."""
    rot = problem.index["rot"]
    r = problem.residual(p, C0)
    cost, lam, evaluations = float(r @ r), 1e-3, 1
    for _ in range(max_iterations):
        J = problem.jacobian(p, C0)
        H, g = J.T @ J, J.T @ r
        D = np.diag(H).copy()
        D[D <= 0] = 1.0
        while True:
            try:
                step = -np.linalg.solve(H + lam * np.diag(D), g)
            except np.linalg.LinAlgError:
                step = None
            if step is not None:
                trial = p + step
                C_trial = Rotation.from_rotvec(trial[rot]).as_matrix() @ C0
                trial[rot] = 0.0
                r_trial = problem.residual(trial, C_trial)
                evaluations += 1
                c_trial = float(r_trial @ r_trial)
                if c_trial <= cost:
                    break
            predicted = -(2 * g @ step + step @ H @ step) if step is not None else np.inf
            lam *= 10.0
            if predicted <= 1e-10 * cost + 2 * math.sqrt(cost * floor) + floor or lam > 1e10:   # converged
                return p, C0, evaluations, True
        gained = cost - c_trial
        p, C0, r, cost = trial, C_trial, r_trial, c_trial
        lam = max(lam / 10.0, 1e-15)
        if gained <= 1e-10 * (cost + gained) + 2 * math.sqrt(cost * floor) + floor:
            return p, C0, evaluations, True
    return p, C0, evaluations, False


def _rms(x):
    return float(np.sqrt(np.mean(x ** 2))) if x is not None and x.size else 0.0


def _euler_deg(C: np.ndarray) -> np.ndarray:
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)     # gimbal lock: scipy sets roll to 0, as we document
        yaw, pitch, roll = Rotation.from_matrix(C).as_euler("ZYX", degrees=True)
    return np.array([roll, pitch, yaw])


def _euler_jacobian(C: np.ndarray) -> np.ndarray:
    """d(roll, pitch, yaw)/dθ in degrees per radian, for C = exp([θ]×)·C (central differences)."""
    G = np.zeros((3, 3))
    h = 1e-6
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        diff = _euler_deg(Rotation.from_rotvec(e).as_matrix() @ C) - _euler_deg(Rotation.from_rotvec(-e).as_matrix() @ C)
        G[:, j] = (diff + 180.0) % 360.0 - 180.0
    return G / (2 * h)


def _covariance(J: np.ndarray) -> np.ndarray:
    """(JᵀJ)⁻¹ with a ridge of 1e-12 of each diagonal element: a direction the data leave open gets a huge
    variance instead of the zero a pseudo-inverse would give it."""
    info = J.T @ J
    d = np.sqrt(np.maximum(np.diag(info), 1e-200))     # a parameter nothing depends on: huge, finite variance
    normalised = info / np.outer(d, d) + 1e-12 * np.eye(len(d))
    return np.linalg.inv(normalised) / np.outer(d, d)


def _result(problem: _Problem, p, C, options: AlignOptions, coarse, overlap_s, evaluations, notes) -> Alignment:
    ix = problem.index
    rg, rf, _, _ = problem.groups(C, p)
    P = len(p)
    m = rg.size + (rf.size if rf is not None else 0)
    dof = max(m - P, 1)
    rms = {"gyro_rad_s": _rms(rg)}
    if rf is not None:
        rms["accel_mps2"] = _rms(rf)
    # Residual variance per group with the degrees of freedom shared out by rows; after a low-pass, the white
    # noise that leaves this residual variance (the information sums JᵀJ over rows as if they were independent).
    inflate = math.sqrt(m / dof / problem.noise_bandwidth)
    sig_g = _rms(rg) * inflate
    sig_f = _rms(rf) * inflate if rf is not None else 1.0
    cov = {}
    # (never below a millionth of the floors: exactly zero residuals would make the scale infinite)
    problem.scale = np.array([1.0 / max(sig_g, 1e-6 * GYRO_FLOOR), 1.0 / max(sig_f, 1e-6 * ACCEL_FLOOR)])
    cov["fit"] = _covariance(problem.jacobian(p, C))
    problem.scale = np.array([1.0 / max(sig_g, GYRO_FLOOR), 1.0 / max(sig_f, ACCEL_FLOOR)])
    J_floor = problem.jacobian(p, C)
    _, delta, drift, bg, bf, lever = problem.unpack(p)
    G = _euler_jacobian(C)
    euler = _euler_deg(C)
    quat = Rotation.from_matrix(C).as_quat()[[3, 0, 1, 2]]
    quat = quat if quat[0] >= 0 else -quat

    def sd(c, idx):
        return np.sqrt(np.maximum(np.diag(c)[idx], 0.0))
    c = cov["fit"]
    rot = ix["rot"]
    sigma = {"rotation_deg": float(np.degrees(np.sqrt(np.max(np.linalg.eigvalsh(c[rot, rot]))))),
             "euler_deg": np.sqrt(np.maximum(np.diag(G @ c[rot, rot] @ G.T), 0.0)),
             "time_offset_s": float(sd(c, ix["dt"])[0]),
             "gyro_bias_diff_rad_s": sd(c, ix["bg"])}
    if problem.with_drift:
        sigma["clock_drift_ppm"] = float(sd(c, ix["drift"])[0])
    if problem.with_accel:
        sigma["accel_bias_diff_mps2"] = sd(c, ix["bf"])
        sigma["lever_arm_m"] = sd(c, ix["lever"])
    observable, reasons = _verdicts(problem, J_floor.T @ J_floor, G, options, searched=coarse is not None)
    cos_pitch = math.cos(math.radians(euler[1]))
    if abs(cos_pitch) < 1e-2:
        notes.append(f"pitch {euler[1]:.4f}° is near ±90° (gimbal lock of the z-y-x angles): roll and yaw "
                     f"are ill-conditioned there (errors grow by 1/cos(pitch) = {1 / max(abs(cos_pitch), 1e-300):.3g});"
                     " the quaternion is not")
    notes.append(f"{evaluations} residual evaluations")
    return Alignment(
        C=C, quaternion_wxyz=quat, euler_deg=euler, time_offset_s=float(delta), time_reference_s=problem.t_ref,
        drift_ppm=float(drift) if problem.with_drift else None, gyro_bias_diff=bg,
        accel_bias_diff=bf, lever_arm_m=lever, sigma=sigma, observable=observable, reasons=reasons, notes=notes,
        residual_rms=rms, n_rows=len(problem), overlap_s=float(overlap_s), coarse_offset_s=None if coarse is None else float(coarse),
        base="A" if problem.base_is_a else "B", extra={"rotation_covariance_rad2": c[rot, rot]})


def _marginal_information(info: np.ndarray, block: slice) -> np.ndarray:
    """Information about one block with all other parameters free (the Schur complement): what the data say
    about it once everything it trades off against has been fitted. Computed in information form, so a
    direction with no information shows as an eigenvalue near 0 while the others keep their digits (an
    eigen-decomposition of a covariance holding both 1e12 and 1e-12 would not)."""
    idx = np.arange(info.shape[0])
    keep = (idx >= block.start) & (idx < block.stop)
    H_bb, H_bo, H_oo = info[np.ix_(keep, keep)], info[np.ix_(keep, ~keep)], info[np.ix_(~keep, ~keep)]
    d = np.sqrt(np.maximum(np.diag(H_oo), 1e-200))
    inner = np.linalg.inv(H_oo / np.outer(d, d) + 1e-12 * np.eye(len(d))) / np.outer(d, d)
    M = H_bb - H_bo @ inner @ H_bo.T
    return 0.5 * (M + M.T)


def _directions(info: np.ndarray, block: slice):
    """Eigen-directions of a block's marginal information, with their 1σ and excitation relative to the
    best-determined direction of the block (sqrt of the eigenvalue ratio)."""
    values, vectors = np.linalg.eigh(_marginal_information(info, block))
    # One sign per axis (largest component positive), rounded so that messages do not print "-0.000".
    vectors = vectors * np.sign(vectors[np.argmax(np.abs(vectors), axis=0), np.arange(vectors.shape[1])])
    vectors = np.round(vectors, 3) + 0.0
    top = max(values[-1], 1e-300)
    values = np.maximum(values, 0.0)
    with np.errstate(divide="ignore"):
        sigma = np.where(values > 0, 1.0 / np.sqrt(values), np.inf)
    return vectors, sigma, np.sqrt(values / top)


def _verdicts(problem: _Problem, info: np.ndarray, G: np.ndarray, options: AlignOptions, searched: bool):
    """Which reported quantities the data determine, and why not where they don't.

    Works on the information matrix JᵀJ with the residual noise floored (GYRO_FLOOR, ACCEL_FLOOR), block by
    block (each block's marginal information, so a parameter that trades off against another shows as
    uncertain):
    - a direction whose 1σ exceeds the option's maximum is unobservable (too little motion, or none about it);
    - a direction of a 3-vector block excited less than min_excitation times its best-excited direction is
      unobservable too: its estimate rests on the small part of the motion, where the sensors' relative
      errors (scale factor, axis misalignment ~1e-3) weigh 1/ratio times more; e.g. a car that mostly yaws
      tells the gyros almost nothing about a rotation about the yaw axis.
    """
    ix = problem.index
    observable, reasons = {}, []
    names = ("roll", "pitch", "yaw")
    vectors, sig, excitation = _directions(info, ix["rot"])
    bad_angles = set()
    for k in range(3):
        u = vectors[:, k]
        sigma_deg = math.degrees(sig[k])
        why = None
        if sigma_deg > options.max_sigma_deg:
            why = f"1σ {sigma_deg:.3g}° exceeds {options.max_sigma_deg:g}°"
        elif excitation[k] < options.min_excitation:
            why = (f"excited {excitation[k]:.3g} times as much as the best-determined axis (threshold "
                   f"{options.min_excitation:g})")
        if why is None:
            continue
        g = G @ u
        hit = [names[i] for i in range(3) if abs(g[i]) >= 0.5 * np.max(np.abs(g))]
        bad_angles.update(hit)
        reasons.append(f"rotation about A's axis ({u[0]:+.3f}, {u[1]:+.3f}, {u[2]:+.3f}) is not determined "
                       f"({why}): the motion turned the sensors too little about other axes; "
                       f"affects {', '.join(hit)}")
    for name in names:
        observable[name] = name not in bad_angles

    def scalar(key, label, unit, limit):
        block = ix[key]
        s = 1.0 / math.sqrt(max(_marginal_information(info, block)[0, 0], 1e-300))
        ok = s <= limit
        if not ok:
            reasons.append(f"{label} is not determined (1σ {s:.3g} {unit} exceeds {limit:g} {unit}): the "
                           "angular rate hardly changed, or changed like another estimate does")
        return ok
    observable["time_offset_s"] = scalar("dt", "time offset", "s", options.max_sigma_time_s)
    if not searched and observable["time_offset_s"]:
        observable["time_offset_s"] = False
        reasons.append(f"time offset is not determined: the angular rate magnitude changed by less than "
                       f"{MIN_RATE_CHANGE:g} rad/s RMS, too little to match the two records")
    if problem.with_drift:
        observable["clock_drift_ppm"] = scalar("drift", "clock drift", "ppm", options.max_sigma_drift_ppm)
    if problem.with_accel:
        vectors, sig, excitation = _directions(info, ix["lever"])
        bad = np.zeros(3, bool)
        for k in range(3):
            u = vectors[:, k]
            if sig[k] > options.max_sigma_lever_m or excitation[k] < options.min_excitation:
                bad |= np.abs(u) >= 0.5 * np.max(np.abs(u))
                reasons.append(f"lever arm along A's axis ({u[0]:+.3f}, {u[1]:+.3f}, {u[2]:+.3f}) is not "
                               f"determined (1σ {sig[k]:.3g} m, {excitation[k]:.3g} times as excited as the "
                               "best axis): the centripetal and angular-acceleration terms hardly act along it")
        observable["lever_arm_m"] = [bool(not x) for x in bad]
    return observable, reasons
