"""A scene's first run (empty kernel cache: the kernel is generated, compiled and exported as machine code) in this
tree against another revision's (default `main`), interleaved: `generate SCENE -o x.npz` as a whole process, wall
time and the process's CPU time (user + sys), each run with a kernel cache of its own.

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
        for r in range(args.rounds):     # interleaved: the machine is shared
            for name, tree in trees.items():
                runs[name].append(cold_run(tree, args.scene, env))
            ref, mine = runs[args.ref][-1], runs["this tree"][-1]
            print(f"round {r}: CPU {args.ref} {ref[1]:.2f} s, this tree {mine[1]:.2f} s (ratio {mine[1] / ref[1]:.2f});"
                  f" wall {ref[0]:.2f} / {mine[0]:.2f} s", flush=True)
    print(f"cold generate {args.scene}, whole process (min/median of {args.rounds}):")
    for name, values in runs.items():
        cpu, wall = [c for _, c in values], [w for w, _ in values]
        print(f"  {name:10s} CPU {min(cpu):.2f}/{statistics.median(cpu):.2f} s, wall {min(wall):.2f}/"
              f"{statistics.median(wall):.2f} s")
    ratios = sorted(m[1] / r[1] for r, m in zip(runs[args.ref], runs["this tree"]))
    print(f"  CPU ratio this tree / {args.ref} per round: min {ratios[0]:.2f}, median {statistics.median(ratios):.2f}"
          f" (1-minute load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs)")


if __name__ == "__main__":
    main()
