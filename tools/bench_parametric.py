"""Baked numbers against run-time parameters (issue 25), and what a --vary batch compiles.

Part 1, the kernel: the same generated source twice, once as the cache builds it (the scene's numbers read from
the array `prm` into locals prm_i once per call) and once "baked" (each `prm_i = prm[i]` replaced by the value's
repr, so LLVM folds it as it folded the literals the generator used to write). Both are compiled here, outside
the cache, and called on the same Simulation's arguments, interleaved A, B, A, B, ... (a shared 2-vCPU machine
varies 2-3x between runs: only the ratio inside one run means something). Thread CPU time of the kernel call
alone; min / median / max ns per sample, the ratio of medians.

With expressions whose numbers the kernel takes at run time (imu_emulator.numerics.expressions.lift), a third
variant: the source with those numbers as literals sympy folded into the derivatives (as generated before).

Part 1b, the outputs: one kernel whose attitude and truth outputs are switched by the arrays passed, against the
kernel generated for each of generate, generate --truth and stream (attitude), interleaved likewise.

Part 2, a batch: `--runs N` realizations of a scene with --vary draws of sensor parameters, in this process
(--workers 0) in a fresh cache: how many kernels were compiled (cache entries), the first load's time, the
batch's wall and CPU time.

    PYTHONPATH=. python tools/bench_parametric.py [--scene examples/drone_imu.toml] [--rounds 7] [--samples 200000]
                                                  [--runs 100] [--skip-batch] [--skip-outputs]
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import os
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def machine() -> str:
    model = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = os.getloadavg()
    return f"{model}, {os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}"


def _compile(source: str, directory: Path, name: str):
    path = directory / f"{name}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module.kernel


def baked(source: str, values) -> str:
    """The source with every scalar parameter a literal again."""
    return re.sub(r"^(\s*)prm_(\d+) = prm\[\d+\]$", lambda m: f"{m[1]}prm_{m[2]} = {float(values[int(m[2])])!r}",
                  source, flags=re.M)


def timed_block(sim, kernel, n: int, out) -> float:
    """Thread CPU ns per sample of `kernel` alone, computing samples 0..n-1 of `sim` into `out` (the same arrays
    every round: fresh ones would put first-touch page faults inside the timed call)."""
    spent = 0

    def timed(*args):
        nonlocal spent
        start = time.thread_time_ns()
        kernel(*args)
        spent += time.thread_time_ns() - start
    sim.kernel = timed
    sim.block(0, n, out=out)
    return spent / n


def literal_expressions(scene, attitude: bool, truth: bool) -> str:
    """The source as the generator wrote it before the expressions' numbers were lifted (issue 25 (a)): sympy folds
    them with the derivatives' factors into literals (5*cos(0.3 t) -> a = -0.45 cos(..)); the motion's slots in
    `prm` are then unread."""
    from imu_emulator.codegen.generate import generate_source
    from imu_emulator.motion import code
    original = code.motion_code
    code.motion_code = lambda *a, slots=None, **k: original(*a, **k)
    try:
        return generate_source(scene, attitude=attitude, truth=truth)
    finally:
        code.motion_code = original


def bench_kernel(scene_path: str, rounds: int, samples: int) -> None:
    from imu_emulator import load_scene
    from imu_emulator.codegen.generate import generate_source
    from imu_emulator.runtime import kernels
    from imu_emulator.runtime.simulation import Simulation

    scene = load_scene(scene_path)
    # long enough for `samples` (the duration is a run-time number: the source is the same)
    scene = dataclasses.replace(scene, duration_s=max(scene.duration_s, samples / scene.rate_hz))
    sim = Simulation(scene, attitude=False)
    source = generate_source(scene, attitude=False, truth=False)
    values = sim._plan.param_values()
    kernels._realize_runtime()
    with tempfile.TemporaryDirectory() as tmp:
        variants = {}
        literal = literal_expressions(scene, attitude=False, truth=False)
        for name, text in (("parametric", source), ("baked", baked(source, values)),
                           ("literal-expressions", literal if literal != source else None)):
            if text is None:     # no expression numbers in this scene: the same source as parametric
                continue
            start = time.process_time()
            variants[name] = _compile(text, Path(tmp), f"bench_parametric_{name}")
            sim.kernel = variants[name]
            sim.block(0, 10)              # compiles
            print(f"{name}: compiled in {time.process_time() - start:.1f} s CPU")
        spent = {name: [] for name in variants}
        n = min(samples, sim.n_samples)
        out = sim._new_block(0, sim.times(0, n))
        for r in range(rounds):
            # the order alternates, and each writes into the same arrays (no first-touch page faults inside)
            for name, kernel in list(variants.items())[::1 if r % 2 else -1]:
                spent[name].append(timed_block(sim, kernel, n, out))
        for name, values_ns in spent.items():
            print(f"{name:>19}: {min(values_ns):6.1f} / {statistics.median(values_ns):6.1f} / "
                  f"{max(values_ns):6.1f} ns per sample (min / median / max of {rounds}, {n} samples each)")
        for other in variants:
            if other != "parametric":
                ratio = statistics.median(spent["parametric"]) / statistics.median(spent[other])
                print(f"parametric / {other} (medians): {ratio:.3f}")


def bench_outputs(scene_path: str, rounds: int, samples: int) -> None:
    """One kernel with switched outputs (generate_source(switched=True): the attitude and truth written only when
    their arrays are passed) against the kernel generated for each choice of outputs, called on the same
    Simulation's arguments, interleaved; thread CPU time of the kernel call."""
    from imu_emulator import load_scene
    from imu_emulator.codegen.generate import generate_source
    from imu_emulator.runtime import kernels
    from imu_emulator.runtime.simulation import Simulation

    scene = load_scene(scene_path)
    scene = dataclasses.replace(scene, duration_s=max(scene.duration_s, samples / scene.rate_hz))
    kernels._realize_runtime()
    choices = {"generate": (False, False), "generate --truth": (False, True), "stream": (True, False)}
    with tempfile.TemporaryDirectory() as tmp:
        start = time.process_time()
        switched = _compile(generate_source(scene, False, False, switched=True), Path(tmp), "bench_outputs_switched")
        print(f"switched: generated in {time.process_time() - start:.1f} s CPU")
        runs = {}
        for i, (name, (attitude, truth)) in enumerate(choices.items()):
            sim = Simulation(scene, attitude=attitude, truth=truth)
            own = _compile(generate_source(scene, attitude, truth), Path(tmp), f"bench_outputs_{i}")
            for kernel in (own, switched):   # compiles (numba: on the first call with these types)
                sim.kernel = kernel
                sim.block(0, 10)
            runs[name] = (sim, own)
        n = min(samples, scene.n_samples)
        spent = {(name, variant): [] for name in choices for variant in ("own", "switched")}
        outs = {name: sim._new_block(0, sim.times(0, n)) for name, (sim, _) in runs.items()}
        for r in range(rounds):
            for name, (sim, own) in runs.items():
                # the order alternates, and each writes into the same arrays (no first-touch page faults inside)
                for variant, kernel in (("own", own), ("switched", switched))[::1 if r % 2 else -1]:
                    spent[name, variant].append(timed_block(sim, kernel, n, outs[name]))
        for name in choices:
            own, one = spent[name, "own"], spent[name, "switched"]
            print(f"{name:>17}: own kernel {min(own):6.1f} / {statistics.median(own):6.1f} / {max(own):6.1f}, "
                  f"switched {min(one):6.1f} / {statistics.median(one):6.1f} / {max(one):6.1f} ns per sample "
                  f"(min / median / max of {rounds}); switched / own (medians) "
                  f"{statistics.median(one) / statistics.median(own):.3f}")


