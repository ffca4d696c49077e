"""What accuracy costs in time: every way the project produces IMU samples, on the same motions, against an
independent symbolic truth (tests/support/reference.py: sympy, rates from R^T dR/dt).

    python tools/accuracy_study.py [--quick] [--out docs/accuracy]

writes accuracy.md (the table, the goal figures and the recommendation), accuracy.csv and accuracy.png
(error against ns per output sample, one point per method and input rate).

Rows:
- source "symbolic": the expressions themselves (exact derivatives), output at 1 kHz.
- source "sampled": the motion sampled at 50/100/200/1000 Hz (positions, and Euler angles with yaw wrapped to
  (-pi, pi] where the attitude is not tangent), then each derivative method of imu_emulator.numerics.derivatives,
  resampled to 1 kHz output by the simulation itself.
- source "attitude-rate": gyro only, at the input sample times, from the sampled Euler angles by the three
  methods of imu_emulator.motion.attitude_rates (Euler-rate formula, the original's dR/dt R^T rotated to the body,
  rotation increments), for the motion that has Euler angles.

Errors are norms of the error vector per sample; "interior" is the middle 90 % of the run, "ends" the first
and last 5 %.  Set-up: scene parsing + kernel generation and compilation into an empty cache directory
+ fitting; ns/sample: the best of a few timed `Simulation.block` calls over the whole run after a warm-up.
"""
from __future__ import annotations

import argparse
import csv
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import sympy as sp

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from imu_emulator.runtime import kernels as kernel_module  # noqa: E402
from imu_emulator import scene_from_dict  # noqa: E402
from imu_emulator.motion.attitude_rates import dcm_rate, euler_rate, increment_rate  # noqa: E402
from imu_emulator.numerics.derivatives import wrap_angles  # noqa: E402
from imu_emulator.scene.model import DEFAULT_DERIVATIVE  # noqa: E402
from imu_emulator.runtime.simulation import Simulation  # noqa: E402
from tests.support.reference import imu_functions, t as T  # noqa: E402

G0 = 9.80665
OUTPUT_HZ = 1000.0
DURATION = 5.0
RATES = (50, 100, 200, 1000)
SAMPLED_METHODS = ("gradient", "central4", "central6", "spline3", "spline5", "spline5c")
# noisy input (logs): position noise of known sigma, fixed seed; smooth is told the sigma
NOISE_M = (1e-3, 1e-2)
NOISY_RATES = (10, 50, 100)
NOISY_METHODS = ("spline3", "spline5c", "smooth")
NOISY_MOTIONS = ("helix", "aggressive")
ECEF = 6.4e6

V_TURN = 20.0                      # m/s; a 1 g coordinated turn: radius V^2/g
R_TURN = V_TURN ** 2 / G0
W_TURN = V_TURN / R_TURN

MOTIONS = {
    # the original tool's full my_imu example
    "helix": dict(xyz=("0.8*5*cos(2*pi*t)", "0.8*5*sin(2*pi*t)", "0.3*5*cos(2*pi*t)"), euler=None,
                  lever=(-0.075, -0.075, 0.025)),
    # 5 m circle once a second, tangent
    "circle": dict(xyz=("5*cos(2*pi*t)", "5*sin(2*pi*t)", "0"), euler=None, lever=(0.1, -0.05, 0.02)),
    # the same circle in ECEF-sized coordinates: the goal's case (cubic spline 0.065 m/s^2 at 100 Hz)
    "circle_ecef": dict(xyz=(f"{ECEF} + 5*cos(2*pi*t)", f"{ECEF} + 5*sin(2*pi*t)", f"{ECEF}"), euler=None,
                        lever=(0.1, -0.05, 0.02)),
    # aggressive: 1 g level turn at 20 m/s (bank 45 deg) with +-40 deg rolls at 2 Hz about the bank,
    # a 0.5 Hz pitch weave and a 2 m height weave; Euler angles given (sampled: yaw wrapped)
    "aggressive": dict(
        xyz=(f"{R_TURN!r}*cos({W_TURN!r}*t)", f"{R_TURN!r}*sin({W_TURN!r}*t)", "2*sin(2*pi*0.5*t)"),
        euler=("pi/4 + 0.7*sin(2*pi*2*t)", "0.15*sin(2*pi*0.5*t)", f"{W_TURN!r}*t + pi/2"),
        lever=(0.1, 0.05, -0.02)),
}


