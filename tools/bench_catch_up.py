"""What catching up at 10 kHz costs, and what the host takes (not a test; prints figures, asserts nothing):

- host gaps: a bare loop reading the monotonic clock and the thread's CPU clock for --seconds; every wall gap over
  100 us, split by the CPU clock into stolen (it stood still: steal time, which the "stalled" miss cause relies
  on) and counted (it ran on: interrupts and host time charged to the thread, which the attribution then blames
  on the emulator); per second and their sizes;
- a pty write: thread CPU per 62-byte packet to a pty whose reader (`cat`) waits, one packet every 100 us;
- a device asked for a range: the MAVLink device's output_many over ranges of 4-50 samples against output sample
  by sample on an identical device, both encoding one sample per call (ahead = 1), thread CPU per call, min of
  --repeat;
- a device encoding ahead: the MAVLink device's `output`, one sample every 100 us as the send loop asks, with its
  default `ahead` (a range encoded at once, handed out one by one) against ahead = 1, interleaved sample by sample;
  thread CPU per sample: mean (the ranges' cost included), median and p99;
- a device's block taken from the ring: the sender's copy of one block of 200 raw samples
  (imu_emulator.live.ring._samples), with every field present and with bench_stream's scene's, one block per ms
  with the thread asleep between (its caches go cold as in the send loop), thread CPU per block, median and p90;
  with --baseline, the same from another checkout's ring module, interleaved block by block;
- with --all-devices, every format's device at 10 kHz: `output` one sample every 100 us as the send loop asks (the
  samples carry accel, gyro, quat and euler only), thread CPU per sample: mean, median and p99, against the period.

    .venv/bin/python tools/bench_catch_up.py [--seconds 5] [--repeat 20] [--baseline DIR] [--all-devices]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import firmware_protocols  # noqa: E402
from firmware_protocols import Samples  # noqa: E402
from imu_emulator.live.transport.base import TargetOptions  # noqa: E402
from imu_emulator.live.transport.pty import PtyTransport  # noqa: E402


def host_gaps(seconds: float) -> None:
    gaps = []
    end = time.monotonic_ns() + int(seconds * 1e9)
    wall, cpu = time.monotonic_ns(), time.thread_time_ns()
    while wall < end:
        w, c = time.monotonic_ns(), time.thread_time_ns()
        if w - wall > 100_000:
            gaps.append((w - wall, c - cpu))
        wall, cpu = w, c
    gaps = np.array(gaps, dtype=float).reshape(-1, 2) / 1e3
    counted = gaps[:, 1] > 0.5 * gaps[:, 0]
    print(f"host gaps over 100 us in a bare loop: {len(gaps) / seconds:.0f} per s")
    for name, rows in (("stolen (CPU clock stood still)", gaps[~counted]), ("counted as the thread's CPU", gaps[counted])):
        if len(rows):
            print(f"  {name}: {len(rows) / seconds:.1f} per s, wall {rows[:, 0].min():.0f}-{rows[:, 0].max():.0f} us, "
                  f"median {np.median(rows[:, 0]):.0f} us; CPU in them median {np.median(rows[:, 1]):.0f} us")
        else:
            print(f"  {name}: none")


def pty_write(count: int = 5000) -> None:
    transport = PtyTransport(TargetOptions())
    reader = subprocess.Popen(["cat", transport.pty.path], stdout=subprocess.DEVNULL)
    try:
        time.sleep(0.3)
        packet, cpu = b"x" * 62, []
        for _ in range(count):
            c0 = time.thread_time_ns()
            os.write(transport.pty.master, packet)
            cpu.append(time.thread_time_ns() - c0)
            until = time.monotonic_ns() + 100_000
            while time.monotonic_ns() < until:
                pass
        print(f"pty write, 62 bytes, reader waiting, one every 100 us: CPU median {np.median(cpu) / 1e3:.1f} us, "
              f"p90 {np.percentile(cpu, 90) / 1e3:.1f} us")
    finally:
        reader.kill()
        reader.wait()
        transport.close()


def _samples(n: int) -> Samples:
    k = np.arange(n)[:, None]
    angles = 0.01 * k + np.array([0.0, 1.0, 2.0])
    quat = np.hstack([np.cos(0.005 * k), np.sin(0.005 * k), np.zeros((n, 2))])
    return Samples((np.arange(n) * 1e7).astype(np.int64), 9.8 * np.sin(angles), 0.1 * np.cos(angles),
                   quat=quat, euler=np.zeros((n, 3)))


def device_ranges(repeat: int) -> None:
    rate, sizes = 100.0, (4, 10, 20, 50)
    samples = _samples(int(rate) * (len(sizes) * repeat + 2))
    many = firmware_protocols.create_device("mavlink-highres", rate)
    one = firmware_protocols.create_device("mavlink-highres", rate)
    many.ahead = one.ahead = 1
    many.output(samples, 0)
    one.output(samples, 0)
    best = {n: [np.inf, np.inf] for n in sizes}
    m = 1
    for _ in range(repeat):
        for n in sizes:       # each range inside one second of samples: no heartbeat falls in it
            c0 = time.thread_time_ns()
            many.output_many(samples, m, m + n)
            c1 = time.thread_time_ns()
            for q in range(m, m + n):
                one.output(samples, q)
            c2 = time.thread_time_ns()
            best[n] = [min(best[n][0], c1 - c0), min(best[n][1], c2 - c1)]
            for device in (many, one):     # on to the next second: past the heartbeat, sample by sample
                for q in range(m + n, m + int(rate)):
                    device.output(samples, q)
            m += int(rate)
    print("MAVLink device, a range at once against sample by sample (thread CPU, min of "
          f"{repeat}): " + "; ".join(f"{n} samples {a / 1e3:.0f} us vs {b / 1e3:.0f} us" for n, (a, b) in best.items()))


def device_ahead(count: int = 20000) -> None:
    rate = 10000.0
    samples = _samples(count + 1)
    devices = {"ahead": firmware_protocols.create_device("mavlink-highres", rate),
               "one by one": firmware_protocols.create_device("mavlink-highres", rate)}
    devices["one by one"].ahead = 1
    warm = firmware_protocols.create_device("mavlink-highres", rate)     # the encoder's first call loads its kernel
    for q in range(40):
        warm.output(samples, q)
    cpu = {name: [] for name in devices}
    for q in range(count):
        for name, device in devices.items():
            until = time.monotonic_ns() + 50_000
            while time.monotonic_ns() < until:
                pass
            c0 = time.thread_time_ns()
            device.output(samples, q)
            cpu[name].append(time.thread_time_ns() - c0)
    print(f"MAVLink device, output every 100 us, {count} samples (thread CPU per sample, mean / median / p99): " + "; ".join(
        f"{name} ({devices[name].ahead} at once) {np.mean(c) / 1e3:.1f} / {np.median(c) / 1e3:.1f} / "
        f"{np.percentile(c, 99) / 1e3:.1f} us" for name, c in cpu.items()))


def ring_take(baseline: str | None, blocks: int = 600) -> None:
    from imu_emulator.live import ring
    takes = {"this tree": ring._samples}
    if baseline:
        path = Path(baseline) / "imu_emulator" / "live" / "ring.py"
        other: dict = {"__name__": "baseline_ring"}
        exec(compile(path.read_text(), str(path), "exec"), other)    # the checkout's module, on this tree's imports
        takes[baseline] = other["_samples"]
    n, fields = 200, [name for name, _ in ring._SAMPLE_FIELDS]
    scene_fields = ("accel", "gyro", "quat", "euler")
    for label, names in (("every field", fields), ("the fields of bench_stream's scene", scene_fields)):
        mask = sum(1 << fields.index(name) for name in names)
        words = n + sum(n * (width or 1) for bit, (_, width) in enumerate(ring._SAMPLE_FIELDS) if mask >> bit & 1)
        data = memoryview(np.random.default_rng(1).normal(size=words)).cast("B")
        cpu = {name: [] for name in takes}
        for _ in range(blocks):
            for name, take in takes.items():
                time.sleep(0.001)
                c0 = time.thread_time_ns()
                take(data, 0, n, mask, 0)
                cpu[name].append(time.thread_time_ns() - c0)
        print(f"a device's block from the ring, {n} samples, {label} ({len(names)}, {words * 8 // 1024} KiB), one per "
              f"ms (thread CPU per block, median / p90): " + "; ".join(
                  f"{name} {np.median(c) / 1e3:.1f} / {np.percentile(c, 90) / 1e3:.1f} us" for name, c in cpu.items()))


def all_devices(count: int = 3000) -> None:
    from firmware_protocols import registry
    samples = _samples(count + 41)
    print(f"every format's device, output every 100 us, {count} samples (thread CPU per sample, mean / median / p99):")
    for name in registry.formats():
        if registry.get(name).device is None:
            continue
        device = registry.create_device(name, 10000.0)
        for q in range(40):       # the encoder's first calls load its machine code
            device.output(samples, q)
        cpu = []
        for q in range(40, 40 + count):
            until = time.monotonic_ns() + 50_000
            while time.monotonic_ns() < until:
                pass
            c0 = time.thread_time_ns()
            device.output(samples, q)
            cpu.append(time.thread_time_ns() - c0)
        mean = np.mean(cpu) / 1e3
        print(f"  {name:28s} {mean:6.1f} / {np.median(cpu) / 1e3:6.1f} / {np.percentile(cpu, 99) / 1e3:6.1f} us"
              + ("  (more than the 100 us period)" if mean > 100 else ""), flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=5.0, help="duration of the host-gap loop")
    parser.add_argument("--repeat", type=int, default=20, help="rounds of the device ranges")
    parser.add_argument("--all-devices", action="store_true", help="also every format's device at 10 kHz")
    parser.add_argument("--baseline", help="another checkout whose ring module's block copy is measured beside")
    args = parser.parse_args()
    model = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                  if line.startswith("model name")), "unknown CPU")
    load = lambda: " ".join(Path("/proc/loadavg").read_text().split()[:3])  # noqa: E731
    print(f"{model}, {os.cpu_count()} CPUs; load average at start {load()}")
    host_gaps(args.seconds)
    pty_write()
    device_ranges(args.repeat)
    device_ahead()
    ring_take(args.baseline)
    if args.all_devices:
        all_devices()
    print(f"load average at end {load()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
