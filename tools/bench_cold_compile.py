"""A scene's first run (empty kernel cache: the kernel is generated, compiled and exported as machine code) in this
tree against another revision's (default `main`), interleaved: `generate SCENE -o x.npz` as a whole process, wall
time and the process's CPU time (user + sys), each run with a kernel cache of its own; and the compile alone, what
`generate`'s status line reports ("compiled in 2.1 s"): building the Simulation in a fresh process whose package
and scene are loaded (the imports numba and sympy need for the kernel are part of it, as for the status line).

    .venv/bin/python tools/bench_cold_compile.py [--ref main] [--scene examples/helix.toml] [--rounds 5]

The other revision is exported with `git archive` (bench_against.export); both run with this virtualenv's Python
and with their bytecode cached. Prints min/median per tree and the CPU ratio per round; asserts nothing.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_against import ROOT, export  # noqa: E402


def cold_run(tree: Path, scene: str, env: dict) -> tuple[float, float]:
    """Wall and CPU seconds of one `generate` of `scene` in `tree` with an empty kernel cache."""
    with tempfile.TemporaryDirectory() as tmp:
        started = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", "imu_emulator", "generate", scene, "-o", f"{tmp}/x.npz",
                                 "--quiet"], cwd=tree, env=dict(env, IMU_EMULATOR_CACHE=f"{tmp}/cache"),
                                stderr=subprocess.PIPE)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.monotonic() - started
        if os.waitstatus_to_exitcode(status):
            raise SystemExit(f"generate {scene} in {tree} failed: {proc.stderr.read().decode().strip()}")
        return wall, usage.ru_utime + usage.ru_stime


#: a fresh process: load the package and the scene, then time what CompileStatus wraps in `generate`
_COMPILE_ONLY = """
import sys, time
from imu_emulator.scene.load import load_scene
from imu_emulator.runtime.simulation import Simulation
scene = load_scene(sys.argv[1])
wall, cpu = time.perf_counter(), time.thread_time()
Simulation(scene, attitude=False)
print(time.perf_counter() - wall, time.thread_time() - cpu)
"""


def compile_run(tree: Path, scene: str, env: dict) -> tuple[float, float]:
    """Wall and thread CPU seconds of building the Simulation of `scene` in `tree` with an empty kernel cache."""
    with tempfile.TemporaryDirectory() as tmp:
        done = subprocess.run([sys.executable, "-c", _COMPILE_ONLY, scene], cwd=tree, capture_output=True, text=True,
                              env=dict(env, IMU_EMULATOR_CACHE=f"{tmp}/cache", PYTHONPATH=str(tree)))
        if done.returncode:
            raise SystemExit(f"compiling {scene} in {tree} failed: {done.stderr.strip()}")
        wall, cpu = (float(x) for x in done.stdout.split())
        return wall, cpu


def _summary(title: str, runs: dict, ref: str) -> None:
    print(title)
    for name, values in runs.items():
        cpu, wall = [c for _, c in values], [w for w, _ in values]
        print(f"  {name:10s} CPU {min(cpu):.2f}/{statistics.median(cpu):.2f} s, wall {min(wall):.2f}/"
              f"{statistics.median(wall):.2f} s")
    ratios = sorted(m[1] / r[1] for r, m in zip(runs[ref], runs["this tree"]))
    print(f"  CPU ratio this tree / {ref} per round: min {ratios[0]:.2f}, median {statistics.median(ratios):.2f}"
          f" (1-minute load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ref", default="main", help="the git revision to compare with")
    parser.add_argument("--scene", default="examples/helix.toml")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    # bytecode cached, as users run it (a shell's PYTHONDONTWRITEBYTECODE would time compiling the sources)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    with tempfile.TemporaryDirectory() as tmp:
        trees = {args.ref: export(args.ref, Path(tmp)), "this tree": ROOT}
        for tree in trees.values():      # writes each tree's bytecode; the timed runs start from it
            cold_run(tree, args.scene, env)
        runs = {name: [] for name in trees}
        compiles = {name: [] for name in trees}
        for r in range(args.rounds):     # interleaved: the machine is shared
            for name, tree in trees.items():
                runs[name].append(cold_run(tree, args.scene, env))
                compiles[name].append(compile_run(tree, args.scene, env))
            ref, mine = runs[args.ref][-1], runs["this tree"][-1]
            print(f"round {r}: CPU {args.ref} {ref[1]:.2f} s, this tree {mine[1]:.2f} s (ratio {mine[1] / ref[1]:.2f});"
                  f" wall {ref[0]:.2f} / {mine[0]:.2f} s; compile alone wall {compiles[args.ref][-1][0]:.2f} / "
                  f"{compiles['this tree'][-1][0]:.2f} s", flush=True)
    _summary(f"cold generate {args.scene}, whole process (min/median of {args.rounds}):", runs, args.ref)
    _summary(f"compile alone (the Simulation built in a loaded process, thread CPU; min/median of {args.rounds}):",
             compiles, args.ref)


if __name__ == "__main__":
    main()
