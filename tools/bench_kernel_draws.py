"""What the full error model's per-sample draws cost inside the generated kernel (issue 25), and whether drawing
them in a pass per chunk helps there.

    .venv/bin/python tools/bench_kernel_draws.py [--rounds 15]

The full model's kernel source (tools/bench_effects.py's circle scene and FULL effects) is generated, then edited
as text into variants, each compiled by numba from a temporary module and called on the same arguments:
  - "kernel": the source as generated;
  - "no draws": every per-sample normal(keys[i], s) replaced by a constant-cost stand-in (s & 7) - 3.5, the bound
    any faster normal could reach (its output differs, of course);
  - "chunk pass, vectorized" / "chunk pass, scalar": each chunk's per-sample normals drawn first into a scratch
    array (tools/bench_normals.py's vectorized pass, or a plain loop), which the sample loop then reads; their
    output is checked equal to the kernel's.
Interleaved rounds of 65 536 samples, thread CPU; prints ns/sample min / median and per-round ratios to
"kernel". Variants are throwaway text edits: the edits are checked to have happened, not kept anywhere.
"""
from __future__ import annotations

import argparse
import importlib.util
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

TOOLS = Path(__file__).resolve().parent
sys.path.insert(0, str(TOOLS.parent))
sys.path.insert(0, str(TOOLS))

from bench_effects import FULL, circle  # noqa: E402
from bench_normals import interleave, report  # noqa: E402

from imu_emulator.codegen.generate import generate_source  # noqa: E402
from imu_emulator.codegen.plan import EffectPlan  # noqa: E402
from imu_emulator.codegen.signature import EMPTY3, arguments  # noqa: E402
from imu_emulator.native.lazy import realize  # noqa: E402

N = 65536
DRAW = re.compile(r"normal\(keys\[(\d+)\], s\)")
FILLS = '''
from bench_normals import _chunk as fill_vectorized
NIDS = np.array({ids!r})


@numba.njit(nogil=True)
def fill_scalar(keys, s0, m, buf):
    for i in range(keys.shape[0]):
        for jj in range(m):
            buf[i, jj] = normal(keys[i], s0 + jj)
'''


def _edit(source: str, old: str, new: str) -> str:
    if old not in source:
        raise SystemExit(f"error: the generated source has no {old!r}: this benchmark needs updating")
    return source.replace(old, new, 1)


def variants(source: str) -> dict[str, str]:
    ids = sorted({int(i) for i in DRAW.findall(source)})
    out = {"kernel": source, "no draws": DRAW.sub("(float(s & 7) - 3.5)", source)}
    for label, fill in (("chunk pass, vectorized", "fill_vectorized"), ("chunk pass, scalar", "fill_scalar")):
        text = _edit(source, "from imu_emulator.numerics.counter_rng import normal\n",
                     "from imu_emulator.numerics.counter_rng import normal\n" + FILLS.format(ids=ids))
        for pos, i in enumerate(ids):
            text = text.replace(f"normal(keys[{i}], s)", f"nrm[{pos}, jj]")
        text = _edit(text, "        mc = min(CHUNK, n - c0)\n",
                     f"        mc = min(CHUNK, n - c0)\n        {fill}(skeys, s0 + c0, mc, nrm)\n")
        text = _edit(text, "    hcy, hsy, hcp, hsp = hold[0], hold[1], hold[2], hold[3]\n",
                     "    hcy, hsy, hcp, hsp = hold[0], hold[1], hold[2], hold[3]\n"
                     f"    nrm = np.empty(({len(ids)}, CHUNK))\n    skeys = keys[NIDS]\n")
        out[label] = text
    return out


def load(name: str, text: str, folder: Path):
    path = folder / f"{name}.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module           # realize() patches the deferred helpers into every loaded module
    spec.loader.exec_module(module)
    return module


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=15)
    args = parser.parse_args()
    scene = circle(FULL, 100.0)
    plan = EffectPlan(scene)
    texts = variants(generate_source(scene, attitude=False, truth=False))
    with tempfile.TemporaryDirectory() as folder:
        modules = {label: load(f"draws_variant_{i}", text, Path(folder)) for i, (label, text) in enumerate(texts.items())}
        realize()
        keys, params = plan.keys(1), plan.param_values()
        state = {label: plan.initial_state(1) for label in modules}
        hold = {label: np.array([1.0, 0.0, 1.0, 0.0]) for label in modules}
        acc = {label: np.empty((1, N, 3)) for label in modules}
        gyro = {label: np.empty((1, N, 3)) for label in modules}

        def call(label, s0):
            modules[label].kernel(*arguments(0, N, s0, EMPTY3, EMPTY3, hold[label], keys, state[label], params,
                                             acc[label], gyro[label]))
        for label in modules:
            call(label, 0)
        for label in texts:
            if label.startswith("chunk") and not (np.array_equal(acc[label], acc["kernel"])
                                                  and np.array_equal(gyro[label], gyro["kernel"])):
                raise SystemExit(f"error: {label} does not reproduce the kernel's output")
        times = interleave({label: (lambda r, label=label: call(label, r * N)) for label in modules}, args.rounds, N)
    report(times, "kernel", f"full error model kernel, {N} samples a call, {args.rounds} interleaved rounds, "
           "thread CPU ns/sample")

if __name__ == "__main__":
    main()
