"""Drive the kernel block by block: evaluate sampled motion for the block (if any), call the compiled
kernel once per block, check the result is finite, hand back a SampleBlock.

Random numbers are a pure function of (seed, IMU, stream, run sample), so stateless effects give the same
bytes for any cut into blocks. Stateful effects (Gauss-Markov, random walks) carry per-IMU state in one array
across blocks, which makes the run sequential: `block(k0, n)` continues the state when k0 is the next run
sample; any other k0 replays the run from its start (or from the current position, going forward) into
scratch buffers first, so the answer is always the same as one run from the start, at the cost of the replay.
"""
from __future__ import annotations

import numpy as np

from imu_emulator.errors import DataError
from imu_emulator.codegen.increments import check_nodes
from imu_emulator.codegen.plan import EffectPlan
from imu_emulator.codegen.signature import BIAS_TRUTH_KEYS, EMPTY3, TRUTH_KEYS, arguments
from imu_emulator.runtime.kernels import compile_kernel, kernel_outputs
from imu_emulator.runtime.memory import check_memory
from imu_emulator.runtime.samples import SampleBlock
from imu_emulator.scene.model import SampledData, Scene

_REPLAY_BLOCK = 65536


class Simulation:
    """IMU samples for a scene. `block(k0, n)` gives samples k0 .. k0+n-1 for any k0 >= 0."""

    def __init__(self, scene: Scene, attitude: bool = True, truth: bool = False, increments: int = 0):
        self.scene = scene
        self.attitude = attitude
        self.truth = truth
        #: Gauss-Legendre nodes of the integrated outputs dtheta, dvel (imu_emulator.codegen.increments); 0: none
        self.increments = check_nodes(increments)
        # Sampled input is fitted before the kernel compiles: bad data is reported in a second, not after it.
        self._plan = EffectPlan(scene)
        self._keys = self._plan.keys(scene.seed)
        #: companion sensors (imu_emulator.companions): computed after the kernel from its truth and attitude,
        #: which the kernel then outputs whether or not they were asked for; they carry state across blocks
        self._companions = any(imu.companions for imu in scene.imus)
        self._attitude_out, self._truth_out = kernel_outputs(scene, attitude, truth)
        self._params = self._plan.param_values()     # the scene's numbers, the kernel's `prm`
        self._stateful = bool(self._plan.slots) or self._companions
        #: each IMU's temperature profile reaches the samples when the temperature effect is on
        self.temperature = "temperature" in scene.effects
        from imu_emulator.scene.earth import model_on    # not earth_truth (frames, rotations) unless it is used
        # geodetic, NED, ECEF truth (earth_truth.KEYS); the companions read it
        self._earth_truth = (truth and model_on(scene)) or self._companions
        self._position = self._series(scene.trajectory, 3 if scene.attitude_mode == "tangent" else 2, "trajectory")
        self._euler = self._series(scene.attitude, 2, "attitude")
        self.kernel = compile_kernel(scene, attitude=self._attitude_out, truth=self._truth_out,
                                     increments=self.increments, plan=self._plan)
        offsets = np.array([imu.time_offset_s for imu in scene.imus])
        self._time_offsets = offsets if offsets.any() else None     # SampleBlock.time_offset_s
        # Tangent attitude holds the last defined heading (cos, sin) and pitch (cos, sin) across blocks.
        h = scene.initial_heading_rad
        self._hold = np.array([np.cos(h), np.sin(h), 1.0, 0.0])
        # The state at the run's start is a pure function of the seed: drawn once (some 0.3 ms for the full error
        # model, a stream key and a call per draw) and copied at every restart, so a replay from the start or a
        # benchmark's restart pays a copy, not the draws again (tools/bench_against.py "restart")
        self._initial = self._plan.initial_state(scene.seed)
        self._reset_state()

    def fresh(self) -> "Simulation":
        """A new simulation of the same scene and outputs, at the run's start (the kernel is not recompiled)."""
        return Simulation(self.scene, attitude=self.attitude, truth=self.truth, increments=self.increments)

    def _reset_state(self) -> None:
        self._state = self._initial.copy()     # the kernel writes the state in place
        self._next = 0      # the run sample the state is at
        if self._companions:
            from imu_emulator.companions import COMPANIONS
            self._runners = [{name: COMPANIONS[name].start(self.scene, m, values)
                              for name, values in imu.companions.items()} for m, imu in enumerate(self.scene.imus)]

    @property
    def bias_truth(self) -> bool:
        return self.truth and self._plan.bias_truth

    @property
    def _bias_out(self) -> bool:
        return self._truth_out and self._plan.bias_truth

    def counts(self) -> dict[str, dict[str, int]]:
        """What the effects counted so far in this run (e.g. "range.gyro.x": samples saturated at the full
        scale), per IMU name; empty when no effect counts."""
        found: dict[str, dict[str, int]] = {}
        for slot, m, label in self._plan.counters:
            found.setdefault(self.scene.imus[m].name, {})[label] = int(self._state[slot])
        for m, runners in enumerate(self._runners if self._companions else ()):
            for runner in runners.values():
                found.setdefault(self.scene.imus[m].name, {}).update(runner.counts)
        return found

    @staticmethod
    def _series(part, order: int, where: str):
        if not isinstance(part, SampledData):
            return None
        from imu_emulator.numerics.derivatives import SampledSeries, unwrap_angles
        from imu_emulator.geo.rotations import continuous_quaternions
        values, noise = part.values, part.noise
        if where == "attitude":
            if part.kind == "quaternion":
                # a rotation by a small angle e moves the unit quaternion by e/2
                values, noise = continuous_quaternions(part.values), part.noise / 2.0
            else:
                values = unwrap_angles(part.values)
        return SampledSeries(part.t, values, part.derivative, max_order=order, name=part.source,
                             noise=noise), order

    @property
    def n_samples(self) -> int:
        return self.scene.n_samples

    @property
    def imu_names(self) -> tuple[str, ...]:
        return self.scene.imu_names

    def times(self, k0: int, n: int) -> np.ndarray:
        return self.scene.t0_s + (k0 + np.arange(n, dtype=np.float64)) * (1.0 / self.scene.rate_hz)

    def block(self, k0: int, n: int, out: SampleBlock | None = None, run_sample: int | None = None) -> SampleBlock:
        """Samples k0 .. k0+n-1 of the scene. With `out` (a block of the right shape, e.g. views into larger
        arrays) the kernel writes there instead of allocating. `run_sample` (default k0) is the run's own
        sample count, which random numbers and state follow: a looped stream passes it so that its noise does
        not repeat with the scene."""
        s0 = k0 if run_sample is None else int(run_sample)
        if self._stateful and s0 != self._next:
            self._replay_to(s0)
        n_imu = len(self.scene.imus)
        t = self.times(k0, n)
        if out is None:
            out = self._new_block(k0, t)
        else:
            out.k0 = k0
            out.t_s[:] = t
        self._call(k0, n, s0, out)
        self._check_finite(out.accel, out.gyro, k0)
        self._after_kernel(t, s0, out)
        if self.temperature:
            from imu_emulator.effects.temperature import profile
            for m, imu in enumerate(self.scene.imus):
                out.temperature_c[m] = profile(imu.values, t)
        return out

    def _after_kernel(self, t: np.ndarray, s0: int, out: SampleBlock) -> None:
        """The Earth truth, then the companion sensors from it (in run order: they carry state)."""
        if self._earth_truth:
            from imu_emulator.motion import earth_truth
            earth_truth.fill(self.scene, t, out.truth)
        if self._companions:
            from imu_emulator.runtime.companions import run_companions
            run_companions(self.scene, self._runners, t, s0, out)

    def _new_block(self, k0: int, t: np.ndarray) -> SampleBlock:
        n_imu, n = len(self.scene.imus), len(t)
        companion = None
        if self._companions:
            from imu_emulator.runtime.companions import new_outputs
            companion = new_outputs(self.scene, n)
        return SampleBlock(k0=k0, t_s=t, accel=np.empty((n_imu, n, 3)), gyro=np.empty((n_imu, n, 3)),
                           quat=np.empty((n_imu, n, 4)) if self._attitude_out else None,
                           truth=self._new_truth(n) if self._truth_out else None, companion=companion,
                           temperature_c=np.empty((n_imu, n)) if self.temperature else None,
                           dtheta=np.empty((n_imu, n, 3)) if self.increments else None,
                           dvel=np.empty((n_imu, n, 3)) if self.increments else None,
                           time_offset_s=self._time_offsets)

    def _new_truth(self, n: int) -> dict:
        truth = {k: np.empty((n, 3)) for k in TRUTH_KEYS}
        if self._earth_truth:
            from imu_emulator.motion.earth_truth import KEYS
            truth.update({k: np.empty((n, 3)) for k in KEYS})
        if self._bias_out:
            truth.update({k: np.empty((len(self.scene.imus), n, 3)) for k in BIAS_TRUTH_KEYS})
        return truth

    def _call(self, k0: int, n: int, s0: int, out: SampleBlock) -> None:
        mot = self._evaluate(self._position, k0, n, s0)
        att = self._evaluate(self._euler, k0, n, s0)
        self.kernel(*arguments(k0, n, s0, mot, att, self._hold, self._keys, self._state, self._params,
                               out.accel, out.gyro,
                               quat=out.quat if self._attitude_out else None,
                               truth=[out.truth[k] for k in TRUTH_KEYS] if self._truth_out else None,
                               bias=[out.truth[k] for k in BIAS_TRUTH_KEYS] if self._bias_out else None,
                               increments=[out.dtheta, out.dvel] if self.increments else None))
        self._next = s0 + n

    def _replay_to(self, s0: int) -> None:
        """Bring the state to run sample s0 by computing the samples before it (discarded)."""
        if s0 < self._next:
            self._reset_state()
            self._hold[:] = [np.cos(self.scene.initial_heading_rad), np.sin(self.scene.initial_heading_rad), 1.0, 0.0]
        while self._next < s0:
            n = min(_REPLAY_BLOCK, s0 - self._next)
            k = self._next % self.n_samples    # the motion a looped run had at that run sample
            n = min(n, self.n_samples - k)
            replayed = self._new_block(k, self.times(k, n))
            s = self._next
            self._call(k, n, s, replayed)
            if self._companions:     # they carry state too: bring it along
                self._after_kernel(replayed.t_s, s, replayed)

    def _evaluate(self, series, k0: int, n: int, s0: int):
        if series is None:
            return EMPTY3
        fitted, order = series
        # Relative to the data's first stamp: an absolute t = 1e7 s carries 1.9e-9 s of rounding.
        tau = (self.scene.t0_s - fitted.t_start) + (k0 + np.arange(n, dtype=np.float64)) / self.scene.rate_hz
        clk = clk_prev = np.zeros(n)
        if "clock" in self.scene.effects:   # the actual sampling instants, as the kernel's clock lines give them
            from imu_emulator.effects.clock import offsets
            clk = offsets(self.scene, self.scene.seed, k0, s0, n)
            clk_prev = offsets(self.scene, self.scene.seed, k0 - 1, s0 - 1, n) if self.increments else clk
        if self.increments:   # the kernel reads node q of sample j at n + j * nodes + q
            from imu_emulator.codegen.increments import node_offsets
            nodes = tau[:, None] + node_offsets(self.increments, clk, clk_prev) / self.scene.rate_hz
            # The first sample's interval (t_-1, t_0] starts before sampled motion's first stamp when the scene
            # starts there (waypoints, tracks, logs): before it the body is held in its first stamp's state, so
            # that interval integrates the first stamp's rate and force (a VectorNav or MIP device's increments
            # made every such stream fail at its start).
            nodes = np.maximum(nodes, min(0.0, float(tau[0])))
            tau = np.concatenate([tau + clk / self.scene.rate_hz, nodes.reshape(-1)])
        else:
            tau = tau + clk / self.scene.rate_hz
        return np.ascontiguousarray(fitted.evaluate_relative(tau, order))

    def _check_finite(self, acc, gyro, k0: int) -> None:
        # A NaN must never reach a wire or a file. A sum is non-finite iff some term is (or the sum
        # overflows, which values this large deserve a look at too); only then search for the first.
        with np.errstate(all="ignore"):
            if np.isfinite(np.sum(acc) + np.sum(gyro)):
                return
        bad = ~(np.isfinite(acc).all(axis=(0, 2)) & np.isfinite(gyro).all(axis=(0, 2)))
        if not bad.any():
            return    # finite values whose sum overflowed
        k = k0 + int(np.argmax(bad))
        from imu_emulator.motion.code import explain_nonfinite
        message = explain_nonfinite(self.scene, k)
        if message is None:
            message = (f"the motion gives a non-finite value at t = {self.scene.t0_s + k / self.scene.rate_hz!r} s "
                       f"(sample {k}) although every expression and derivative is finite there: products of "
                       "large terms overflowed; reduce the motion's magnitudes or rates")
        raise DataError(message)

    def run(self, block_size: int = 65536, progress=None) -> SampleBlock:
        """The whole scene in one SampleBlock; the kernel writes straight into the full arrays."""
        n_total = self.n_samples
        check_memory(n_total, len(self.scene.imus), self._attitude_out, self._truth_out, "simulate",
                     increments=bool(self.increments), temperature=self.temperature,
                     earth_truth=self._earth_truth, bias_truth=self._bias_out)
        whole = self._new_block(0, np.empty(n_total))
        for k0 in range(0, n_total, block_size):
            self.block(k0, min(block_size, n_total - k0), out=whole.view(k0, min(k0 + block_size, n_total)))
            if progress is not None:
                progress(min(k0 + block_size, n_total), n_total)
        whole.k0 = 0
        return whole


def simulate(scene: Scene, truth: bool = False, increments: int = 0) -> SampleBlock:
    """Python API: all samples of a scene (with `increments` Gauss-Legendre nodes: dtheta and dvel too)."""
    return Simulation(scene, attitude=True, truth=truth, increments=increments).run()
