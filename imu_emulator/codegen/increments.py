"""Integrated outputs: Δθ = ∫ω_ib dt and Δv = ∫f dt over each sample interval (t_{k−1}, t_k], in sensor axes.

The kernel evaluates the continuous chain (motion, navigation stage, body stage at each IMU, mounting) at the
Gauss–Legendre nodes of the interval and sums them with their weights. The lines come from the same effect
records and stage lists as the sample itself, so an effect of the navigation or body stage (present or future)
is integrated without knowing about increments.

Why Gauss–Legendre: N nodes integrate every polynomial of degree ≤ 2N − 1 exactly, and for a smooth integrand
the error over an interval of length h is h^(2N+1) (N!)⁴ / ((2N+1) ((2N)!)³) · f^(2N)(ξ). For motion whose
content lies at angular frequencies ≤ ω, |f^(2N)| ≤ |f|max ω^(2N), so the error relative to |f|max·h is at most
c_N (ωh)^(2N): with the default N = 4, c_4 = 5.6e-10, which is below 1e-12 for ωh < 0.45 (content below
f_s/14: 7 Hz at 100 Hz) and below 1e-9 at ωh < 1.1; more nodes (up to MAX_NODES) reach 1e-12 nearer to
Nyquist (N = 6: c_6 = 1.9e-16, 1e-12 at ωh < 0.49·π). Nothing is summed across intervals, so there is no drift.

The sensor stage applies to an increment as to the interval's mean: the stage's lines run once more per IMU
on (Δθ/T, Δv/T), with the sample's random draws and state, and the result is multiplied by the interval
length T. Per effect that is: bias (constant, turn-on, random walk, instability, temperature) → b·T; scale
factor, misalignment → (I + M)·Δ; g-sensitivity → G·Δv added to Δθ; white noise → the sample's draw times
N·√(f_s)·T = N·√T per axis, the standard deviation of white noise of density N integrated over T (the same
draw as the rate sample: the rate is the increment over T); quadratic nonlinearity → K₂·(Δ/T)²·T (the
square of the mean, not the mean of the square: they differ by K₂·var over the interval). The output stage
(range, resolution of the rate outputs) does not apply: an increment's range and quantum are the wire
field's, applied by the format. With the clock effect the interval runs between the actual instants
t_{k−1}' and t_k' (T = Δt·(1 + clk_k − clk_{k−1})), so consecutive increments tile time exactly.
"""
from __future__ import annotations

import re

import numpy as np

DEFAULT_NODES = 4
MAX_NODES = 16
#: the kernel's extra arguments when increments are compiled: (n_imu, n, 3) each
ARGS = ("out_dtheta", "out_dvel")


def check_nodes(count) -> int:
    """The number of nodes, validated (0: no increments; True: the default)."""
    from imu_emulator.errors import ImuEmulatorError
    if count is True:
        return DEFAULT_NODES
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 0 <= count <= MAX_NODES:
        raise ImuEmulatorError(f"increments: the number of Gauss-Legendre nodes is an integer 1..{MAX_NODES} "
                               f"(0: none), got {count!r}")
    return int(count)


def check_integrable(effects) -> None:
    """The navigation- and body-stage lines run once more per node, at the node's t: an effect there must be a
    pure function of the variables it reads (no state, no random draws, which would advance or repeat per node).
    The sample clock is the exception: its lines run for the interval's two ends only; so is an effect whose
    state only caches a pure function of (seed, run sample) (vibration's filtered noise)."""
    from imu_emulator.effects import Stage
    from imu_emulator.errors import ImuEmulatorError
    for effect in effects:
        repeated = effect.stage in (Stage.NAVIGATION, Stage.BODY) and not effect.sample_clock and not effect.cached_state
        if repeated and (effect.state or effect.random):
            raise ImuEmulatorError(f"increments: effect {effect.name!r} keeps state or draws random numbers in the "
                                   "navigation or body stage, which the quadrature evaluates at several instants "
                                   "per sample; it cannot be integrated")


