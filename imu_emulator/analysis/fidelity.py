"""How far a replayed flight is from the flight: the emulated IMU against the vehicle's own recorded IMU.

Per axis: correlation, RMS difference raw and after a zero-phase low-pass (the replayed motion holds nothing
faster than its log's sample rates allow, the recorded IMU holds vibration and noise: the low-passed figures
say how well the motion itself is reproduced), the bias (mean difference, recorded - emulated) and the time
offset between the two (cross-correlation of the low-passed signals over all axes, refined between lags by a
parabola through the peak; positive: the recorded signal lags the emulated one).

The recorded signal is linearly interpolated to the emulated sample times, over the span both cover.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from imu_emulator.errors import DataError

MAX_OFFSET_S = 0.25


@dataclass(frozen=True)
class AxisFigures:
    correlation: float
    correlation_lowpassed: float
    rms_difference: float
    rms_difference_lowpassed: float
    bias: float


@dataclass(frozen=True)
class Comparison:
    quantity: str                    # "gyro" (rad/s) or "accel" (m/s^2)
    axes: tuple[AxisFigures, ...]
    time_offset_s: float
    lowpass_hz: float
    t: np.ndarray                    # common times
    emulated: np.ndarray             # (n, 3)
    recorded: np.ndarray             # (n, 3), interpolated to t

    def figures(self) -> dict:
        return {"quantity": self.quantity, "time_offset_s": self.time_offset_s, "lowpass_hz": self.lowpass_hz,
                "samples": int(self.t.size), "axes": [asdict(a) for a in self.axes]}


def lowpass(x: np.ndarray, rate_hz: float, cutoff_hz: float) -> np.ndarray:
    """Zero-phase 4th-order Butterworth (forward and backward), along axis 0."""
    from scipy.signal import butter, sosfiltfilt
    if cutoff_hz >= 0.5 * rate_hz:
        return x.copy()
    sos = butter(4, cutoff_hz, fs=rate_hz, output="sos")
    return sosfiltfilt(sos, x, axis=0)


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    denominator = np.sqrt((a * a).sum() * (b * b).sum())
    return float((a * b).sum() / denominator) if denominator > 0 else float("nan")


def time_offset(emulated: np.ndarray, recorded: np.ndarray, rate_hz: float, max_offset_s: float = MAX_OFFSET_S) -> float:
    """Lag (s) that best aligns recorded to emulated: recorded(t + lag) ~ emulated(t).

    The emulated signal's central part (a fixed window) is correlated with the recorded signal shifted by
    each lag, normalised by the shifted part's norm: by Cauchy-Schwarz that score peaks exactly at the true
    lag when the signals agree, whatever their spectrum (a plain cross-covariance over the overlapping part
    of a slow signal peaks a sample or so away from it)."""
    e = emulated - emulated.mean(axis=0)
    r = recorded - recorded.mean(axis=0)
    n = e.shape[0]
    max_lag = min(int(max_offset_s * rate_hz), n // 4)
    window = slice(max_lag, n - max_lag)
    ew = e[window]
    lags = np.arange(-max_lag, max_lag + 1)
    scores = np.empty(lags.size)
    for i, k in enumerate(lags):
        rs = r[max_lag + k:n - max_lag + k]
        norm = np.sqrt((rs * rs).sum())
        scores[i] = (ew * rs).sum() / norm if norm > 0 else 0.0
    i = int(np.argmax(scores))
    shift = 0.0
    if 0 < i < lags.size - 1:
        y0, y1, y2 = scores[i - 1:i + 2]
        curvature = y0 - 2 * y1 + y2
        shift = 0.5 * (y0 - y2) / curvature if curvature < 0 else 0.0
    return float((lags[i] + shift) / rate_hz)


def compare(quantity: str, t: np.ndarray, emulated: np.ndarray, t_rec: np.ndarray, recorded: np.ndarray,
            rate_hz: float, lowpass_hz: float) -> Comparison:
    inside = (t >= t_rec[0]) & (t <= t_rec[-1])
    if inside.sum() < 16:
        raise DataError(f"the recorded IMU ({t_rec[0]:.3f}..{t_rec[-1]:.3f} s) and the replay "
                        f"({t[0]:.3f}..{t[-1]:.3f} s) overlap in fewer than 16 samples")
    t = t[inside]
    emulated = emulated[inside]
    rec = np.column_stack([np.interp(t, t_rec, recorded[:, i]) for i in range(3)])
    emu_lp = lowpass(emulated, rate_hz, lowpass_hz)
    rec_lp = lowpass(rec, rate_hz, lowpass_hz)
    axes = []
    for i in range(3):
        d = rec[:, i] - emulated[:, i]
        axes.append(AxisFigures(
            correlation=_correlation(rec[:, i], emulated[:, i]),
            correlation_lowpassed=_correlation(rec_lp[:, i], emu_lp[:, i]),
            rms_difference=float(np.sqrt(np.mean(d * d))),
            rms_difference_lowpassed=float(np.sqrt(np.mean((rec_lp[:, i] - emu_lp[:, i]) ** 2))),
            bias=float(d.mean())))
    return Comparison(quantity, tuple(axes), time_offset(emu_lp, rec_lp, rate_hz), lowpass_hz, t, emulated, rec)