def bench_batch(scene_path: str, runs: int, vary: list[str]) -> None:
    from imu_emulator.analysis import batch

    with tempfile.TemporaryDirectory() as tmp:
        os.environ["IMU_EMULATOR_CACHE"] = str(Path(tmp) / "cache")
        wall, cpu = time.perf_counter(), time.process_time()
        result = batch.run(scene_path, runs, 1, Path(tmp) / "out", executor=None, vary=vary)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        entries = [p for p in (Path(tmp) / "cache" / "kernels").iterdir() if not p.name.startswith(".")]
        loads = [r["kernel_load_s"] for r in result.rows if r["kernel_load_s"] is not None]
        print(f"batch of {runs} with --vary {' --vary '.join(vary)}: {len(entries)} kernel(s) compiled, "
              f"{len(loads)} load(s) ({', '.join(f'{s:.1f} s' for s in loads)}), {len(result.failures)} failed; "
              f"{wall:.1f} s wall, {cpu:.1f} s CPU ({cpu / runs:.2f} s CPU per realization)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default=str(ROOT / "examples" / "drone_imu.toml"))
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--samples", type=int, default=200_000)
    parser.add_argument("--runs", type=int, default=100)
    parser.add_argument("--vary", action="append", default=None)
    parser.add_argument("--skip-batch", action="store_true")
    parser.add_argument("--skip-outputs", action="store_true", help="skip part 1b (the switched outputs)")
    args = parser.parse_args()
    print(machine())
    print(f"scene {args.scene}")
    bench_kernel(args.scene, args.rounds, args.samples)
    if not args.skip_outputs:
        bench_outputs(args.scene, args.rounds, args.samples)
    if not args.skip_batch:
        from imu_emulator import load_scene
        imu = load_scene(args.scene).imu_names[0]
        vary = args.vary or [f"{imu}.gyro.noise_density=uniform(0.001,0.01)", f"{imu}.accel.bias=normal(0,0.05)"]
        bench_batch(args.scene, args.runs, vary)
    print(machine())


if __name__ == "__main__":
    main()