def _sym(text):
    return sp.sympify(text, locals={"t": T, "pi": sp.pi})


class Motion:
    def __init__(self, name, xyz, euler, lever):
        self.name, self.xyz, self.euler, self.lever = name, xyz, euler, lever
        pos = [_sym(e) for e in xyz]
        eul = None if euler is None else [_sym(e) for e in euler]
        self.oracle = imu_functions(pos, eul, lever=lever)
        self._pos = sp.lambdify(T, pos, "numpy")
        self._eul = None if eul is None else sp.lambdify(T, eul, "numpy")

    def position(self, t):
        return np.column_stack([np.broadcast_to(np.asarray(c, float), t.shape) for c in self._pos(t)])

    def euler_samples(self, t):
        return np.column_stack([np.broadcast_to(np.asarray(c, float), t.shape) for c in self._eul(t)])

    def base(self):
        return {"scene": {"rate_hz": OUTPUT_HZ}, "imu": [{"name": "imu0", "lever_arm_m": list(self.lever)}],
                "effects": {"gravity": True, "lever_arm": True}}

    def symbolic_scene(self):
        raw = self.base()
        raw["scene"]["duration_s"] = DURATION
        raw["trajectory"] = dict(zip("xyz", self.xyz))
        raw["attitude"] = ({"mode": "tangent"} if self.euler is None
                           else {"mode": "euler", **dict(zip(("roll", "pitch", "yaw"), self.euler))})
        return scene_from_dict(raw)

    def sampled_scene(self, rate, method, noise=None):
        t = np.arange(int(round(DURATION * rate)) + 1) / rate
        raw = self.base()
        position = self.position(t)
        if noise:
            position = position + np.random.default_rng(rate).normal(0.0, noise, position.shape)
        traj = {"t": t, "position": position, "derivative": method}
        if noise is not None and method == "smooth":
            traj["position_noise_m"] = noise
        if self.euler is None:
            raw["attitude"] = {"mode": "tangent"}
        else:
            e = self.euler_samples(t)
            e[:, 2] = wrap_angles(e[:, 2])          # as a logger writes yaw; the simulation unwraps
            traj["euler"] = e
            # only the positions are noisy: the angles keep the default method
            raw["attitude"] = {"mode": "file", "derivative": DEFAULT_DERIVATIVE if method == "smooth" else method}
        raw["trajectory"] = traj
        return scene_from_dict(raw)


def _stats(err: np.ndarray):
    """err (n, 3) -> (max, rms) of the vector norm over the interior and over both 5 % ends."""
    norm = np.linalg.norm(err, axis=1)
    n = norm.size
    e = max(1, int(round(0.05 * n)))
    inner, ends = norm[e:n - e], np.concatenate([norm[:e], norm[n - e:]])
    rms = lambda x: float(np.sqrt(np.mean(x * x)))  # noqa: E731
    return float(inner.max()), rms(inner), float(ends.max()), rms(ends)


_CACHES: list[str] = []


def _fresh_cache():
    """An empty kernel cache directory and an empty in-memory cache: the next compile is a real one."""
    directory = tempfile.mkdtemp(prefix="imu-acc-cache-")
    _CACHES.append(directory)
    os.environ["IMU_EMULATOR_CACHE"] = directory
    kernel_module._loaded.clear()
    return directory


def _time_blocks(sim, n, repeats):
    sim.block(0, n)                                   # warm-up (kernel loaded, caches hot)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        sim.block(0, n)
        best = min(best, time.perf_counter() - start)
    return best / n * 1e9


def _time_call(fn, n, repeats):
    fn()
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best / n * 1e9


