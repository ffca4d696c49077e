"""The record every companion sensor module declares, what it is handed each block, and the timing and noise
helpers they share.

A companion sensor (magnetometer, barometer, GNSS receiver, the unit's own navigation estimate) is a part
beside the IMU's triads: the scene names it per IMU with a sub-table ([imu.magnetometer], ...), it has its own
rate and its own errors in datasheet units, and it is computed in numpy after the kernel from the truth the
simulation produces (imu_emulator.runtime.simulation). The kernel never sees it, so naming one costs no
compilation beyond the truth and attitude outputs it reads.

Randomness: every draw is a counter-based normal (imu_emulator.numerics.counter_rng) keyed by the scene's seed,
the IMU, the sensor's stream name and the sensor's own update index, so noise does not depend on how the run is
cut into blocks; a Gauss-Markov error carries its last value across blocks (Runner state), and the simulation
replays from the start when asked for a block out of order, as it does for the kernel's stateful effects.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from imu_emulator.effects import Param
from imu_emulator.errors import SceneError


@dataclass(frozen=True)
class Companion:
    name: str                     # the [[imu]] sub-table naming it ([imu.<name>]), an identifier
    description: str              # one line
    params: tuple[Param, ...]     # keys of [imu.<name>] (Param.table == f"imu.{name}")
    #: the per-sample outputs: Samples field name (or a column-only name) -> width (0: (n,), k: (n, k))
    fields: Mapping[str, int]
    #: start(scene, m, values) -> a Runner for IMU m; values: this sensor's parameters by key, in SI
    start: Callable[..., "Runner"] = field(repr=False)
    #: keys that are not numbers with units (e.g. GNSS outages): key -> parse(value, where) -> value
    extra: Mapping[str, Callable[[Any, str], Any]] = field(default_factory=dict, repr=False)
    #: checks that need several parameters: validate(values, where) raises SceneError naming the key
    validate: Callable[[dict, str], None] | None = field(default=None, repr=False)


@dataclass
class Truth:
    """What a companion reads for one block of one IMU (n samples).

    s:        (n,) int64 run sample indices (noise and updates follow the run, as the kernel's do)
    t:        (n,) scene time, s
    rate_hz:  the IMU's sample rate
    llh:      (n, 3) geodetic latitude, longitude (deg), height above the WGS-84 ellipsoid (m) of the body's
              reference point S
    v_ned:    (n, 3) Earth-referenced velocity of S, north, east, down, m/s
    c_ns:     (n, 3, 3) sensor axes -> local NED at the current position (the IMU's attitude output, its
              mounting included)
    c_nb:     (n, 3, 3) the scene's body axes -> local NED
    omega_b:  (n, 3) body rate in the scene's body axes, rad/s
    values:   the IMU's own parameter values (ImuSpec.values: its temperature profile)
    """
    s: np.ndarray
    t: np.ndarray
    rate_hz: float
    llh: np.ndarray
    v_ned: np.ndarray
    c_ns: np.ndarray
    c_nb: np.ndarray
    omega_b: np.ndarray
    values: Mapping[str, Any]


class Runner:
    """One companion of one IMU through a run: `block(truth)` gives the block's outputs (Companion.fields), blocks
    in order from the run's start; `counts` what it clipped (shown with the effects' counters)."""

    def __init__(self):
        self.counts: dict[str, int] = {}

    def block(self, truth: Truth) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def count(self, label: str, n: int) -> None:
        if n:
            self.counts[label] = self.counts.get(label, 0) + int(n)


def update_index(s: np.ndarray, imu_rate_hz: float, rate_hz: float, delay_s: float = 0.0) -> np.ndarray:
    """The index of the sensor's latest update at run samples s: update j happens at j / rate_hz (+ delay_s)
    on the run's clock; -1 before the first. A tolerance of 1e-9 of an update keeps an update exactly on a
    sample instant from slipping to the next sample by rounding."""
    return np.floor((s / imu_rate_hz - delay_s) * rate_hz + 1e-9).astype(np.int64)


def changes(j: np.ndarray, previous: int) -> np.ndarray:
    """(n,) bool: where the update index differs from the sample before (`previous`: the last block's last)."""
    before = np.empty_like(j)
    before[0] = previous
    before[1:] = j[:-1]
    return j != before


def hold(new: np.ndarray, values: np.ndarray, last: np.ndarray) -> np.ndarray:
    """values (n, ...) taken where `new`, held until the next; samples before the block's first new one hold
    `last` (the previous block's last output)."""
    n = len(new)
    source = np.maximum.accumulate(np.where(new, np.arange(n), -1))
    out = np.empty_like(values)
    out[source >= 0] = values[source[source >= 0]]
    out[source < 0] = last
    return out


class Held:
    """The output of a sensor that updates at its own rate and holds its reading between updates (magnetometer,
    barometer): update j at j / rate_hz on the run's clock, the last reading carried across blocks."""

    def __init__(self, rate_hz: float, width: int):
        self.rate_hz = rate_hz
        self.last_j = -1                # the update index at the previous block's last sample
        self.last = np.zeros(width)     # the previous block's last output

    def block(self, truth: Truth, measure: Callable[[np.ndarray, np.ndarray], np.ndarray]
              ) -> tuple[np.ndarray, np.ndarray]:
        """(n, width) outputs and (n,) 1.0 where a new reading arrives (Samples.mag_new / baro_new): `measure(at,
        j)` gives the readings (len(at), width) of the updates j that happen at this block's samples `at` (called
        only when some do); each is held until the next."""
        j = update_index(truth.s, truth.rate_hz, self.rate_hz)
        new = changes(j, self.last_j)
        at = np.flatnonzero(new)
        values = np.zeros((len(j), len(self.last)))
        if len(at):
            values[at] = measure(at, j[at])
        out = hold(new, values, self.last)
        self.last_j, self.last = int(j[-1]), out[-1].copy()
        return out, new.astype(float)


def normals(seed: int, m: int, stream: str, first: int, n: int) -> np.ndarray:
    """n standard normals of IMU m's named stream, numbers first .. first + n - 1 (counter_rng)."""
    from imu_emulator.numerics.counter_rng import normals as draw, stream_key
    if n <= 0:
        return np.empty(0)
    return draw(stream_key(seed, m, stream), first, n)


def update_normals(seed: int, m: int, stream: str, ids: np.ndarray) -> np.ndarray:
    """The standard normals of IMU m's named stream at the non-decreasing update indices `ids` (one number per
    update, so a reading's noise does not depend on the block it falls in)."""
    first = int(ids[0])
    return normals(seed, m, stream, first, int(ids[-1]) - first + 1)[ids - first]


def param_maker(name: str, shape: str = "scalar") -> Callable[..., Param]:
    """The Param constructor of companion `name`'s keys (table imu.<name>), `shape` unless one is given."""
    def make(key, unit, description, shape=shape, default=0.0, datasheet=""):
        return Param(key, f"imu.{name}", unit, description, shape, default=default, datasheet=datasheet)
    return make


def check_sigmas(values: dict, keys, where: str, name: str) -> None:
    """Standard deviations (triples) of the keys are >= 0, else a SceneError naming the key."""
    for key in keys:
        if min(values[key]) < 0:
            raise SceneError(f"{where}.{name}.{key}: standard deviations are >= 0")


class Markov:
    """First-order Gauss-Markov errors, one per axis, at a fixed step: x_j = phi x_(j-1) + sigma sqrt(1 - phi^2)
    w_j with phi = exp(-step / tau), started from its stationary distribution (x_0 = sigma w_0), so every x_j
    has variance sigma^2 and correlation phi^|i-j| (Gelb, Applied Optimal Estimation, table 3.1-1). Each step
    is computed once, in order: `at(j)` takes update indices no earlier than the last one it gave."""

    def __init__(self, seed: int, m: int, stream: str, sigma, step_s: float, tau_s: float):
        self.seed, self.m, self.stream = seed, m, stream
        self.sigma = np.asarray(sigma, dtype=float)
        self.phi = math.exp(-step_s / tau_s)
        self.next = 0                               # the first index not computed yet
        self.last = np.zeros(len(self.sigma))       # x at next - 1

    def at(self, j: np.ndarray) -> np.ndarray:
        """(len(j), axes) the errors at update indices j (non-decreasing, >= next - 1; negative: zeros)."""
        from scipy.signal import lfilter
        j = np.asarray(j, dtype=np.int64)
        out = np.zeros((len(j), len(self.sigma)))
        top = int(j.max()) if len(j) else -1
        if not self.sigma.any() or top < 0:
            return out
        first = self.next
        # row 0: x at first - 1 (the value carried), then first .. top
        x = np.empty((top - first + 2, len(self.sigma)))
        x[0] = self.last
        drive = self.sigma * math.sqrt(1.0 - self.phi ** 2)
        for axis in range(len(self.sigma)):
            w = normals(self.seed, self.m, f"{self.stream}.{axis}", first, top - first + 1)
            if not len(w):
                continue
            if first == 0:
                x[1, axis] = self.sigma[axis] * w[0]      # the stationary start
                w, zi = w[1:], self.phi * x[1, axis]
                x[2:, axis] = lfilter([drive[axis]], [1.0, -self.phi], w, zi=[zi])[0]
            else:
                x[1:, axis] = lfilter([drive[axis]], [1.0, -self.phi], w, zi=[self.phi * x[0, axis]])[0]
        self.last = x[-1].copy()
        self.next = top + 1
        valid = j >= 0
        out[valid] = x[j[valid] - first + 1]
        return out
