"""A warm `generate` of this tree against another revision's (default `main`), interleaved: modules imported, the
process's CPU time (user + sys, from getrusage of the reaped child) and wall time, each run a fresh interpreter.

    .venv/bin/python tools/bench_startup_against.py [--ref main] [--rounds 9] [--scene examples/drone_imu.toml]

The other revision is exported with `git archive` into a temporary directory (nothing in a worktree is touched) and
run with PYTHONPATH set to it (the probe checks which tree `imu_emulator` came from). Each tree has its own kernel
cache, filled by one run before the rounds (so every timed run is warm: kernel and CSV loops loaded from the cache,
bytecode written). The rounds alternate the trees (A, B, A, B, ...) so the shared machine's load falls on both
alike. The default scene is written with datasheet units ("2 deg/h", "40 ug", "0.2 %", a preset's "deg/s/sqrt(Hz)")
and both revisions read it. Prints min/median/max per tree, the ratio of the medians (this tree / the other), which
heavy packages each imported, the CPU model and the load average; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("pint", "dask", "distributed", "babel", "pandas", "matplotlib", "sympy", "numba", "scipy", "pyarrow")
PROBE = """
import json, sys
tree = sys.argv.pop(1)
from imu_emulator.cli import main
import imu_emulator
if not imu_emulator.__file__.startswith(tree):
    raise SystemExit(f"imported {imu_emulator.__file__}, not the tree {tree}")
code = main(sys.argv[1:])
print(json.dumps({"code": code, "modules": len(sys.modules), "heavy": [m for m in HEAVY if m in sys.modules]}))
""".replace("HEAVY", repr(HEAVY))


def export(ref: str, into: Path) -> Path:
    """`git archive REF` unpacked into `into` (the repository's other worktrees and checkout untouched)."""
    archive = into / "ref.tar"
    with open(archive, "wb") as out:
        subprocess.run(["git", "-C", str(ROOT), "archive", ref], stdout=out, check=True)
    tree = into / "ref"
    with tarfile.open(archive) as tar:
        tar.extractall(tree, filter="data")
    return tree


def run(tree: Path, scene: Path, out: Path, cache: Path) -> tuple[float, dict]:
    """Wall seconds and the probe's report of one generate (its CPU: children_cpu() before and after)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env.update(PYTHONPATH=str(tree), IMU_EMULATOR_CACHE=str(cache))
    started = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-c", PROBE, str(tree), "generate", str(scene), "-o", str(out),
                             "--quiet"], cwd=tree, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    stdout, stderr = proc.communicate()
    wall = time.monotonic() - started
    if proc.returncode:
        raise SystemExit(f"generate with {tree} failed: {stderr.decode().strip()}")
    return wall, json.loads(stdout.decode().strip().splitlines()[-1])


def children_cpu() -> float:
    """User + sys seconds of this process's reaped children so far (one child at a time: differences are per run)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown CPU"


def summary(values, fmt="{:.3f}") -> str:
    return "/".join(fmt.format(v) for v in (min(values), statistics.median(values), max(values)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ref", default="main", help="the other revision (default main)")
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--scene", default="examples/drone_imu.toml")
    args = parser.parse_args()
    scene = (ROOT / args.scene).resolve()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        trees = {"ref": export(args.ref, tmp), "this": ROOT}
        figures = {name: {"wall": [], "cpu": [], "modules": [], "heavy": set()} for name in trees}
        for name, tree in trees.items():        # fill each tree's kernel cache (and write its bytecode)
            run(tree, scene, tmp / f"{name}.csv", tmp / f"cache-{name}")
        for _ in range(args.rounds):             # interleaved: the machine is shared
            for name, tree in trees.items():
                before = children_cpu()
                wall, report = run(tree, scene, tmp / f"{name}.csv", tmp / f"cache-{name}")
                figures[name]["wall"].append(wall)
                figures[name]["cpu"].append(children_cpu() - before)
                figures[name]["modules"].append(report["modules"])
                figures[name]["heavy"] |= set(report["heavy"])
        same = (tmp / "ref.csv").read_bytes() == (tmp / "this.csv").read_bytes()
    labels = {"ref": f"{args.ref}", "this": "this tree"}
    print(f"warm `generate {args.scene} -o x.csv`, {args.rounds} rounds interleaved (min/median/max):")
    for name, f in figures.items():
        print(f"  {labels[name]:10s} modules {summary(f['modules'], '{:d}')}, CPU {summary(f['cpu'])} s, "
              f"wall {summary(f['wall'])} s; heavy packages imported: {', '.join(sorted(f['heavy'])) or 'none'}")
    for key in ("modules", "cpu", "wall"):
        ratio = statistics.median(figures["this"][key]) / statistics.median(figures["ref"][key])
        print(f"  ratio of medians, this tree / {args.ref}, {key}: {ratio:.2f}")
    print(f"  the two CSV files are {'identical' if same else 'DIFFERENT'}")
    print(f"{cpu_model()}, {os.cpu_count()} CPUs; 1-minute load average {load_before[0]:.1f} before, "
          f"{os.getloadavg()[0]:.1f} after")


if __name__ == "__main__":
    main()