def run_study(rates, repeats, fresh_compile_each, log=print):
    rows = []
    for name, spec in MOTIONS.items():
        motion = Motion(name, **spec)
        truth_times = None
        compile_cost = {}

        def simulate(kind, build, rate, method):
            nonlocal truth_times
            if fresh_compile_each or kind not in compile_cost:
                _fresh_cache()
                start = time.perf_counter()
                scene = build()
                sim = Simulation(scene)
                sim.block(0, 1)                       # numba compiles on the first call
                setup = time.perf_counter() - start
                compile_cost[kind] = setup
            else:
                start = time.perf_counter()
                scene = build()
                sim = Simulation(scene)
                sim.block(0, 1)
                # kernel already loaded: add the measured compile of this kernel kind once more
                setup = time.perf_counter() - start + compile_cost[kind]
            out = sim.run()
            if truth_times is None or not np.array_equal(truth_times[0], out.t_s):
                truth_times = (out.t_s, *motion.oracle(out.t_s))
            _, acc, gyro = truth_times
            ns = _time_blocks(sim, sim.n_samples, repeats)
            f = _stats(out.accel[0] - acc)
            w = _stats(out.gyro[0] - gyro)
            rows.append(dict(motion=name, source=kind, method=method, input_hz=rate, output_hz=int(OUTPUT_HZ),
                             f_max_interior=f[0], f_rms_interior=f[1], f_max_ends=f[2], f_rms_ends=f[3],
                             w_max_interior=w[0], w_rms_interior=w[1], w_max_ends=w[2], w_rms_ends=w[3],
                             setup_s=setup, ns_per_sample=ns))
            log(f"{name:12s} {kind:9s} {method:9s} {str(rate):>5s} Hz  f {f[0]:.2e}/{f[2]:.2e}  "
                f"w {w[0]:.2e}/{w[2]:.2e}  setup {setup:.2f} s  {ns:.0f} ns/sample")

        simulate("symbolic", motion.symbolic_scene, "exact", "-")
        for rate in rates:
            for method in SAMPLED_METHODS:
                simulate("sampled", lambda: motion.sampled_scene(rate, method), rate, method)
        if name.startswith("circle") and 1000 in rates:
            # the rounding floor of ECEF-sized coordinates, and what smoothing with no stated noise does to it
            simulate("sampled", lambda: motion.sampled_scene(1000, "smooth", noise=0.0), 1000, "smooth")
        if name in NOISY_MOTIONS:
            for sigma in NOISE_M:
                for rate in NOISY_RATES:
                    for method in NOISY_METHODS:
                        simulate(f"noisy {sigma * 1e3:g} mm", lambda: motion.sampled_scene(rate, method, sigma),
                                 rate, method)

        if motion.euler is not None:
            for rate in rates:
                t = np.arange(int(round(DURATION * rate)) + 1) / rate
                e = motion.euler_samples(t)
                e[:, 2] = wrap_angles(e[:, 2])
                _, gyro = motion.oracle(t)
                for label, fn in (("euler+spline5c", lambda: euler_rate(t, e, "spline5c")),
                                  ("euler+spline5", lambda: euler_rate(t, e, "spline5")),
                                  ("dcm+gradient", lambda: dcm_rate(t, e, "gradient")),
                                  ("dcm+spline5c", lambda: dcm_rate(t, e, "spline5c")),
                                  ("increment2", lambda: increment_rate(t, e, 2)),
                                  ("increment4", lambda: increment_rate(t, e, 4)),
                                  ("increment6", lambda: increment_rate(t, e, 6))):
                    start = time.perf_counter()
                    w_est = fn()
                    setup = time.perf_counter() - start
                    ns = _time_call(fn, t.size, repeats)
                    w = _stats(w_est - gyro)
                    nan = float("nan")
                    rows.append(dict(motion=name, source="attitude-rate", method=label, input_hz=rate,
                                     output_hz=rate, f_max_interior=nan, f_rms_interior=nan, f_max_ends=nan,
                                     f_rms_ends=nan, w_max_interior=w[0], w_rms_interior=w[1], w_max_ends=w[2],
                                     w_rms_ends=w[3], setup_s=setup, ns_per_sample=ns))
                    log(f"{name:12s} att-rate  {label:15s} {rate:>5d} Hz  w {w[0]:.2e}/{w[2]:.2e}  {ns:.0f} ns/sample")
    return rows