def nodes(count: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes as fractions of the interval in (0, 1), and weights summing to 1."""
    xi, w = np.polynomial.legendre.leggauss(count)
    return (xi + 1.0) / 2.0, w / 2.0


def node_offsets(count: int, clk: np.ndarray | float = 0.0, clk_prev: np.ndarray | float = 0.0) -> np.ndarray:
    """Each node's instant in samples relative to sample k, (n, count): the interval runs from k − 1 + clk_prev
    to k + clk (sampled motion is evaluated there, as the kernel evaluates symbolic motion)."""
    u, _ = nodes(count)
    clk, clk_prev = np.atleast_1d(clk)[:, None], np.atleast_1d(clk_prev)[:, None]
    return (clk_prev - 1.0) + (1.0 + clk - clk_prev) * u[None, :]


def _acc(kind: str, m: int, axis: str) -> str:
    return f"inc_{kind}{m}{axis}"


def constants(count: int) -> list[str]:
    u, w = nodes(count)
    return [f"INC_U = np.array({[float(x) for x in u]!r})", f"INC_W = np.array({[float(x) for x in w]!r})"]


def node_lines(count: int, *, n_imu: int, clock: list[str], phase_lines: list[str], motion: list[str],
               navigation: list[str], imu_frames: list[list[str]], t0: str, dt: str) -> list[str]:
    """The per-sample lines that integrate over (t_{k−1}, t_k]: they leave the integrals in inc_th<m><axis>
    and inc_dv<m><axis> and the interval length in inc_T; the sample's own evaluation runs after them and
    overwrites every variable they set. `motion` reads the sampled motion at index `jn` for node q; `t0` and `dt`
    are the source of the scene's start time and sample interval (run-time parameters)."""
    lines = ["# integrated outputs over (t_k-1, t_k]: Gauss-Legendre quadrature of the chain (codegen.increments)"]
    lines += [f"{_acc(kind, m, a)} = 0.0" for m in range(n_imu) for kind in ("th", "dv") for a in "xyz"]
    if clock:   # the previous sample's instant: its clock lines with k - 1, s - 1 (s = -1 wraps, as a counter)
        lines += ["# the interval's start: the previous sample's actual instant (its clock lines at k - 1, s - 1)",
                  "inc_clk = clk", "k -= 1", "s -= 1", *clock, "inc_clkp = clk", "k += 1", "s += 1",
                  "clk = inc_clk", f"inc_T = (1.0 + inc_clk - inc_clkp) * {dt}"]
    else:
        lines += [f"inc_T = {dt}"]
    # The phase of each periodic term at k, reduced exactly once; a node adds its offset in cycles.
    bases = []
    for line in phase_lines:
        found = re.fullmatch(r"sph(\d+), cph\d+ = sincos_cycles\(_c\)", line)
        bases.append(f"inc_c{found.group(1)} = _c" if found else line)
    n_phases = sum(1 for line in phase_lines if line.startswith("sph"))
    lines += ["# each periodic phase at k, reduced exactly once; a node adds its offset in cycles"] + bases
    lines += ["# node q at fraction INC_U[q] of the interval, weight INC_W[q]: motion, stages 1-3 there, summed",
              f"for q in range({count}):"]
    body = ["iu = (inc_clkp - 1.0) + (1.0 + inc_clk - inc_clkp) * INC_U[q]" if clock else "iu = INC_U[q] - 1.0",
            f"t = {t0} + k * {dt} + iu * {dt}", f"jn = n + j * {count} + q"]
    body += [f"sph{i}, cph{i} = sincos_cycles(inc_c{i} + iu * PH{i}_HI)" for i in range(n_phases)]
    body += motion + ["fnx = ax", "fny = ay", "fnz = az"] + navigation
    body += ["fbx = r00 * fnx + r10 * fny + r20 * fnz", "fby = r01 * fnx + r11 * fny + r21 * fnz",
             "fbz = r02 * fnx + r12 * fny + r22 * fnz"]
    for m, frame in enumerate(imu_frames):
        body += frame
        body += [f"{_acc('th', m, a)} += INC_W[q] * g{a}" for a in "xyz"]
        body += [f"{_acc('dv', m, a)} += INC_W[q] * o{a}" for a in "xyz"]
    lines += ["    " + line for line in body]
    return lines


def sampled_at_nodes(lines: list[str]) -> list[str]:
    """Sampled-motion lines reading node q's row (jn) instead of the sample's (j)."""
    return [re.sub(r"\b(mot|att)\[(\d+), j, ", r"\1[\2, jn, ", line) for line in lines]


def imu_lines(m: int, sensor: list[str], state_vars: list[str]) -> list[str]:
    """IMU m's increments with the sensor stage applied (see the module docstring), written to the outputs.
    `sensor` are the sensor-stage lines after mounting; `state_vars` the state they may advance, restored
    after so that the sample's own pass starts from the same state."""
    th = [_acc("th", m, a) for a in "xyz"]
    dv = [_acc("dv", m, a) for a in "xyz"]
    lines = [f"# -- IMU {m}: increments over (t_k-1, t_k], then the sensor stage on their mean"]
    lines += [f"{v} *= inc_T" for v in th + dv]
    if sensor:
        saved = [v for v in state_vars if any(re.search(rf"(?<!\w){re.escape(v)}(?![\w\[])", line) for line in sensor)]
        lines += [f"inc_s{i} = {v}" for i, v in enumerate(saved)]
        lines += ["inc_iT = 1.0 / inc_T"]
        lines += [f"o{a} = {v} * inc_iT" for a, v in zip("xyz", dv)]
        lines += [f"g{a} = {v} * inc_iT" for a, v in zip("xyz", th)]
        lines += sensor
        lines += [f"{v} = g{a} * inc_T" for a, v in zip("xyz", th)] + [f"{v} = o{a} * inc_T" for a, v in zip("xyz", dv)]
        lines += [f"{v} = inc_s{i}" for i, v in enumerate(saved)]
    lines += [f"out_dtheta[{m}, j, {i}] = {v}" for i, v in enumerate(th)]
    lines += [f"out_dvel[{m}, j, {i}] = {v}" for i, v in enumerate(dv)]
    return lines
