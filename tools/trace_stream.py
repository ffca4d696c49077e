"""Which sends the misses follow (not a test; prints figures, asserts nothing): one stream of tools/bench_stream.py's
scene (HIGHRES_IMU to a pty read by this process), with the emulator's miss classification and its pty sends
traced from inside the emulator's process:

- every missed deadline: its cause (realtime.MISS_CAUSES), lateness and the sender's own CPU time it was judged by;
- every send to the pty that took more than --slow-us of wall time: its wall and CPU time and whether the thread
  switched (voluntary: it blocked in the kernel; involuntary: preempted);
- the misses that are not `stalled`, split by what came within 1.5 ms before them: a slow send, else a `stalled`
  miss (the sender still catching up from the host's stall), else neither.

    .venv/bin/python tools/trace_stream.py [--seconds 20] [--rate 10000] [--device off] [--slow-us 60]

The wrapping costs the sender a few microseconds a send, so its misses are not the untraced stream's figures.
"""
from __future__ import annotations

import argparse
import atexit
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))


def _inside(out: str, slow_ns: int, argv: list) -> int:
    """The emulator's CLI with the classification and the pty sends recorded; written to `out` at exit."""
    from imu_emulator.live import realtime
    from imu_emulator.live.transport.pty import PtyTransport

    misses, sends, state = [], [], {"late": 0, "own": 0}
    causes = list(realtime.MISS_CAUSES)
    add, classify, own_cpu = realtime.LatenessStats.add, realtime.LatenessStats.classify, realtime.Pacer.own_cpu_ns

    def traced_add(self, late):
        state["late"] = late
        add(self, late)

    def traced_classify(self, cause):
        misses.append((state["late"], causes.index(cause), state["own"], time.monotonic_ns()))
        classify(self, cause)

    def traced_own(self):
        state["own"] = own_cpu(self)
        return state["own"]

    def traced(send):
        def wrapper(*args):
            before, start, cpu = resource.getrusage(resource.RUSAGE_THREAD), time.monotonic_ns(), time.thread_time_ns()
            result = send(*args)
            wall = time.monotonic_ns() - start
            if wall > slow_ns:
                after = resource.getrusage(resource.RUSAGE_THREAD)
                sends.append((start, wall, time.thread_time_ns() - cpu, after.ru_nvcsw - before.ru_nvcsw,
                              after.ru_nivcsw - before.ru_nivcsw))
            return result
        return wrapper

    realtime.LatenessStats.add, realtime.LatenessStats.classify = traced_add, traced_classify
    realtime.Pacer.own_cpu_ns = traced_own
    PtyTransport.send, PtyTransport.send_many = traced(PtyTransport.send), traced(PtyTransport.send_many)
    atexit.register(lambda: np.savez(out, misses=np.array(misses, dtype=np.int64).reshape(-1, 4),
                                     sends=np.array(sends, dtype=np.int64).reshape(-1, 5), causes=np.array(causes)))
    from imu_emulator.cli import main
    return main(argv)


def _follow(misses: np.ndarray, sends: np.ndarray, stalled: int, window_ns: int = 1_500_000) -> tuple:
    """The misses not stalled, by what came within `window_ns` before each: a slow send first, else a stalled
    miss (the host's stall the sender is still catching up from), else neither. Returns ([(what, count)], the
    miss rows after neither)."""
    stalls = misses[misses[:, 1] == stalled, 3]
    found, neither = Counter(), []
    for row in misses[misses[:, 1] != stalled]:
        t = row[3]
        if ((sends[:, 0] < t) & (sends[:, 0] > t - window_ns)).any():
            found["within 1.5 ms after a slow send"] += 1
        elif ((stalls < t) & (stalls > t - window_ns)).any():
            found["after a stalled miss (no slow send)"] += 1
        else:
            found["after neither"] += 1
            neither.append(row)
    return [(what, found[what]) for what in ("within 1.5 ms after a slow send", "after a stalled miss (no slow send)",
                                             "after neither")], neither


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "--inside":
        return _inside(sys.argv[2], int(sys.argv[3]), sys.argv[4:])
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--rate", type=float, default=10000.0)
    parser.add_argument("--device", choices=("on", "off"), default="on")
    parser.add_argument("--slow-us", type=float, default=60.0, help="sends longer than this (wall) are recorded")
    args = parser.parse_args()
    import bench_stream

    print(f"{bench_stream._cpu_model()}, {os.cpu_count()} CPUs; load average at start {bench_stream._load()}")
    with tempfile.TemporaryDirectory() as tmp:
        scene, out = Path(tmp) / "scene.toml", Path(tmp) / "trace.npz"
        scene.write_text(bench_stream.SCENE.format(rate=args.rate))
        proc = subprocess.Popen([sys.executable, __file__, "--inside", str(out), str(int(args.slow_us * 1e3)),
                                 "stream", str(scene), "--format", "mavlink-highres", "--to", "pty", "--loop",
                                 "--duration", str(args.seconds), "--quiet", "--device", args.device],
                                stdout=subprocess.PIPE, cwd=REPO, text=True)
        line = proc.stdout.readline()
        path = next(word for word in line.split("-> ")[1].split() if word.startswith("/"))
        bench_stream.read_until_exit(proc, os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK))
        trace = np.load(out)
        misses, sends, causes = trace["misses"], trace["sends"], list(trace["causes"])
    count = int(args.rate * args.seconds)
    by_cause = Counter(causes[c] for c in misses[:, 1])
    print(f"{args.rate:.0f} Hz, {args.seconds:g} s, --device {args.device}: missed {len(misses) / count:.3%} of "
          f"{count} deadlines: " + ", ".join(f"{n} {cause}" for cause, n in by_cause.most_common()))
    print(f"sends over {args.slow_us:g} us of wall time: {len(sends)}"
          + (f"; wall median {np.median(sends[:, 1]) / 1e3:.0f} us (max {sends[:, 1].max() / 1e3:.0f}), CPU median "
             f"{np.median(sends[:, 2]) / 1e3:.0f} us; {int((sends[:, 3] > 0).sum())} blocked in the kernel, "
             f"{int((sends[:, 4] > 0).sum())} preempted" if len(sends) else ""))
    stalled = causes.index("stalled")
    own = misses[misses[:, 1] != stalled]
    split, neither = _follow(misses, sends, stalled)
    print(f"misses not stalled: {len(own)}; " + ", ".join(f"{n} {what}" for what, n in split))
    if neither:
        print("  after neither (cause, lateness us, sender CPU us since last on time): " + "; ".join(
            f"{causes[c]} {late / 1e3:.0f} {cpu / 1e3:.0f}" for late, c, cpu, _ in neither[:20]))
    print(f"load average at end {bench_stream._load()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