COLUMNS = ["motion", "source", "method", "input_hz", "output_hz", "f_max_interior", "f_rms_interior", "f_max_ends",
           "f_rms_ends", "w_max_interior", "w_rms_interior", "w_max_ends", "w_rms_ends", "setup_s", "ns_per_sample"]


def _fmt(value):
    if isinstance(value, float):
        if np.isnan(value):
            return "-"
        return f"{value:.2e}" if value < 0.01 or value >= 1e4 else f"{value:.3g}"
    return str(value)


def write_csv(rows, path):
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})


def _find(rows, motion, method, rate):
    for row in rows:
        if row["motion"] == motion and row["method"] == method and row["input_hz"] == rate:
            return row
    return None


def goal_lines(rows):
    lines = []
    spline3 = _find(rows, "circle_ecef", "spline3", 100)
    for method in ("spline5", "spline5c", "central6"):
        row = _find(rows, "circle_ecef", method, 100)
        if spline3 and row:
            lines.append(f"- ECEF circle, 100 Hz input: {method} interior max |f error| {row['f_max_interior']:.2e} "
                         f"m/s² vs spline3 {spline3['f_max_interior']:.2e} m/s²: "
                         f"{spline3['f_max_interior'] / row['f_max_interior']:.0f}× smaller "
                         f"(goal ≥ 10×); ends/interior {row['f_max_ends'] / row['f_max_interior']:.1f} for f, "
                         f"{row['w_max_ends'] / row['w_max_interior']:.1f} for ω (goal ≤ 2)")
    for method in ("spline5", "spline5c"):
        ratios = []
        for row in rows:
            if row["method"] == method and row["source"] == "sampled":
                ratios.append(f"{row['motion']}@{row['input_hz']}: {row['f_max_ends'] / row['f_max_interior']:.1f}"
                              f"/{row['w_max_ends'] / row['w_max_interior']:.1f}")
        if ratios:
            lines.append(f"- {method} ends/interior (max f / max ω): " + ", ".join(ratios))
    origin = _find(rows, "circle", "spline5c", 1000)
    for method in ("spline5c", "smooth"):
        row = _find(rows, "circle_ecef", method, 1000)
        if origin and row:
            lines.append(f"- ECEF circle, 1 kHz input, {method}: interior max |f error| {row['f_max_interior']:.2e} "
                         f"m/s² vs the circle at the origin (spline5c) {origin['f_max_interior']:.2e}: "
                         f"{row['f_max_interior'] / origin['f_max_interior']:.0f}× (goal ≤ 10×)")
    for row in rows:
        if row["source"].startswith("noisy") and row["method"] == "smooth":
            best = min((r for r in rows if r["source"] == row["source"] and r["motion"] == row["motion"]
                        and r["input_hz"] == row["input_hz"]), key=lambda r: r["f_rms_interior"])
            other = _find_source(rows, row["motion"], "spline5c", row["input_hz"], row["source"])
            lines.append(f"- {row['motion']}, {row['source']} at {row['input_hz']} Hz: smooth f rms "
                         f"{row['f_rms_interior']:.2e}, ω rms {row['w_rms_interior']:.2e}; spline5c f rms "
                         f"{other['f_rms_interior']:.2e} ({other['f_rms_interior'] / row['f_rms_interior']:.0f}×); "
                         f"best: {best['method']}")
    return lines


def _find_source(rows, motion, method, rate, source):
    for row in rows:
        if (row["motion"], row["method"], row["input_hz"], row["source"]) == (motion, method, rate, source):
            return row
    return None


