"""Cost of the serial stream decoders on hostile floods: 50 kB and 200 kB of one repeated unit (a '$', the
format's first byte, its header) fed in one call. Prints thread CPU time and wall time (best of --repeats)
and the ratio 200 kB / 50 kB: 4 means linear, 16 quadratic. Prints figures, asserts nothing.

    .venv/bin/python tools/bench_decoder_floods.py [--repeats 3] [--decoders vectornav-vnymr ...]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import firmware_protocols as fp

DECODERS = ("mavlink-highres", "vectornav-binary", "vectornav-vnymr", "xsens-mtdata2", "microstrain-mip")
SIZES = (50_000, 200_000)


def units(name: str) -> dict:
    samples = fp.Samples(time_ns=np.array([0]), accel=np.array([[0.1, 0.2, 9.8]]), gyro=np.array([[0.01, 0.02, 0.03]]))
    packet = fp.create_encoder(name).encode(samples).packet(0)
    found = {"'$'": b"$", "first byte": packet[:1], "header (6 B)": packet[:6]}
    if name == "xsens-mtdata2":
        found["Xbus 8184 B header"] = bytes.fromhex("faff36ff1ff8")
    return found


def cost(name: str, data: bytes, repeats: int) -> tuple[float, float]:
    """Best (CPU s, wall s) of `repeats` runs of a fresh decoder over `data` in one feed."""
    cpu, wall = [], []
    for _ in range(repeats):
        decoder = fp.create_decoder(name)
        c0, w0 = time.thread_time_ns(), time.perf_counter_ns()
        decoder.feed(data)
        cpu.append((time.thread_time_ns() - c0) / 1e9)
        wall.append((time.perf_counter_ns() - w0) / 1e9)
    return min(cpu), min(wall)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--decoders", nargs="*", default=DECODERS, help="format names (one per decoder)")
    args = parser.parse_args()
    print(f"{'decoder':18} {'flood of':20} {'50 kB cpu ms':>12} {'200 kB cpu ms':>13} {'200 kB wall ms':>14} {'ratio':>6}")
    for name in args.decoders:
        for label, unit in units(name).items():
            small, large = ((unit * (n // len(unit) + 1))[:n] for n in SIZES)
            (c_small, _), (c_large, w_large) = cost(name, small, args.repeats), cost(name, large, args.repeats)
            ratio = c_large / c_small if c_small > 0 else float("nan")
            print(f"{name:18} {label:20} {c_small * 1e3:12.1f} {c_large * 1e3:13.1f} {w_large * 1e3:14.1f} {ratio:6.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