def write_markdown(rows, path, command, elapsed):
    head = ["motion", "source", "method", "in Hz", "out Hz", "f max int", "f rms int", "f max ends", "f rms ends",
            "ω max int", "ω rms int", "ω max ends", "ω rms ends", "set-up s", "ns/sample"]
    out = ["# What accuracy costs in time", "",
           f"Regenerate: `{command}` ({elapsed:.0f} s on the machine that wrote this). Errors are the norm of the "
           "error vector per sample against an independent sympy derivation (tests/support/reference.py): specific force "
           "f at the IMU in m/s², angular rate ω in rad/s; *int* = middle 90 % of the 5 s run, *ends* = first and "
           "last 5 %. Set-up = scene parsing + kernel generation/compilation into an empty cache + fitting; "
           "ns/sample = one `Simulation.block` over the run after warm-up (sampled rows include evaluating "
           "the fitted derivatives). `attitude-rate` rows: gyro only, at the input times, from sampled Euler "
           "angles (imu_emulator.motion.attitude_rates). Plot: [accuracy.png](accuracy.png); data: "
           "[accuracy.csv](accuracy.csv).", "",
           f"Default derivative method for sampled input in this tree: `{DEFAULT_DERIVATIVE}`.", "",
           "## Goal figures", ""]
    out += goal_lines(rows) + ["", "## Table", ""]
    out.append("| " + " | ".join(head) + " |")
    out.append("|" + "---|" * len(head))
    for row in rows:
        out.append("| " + " | ".join(_fmt(row[c]) for c in COLUMNS) + " |")
    Path(path).write_text("\n".join(out) + "\n")


def write_plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    motions = list(MOTIONS)
    fig, axes = plt.subplots(2, len(motions), figsize=(4.2 * len(motions), 8), squeeze=False)
    methods = sorted({r["method"] for r in rows})
    colors = {m: plt.cm.tab20(i % 20) for i, m in enumerate(methods)}
    sizes = {50: 20, 100: 40, 200: 70, 1000: 120}
    for j, motion in enumerate(motions):
        for i, (key, label) in enumerate((("f_max_interior", "f"), ("w_max_interior", "ω"))):
            ax = axes[i][j]
            for r in rows:
                if r["motion"] != motion or not np.isfinite(r[key]):
                    continue
                value = max(r[key], 1e-14)
                ax.scatter(r["ns_per_sample"], value, color=colors[r["method"]], s=sizes.get(r["input_hz"], 30),
                           marker="*" if r["source"] == "symbolic" else ("s" if r["source"] == "attitude-rate" else "o"),
                           edgecolors="k", linewidths=0.3, label=r["method"])
                end = r[key.replace("interior", "ends")]
                ax.scatter(r["ns_per_sample"], max(end, 1e-14), facecolors="none", edgecolors=colors[r["method"]],
                           s=sizes.get(r["input_hz"], 30), linewidths=0.8)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_title(f"{motion}: {label}")
            ax.set_xlabel("ns per output sample")
            ax.set_ylabel(f"max |{label} error| ({'m/s²' if label == 'f' else 'rad/s'})")
            ax.grid(True, which="major", alpha=0.3)
    handles, labels = [], []
    for ax in axes.flat:
        for h, l in zip(*ax.get_legend_handles_labels()):
            if l not in labels:
                handles.append(h)
                labels.append(l)
    fig.legend(handles, labels, loc="lower center", ncol=min(8, len(labels)), fontsize=8)
    fig.suptitle("Error vs cost; filled: interior max, hollow: ends max; marker size: input rate 50/100/200/1000 Hz")
    fig.tight_layout(rect=(0, 0.06, 1, 0.97))
    fig.savefig(path, dpi=110)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="100 and 1000 Hz input only, one compile per kernel kind")
    parser.add_argument("--out", default=str(ROOT / "docs" / "accuracy"), help="output directory")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    old_cache = os.environ.get("IMU_EMULATOR_CACHE")
    start = time.perf_counter()
    try:
        rows = run_study(rates=(100, 1000) if args.quick else RATES, repeats=2 if args.quick else 5,
                         fresh_compile_each=not args.quick)
    finally:
        for directory in _CACHES:
            shutil.rmtree(directory, ignore_errors=True)
        if old_cache is None:
            os.environ.pop("IMU_EMULATOR_CACHE", None)
        else:
            os.environ["IMU_EMULATOR_CACHE"] = old_cache
    elapsed = time.perf_counter() - start
    command = "python tools/accuracy_study.py" + (" --quick" if args.quick else "")
    write_csv(rows, out / "accuracy.csv")
    write_markdown(rows, out / "accuracy.md", command, elapsed)
    write_plot(rows, out / "accuracy.png")
    print(f"wrote {out / 'accuracy.md'}, accuracy.csv, accuracy.png in {elapsed:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
