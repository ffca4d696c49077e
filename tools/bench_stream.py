"""Figures for live streaming (not a test): HIGHRES_IMU to a pty read by this process.

- lateness against deadlines (the emulator's own statistics) at each rate: p50, p99, p99.9, max and
  the share of deadlines missed by more than one period;
- drift between sample time and the reader's wall clock over a long run at 1 kHz;
- time from launching the command to the first packet received (warm cache);
- the machine's floor at each rate: the same pacer with nothing to send, no producer and no reader. On
  shared virtual machines the host takes the vCPU away now and then (seen here: every 100 ms, for
  0.2-5 ms, even from a loop that never sleeps); no pacing inside the guest can beat that floor.

With --baseline PATH (another checkout, e.g. /work/main) the lateness runs become a comparison: for each rate,
--pairs rounds of (floor, PATH's emulator, this tree's emulator; with --loaded-floor also the floor with another
CPU kept as busy as a stream keeps it besides its sender; with --pty-floor also the floor writing a packet a
deadline to a pty this process reads), the order rotated each round, so the machine's load hits all alike; per
run it prints misses %, lateness p50/p99, the sender thread's (a floor's pacing thread's) CPU per second of
streaming, and this tree's misses by cause; then the medians and the misses above the floor, this tree against
PATH, in percentage points and as a ratio. The CPU model and the load average (start, end) are printed.
The host's stalls differ from one run to the next by more than the emulator's own misses, so each run's misses
are also told apart by the sender thread's CPU clock (realtime.MISS_CAUSES "stalled"; the floor by the same rule):
the misses not stalled, this tree's against the floor's, compare the two on the stalls each met.

    python tools/bench_stream.py [--seconds 30] [--rates 1000 10000] [--drift-seconds 600]
    python tools/bench_stream.py --baseline /work/main --rates 10000 --seconds 20 --pairs 3 --drift-seconds 0
    python tools/bench_stream.py --baseline . --device off --baseline-device on --rates 10000 --drift-seconds 0
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from imu_emulator.live.realtime import LatenessStats

REPO = Path(__file__).resolve().parents[1]
SCENE = """
[scene]
rate_hz = {rate}
duration_s = 1.0
[trajectory]
shape = "circle"
radius_m = 5.0
frequency_hz = 1.0
height_m = 0.0
[attitude]
mode = "tangent"
[[imu]]
name = "imu0"
[effects]
gravity = true
"""


def launch(directory: Path, rate: float, seconds: float, stats: Path, fmt: str = "mavlink-highres",
           target: str = "pty", extra: tuple = (), repo: Path = REPO):
    """Start a stream to a pty (or a virtual SLCAN adapter's pty: target can:slcan:pty) and open the pty."""
    scene = directory / f"bench_{int(rate)}.toml"
    scene.write_text(SCENE.format(rate=rate))
    started = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "imu_emulator", "stream", str(scene), "--format",
                             fmt, "--to", target, "--loop", "--duration", str(seconds), "--quiet",
                             "--stats-json", str(stats), *extra], stdout=subprocess.PIPE, cwd=repo, text=True)
    # cwd: `-m` imports the package of the working directory (a --baseline checkout runs its own code)
    line = proc.stdout.readline()
    path = next(word for word in line.split("-> ")[1].split() if word.startswith("/"))
    fd = os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    return proc, fd, started


def read_until_exit(proc, fd, on_data=None):
    """Read everything until the emulator exits; returns the monotonic time of the first byte."""
    first = None
    while True:
        ready, _, _ = select.select([fd], [], [], 0.2)
        if ready:
            try:
                data = os.read(fd, 1 << 16)
            except OSError:
                break
            if not data:   # end of file: the emulator closed its side
                break
            if first is None:
                first = time.monotonic()
            if on_data:
                on_data(time.monotonic(), data)
        elif proc.poll() is not None:
            break
    os.close(fd)
    proc.wait()
    return first


# Extra options of every lateness run (--device off), and of the --baseline checkout's runs (--baseline-device).
STREAM_OPTIONS: list = []
BASELINE_OPTIONS: list = []


def lateness(directory: Path, rate: float, seconds: float, repo: Path = REPO, options: list = STREAM_OPTIONS) -> dict:
    """The emulator's statistics; with "other_cpu_ratio" added: the CPU a second of streaming took besides the
    sender thread's (the producer, the emulator's other threads and start-up, this reader), which --loaded-floor
    gives the floor."""
    stats = directory / "stats.json"
    children, own = resource.getrusage(resource.RUSAGE_CHILDREN), time.process_time()
    proc, fd, _ = launch(directory, rate, seconds, stats, extra=tuple(options), repo=repo)
    read_until_exit(proc, fd)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    summary = json.loads(stats.read_text())
    total = (after.ru_utime + after.ru_stime - children.ru_utime - children.ru_stime) + (time.process_time() - own)
    if "sender_cpu_ratio" in summary:
        summary["other_cpu_ratio"] = max(0.0, total / seconds - summary["sender_cpu_ratio"])
    return summary


def drift(directory: Path, seconds: float) -> tuple[float, float]:
    """(drift over the run, spread) in ms: reader's clock minus packet time, last second vs first second."""
    from pymavlink.dialects.v20 import common as mavlink2
    mav = mavlink2.MAVLink(None)
    points = []

    def on_data(now, data):
        for message in mav.parse_buffer(data) or []:
            if message.get_type() == "HIGHRES_IMU":
                points.append((now, message.time_usec * 1e-6))

    proc, fd, _ = launch(directory, 1000, seconds, directory / "drift.json")
    read_until_exit(proc, fd, on_data)
    arrival, sample = np.array(points).T
    offset = (arrival - arrival[0]) - (sample - sample[0])
    head, tail = offset[sample - sample[0] < 1.0], offset[sample - sample[-1] > -1.0]
    return (np.median(tail) - np.median(head)) * 1e3, (np.percentile(tail, 99) - np.median(tail)) * 1e3


BASELINE = """
import gc, json, os, sys, time, tty
from imu_emulator.live.realtime import LatenessStats, Pacer, enable_realtime
rate, seconds, pty = float(sys.argv[1]), float(sys.argv[2]), len(sys.argv) > 3
rt = enable_realtime()
if pty:     # a HIGHRES_IMU-sized packet to a pty each deadline, for a reader in another process (--pty-floor)
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    packet, refused = bytes(int(sys.argv[3])), 0
    print("-> " + os.ttyname(slave), flush=True)
gc.freeze(); gc.disable()
period = 1e9 / rate
pacer, stats = Pacer(rt.fifo, period, spin=rt.spin), LatenessStats(period)
start = time.monotonic_ns() + (500_000_000 if pty else 10_000_000)     # the reader opens the pty meanwhile
cpu = time.thread_time_ns()
for k in range(int(rate * seconds)):
    deadline = start + int(k * period)
    late = pacer.wait_until(deadline) - deadline
    if pty:
        try:
            os.write(master, packet)
        except BlockingIOError:     # the pty full: counted, printed with the run
            refused += 1
    stats.add(late)
    if late > period:     # the emulator's rule for "stalled"; the rest is host time its CPU clock counts
        stats.classify("stalled" if late - pacer.own_cpu_ns() > period else "woke_late")
summary = stats.summary()
# the pacing thread's CPU per second, as the emulator's sender_cpu_ratio counts its send loop's
summary["sender_cpu_ratio"] = (time.thread_time_ns() - cpu) / (time.monotonic_ns() - start)
if pty:
    summary["refused_writes"] = refused
print(json.dumps(summary))
"""


# --loaded-floor: the other vCPU kept as busy as a stream keeps it (producer, reader), in slices of a millisecond,
# which a stream's many short wake-ups resemble more than one long busy stretch would.
LOAD = """
import sys, time
duty, seconds = float(sys.argv[1]), float(sys.argv[2])
end = time.monotonic() + seconds
while time.monotonic() < end:
    busy = time.monotonic() + duty * 1e-3
    while time.monotonic() < busy:
        pass
    time.sleep((1 - duty) * 1e-3)
"""


def baseline(rate: float, seconds: float, load: float = 0.0) -> dict:
    """The machine's floor: the same pacer with nothing to send, no producer, no reader; with `load` (CPU s/s,
    below 1) a process keeps another CPU that busy meanwhile."""
    helper = None
    if load > 0:
        helper = subprocess.Popen([sys.executable, "-c", LOAD, str(min(load, 0.95)), str(seconds + 1.0)])
        time.sleep(0.2)
    try:
        out = subprocess.run([sys.executable, "-c", BASELINE, str(rate), str(seconds)], capture_output=True,
                             text=True, check=True, cwd=REPO)
    finally:
        if helper is not None:
            helper.kill()
            helper.wait()
    return json.loads(out.stdout)


def pty_floor(rate: float, seconds: float, size: int = 62) -> dict:
    """The same pacer writing a `size`-byte packet to a pty at each deadline (after it, as the emulator's send loop
    does), read by this process as bench runs read the emulator's: what talking to a reader costs on this machine
    (each write wakes the reader's CPU), with no encoding, no producer, no block."""
    proc = subprocess.Popen([sys.executable, "-c", BASELINE, str(rate), str(seconds), str(size)],
                            stdout=subprocess.PIPE, text=True, cwd=REPO)
    path = proc.stdout.readline().split("-> ")[1].strip()
    read_until_exit(proc, os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK))
    return json.loads(proc.stdout.read())     # its statistics, a line that waited in the pipe


def first_packet(directory: Path) -> float:
    proc, fd, started = launch(directory, 1000, 1.0, directory / "first.json")
    first = read_until_exit(proc, fd)
    return first - started


def _load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def _steal_ms() -> float:
    """The guest's steal time so far, all CPUs, in ms (/proc/stat, in USER_HZ ticks): the host running someone
    else on our vCPUs. A stream keeps both vCPUs of these guests busy (sender, producer, reader), the floor one."""
    for line in Path("/proc/stat").read_text().splitlines():
        if line.startswith("cpu "):
            return int(line.split()[8]) * 1000 / os.sysconf("SC_CLK_TCK")
    return 0.0


def _cpu_model() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return "unknown CPU"


def compare(directory: Path, rate: float, seconds: float, pairs: int, base: Path, loaded_floor: bool = False,
            with_pty_floor: bool = False) -> None:
    """Floor, `base`'s emulator and this tree's, interleaved (order rotated each round); medians and ratio.
    loaded_floor: a kind "load": the floor with another CPU kept as busy as this tree's last run kept the machine
    besides its sender (0.3 s/s until this tree has run). with_pty_floor: a kind "pty", the floor writing a packet
    to a pty read here at each deadline (pty_floor)."""
    kinds = ["floor", "base", "tree"] + (["load"] if loaded_floor else []) + (["pty"] if with_pty_floor else [])
    runs = {k: [] for k in kinds}
    shown = LatenessStats.shown
    other = 0.3
    for round_ in range(pairs):
        for kind in kinds[round_ % len(kinds):] + kinds[:round_ % len(kinds)]:
            stolen = _steal_ms()
            refused = None
            if kind in ("floor", "load", "pty"):
                late = pty_floor(rate, seconds) if kind == "pty" else baseline(rate, seconds,
                                                                               other if kind == "load" else 0.0)
                cpu, refused = late.pop("sender_cpu_ratio", None), late.pop("refused_writes", None)
            else:
                s = (lateness(directory, rate, seconds) if kind == "tree"
                     else lateness(directory, rate, seconds, base, BASELINE_OPTIONS))
                late, cpu = s["lateness"], s.get("sender_cpu_ratio")
                if kind == "tree" and "other_cpu_ratio" in s:
                    other = s["other_cpu_ratio"]
            stolen = (_steal_ms() - stolen) / seconds
            runs[kind].append(late)
            causes = LatenessStats.causes_text(late.get("missed_by_cause", {}))
            own = own_misses(late)
            print(f"  round {round_ + 1} {kind:>5s}: missed {late['missed_ratio']:.4%}, p50 {shown(late['p50_us'])} us, "
                  f"p99 {shown(late['p99_us'])} us" + ("" if cpu is None else f", sender CPU {cpu:.2f} s/s")
                  + (f", another CPU kept busy {min(other, 0.95):.2f} s/s" if kind == "load" else "")
                  + (f", {refused} writes refused (the pty full)" if refused else "")
                  + (f"; misses: {causes}" if causes else "")
                  + ("" if own is None else f"; its own (not stalled): {own:.4f} %")
                  + f" (load {_load()}; host steal {stolen:.1f} ms/s, both CPUs)", flush=True)
    median = {k: float(np.median([r["missed_ratio"] for r in runs[k]])) * 100 for k in kinds}
    above = {k: median[k] - median["floor"] for k in ("base", "tree")}
    print(f"{rate:>7.0f} Hz, {pairs} rounds of {seconds:g} s, median misses: floor {median['floor']:.3f} %, "
          f"{base} {median['base']:.3f} %, this tree {median['tree']:.3f} %; above the floor: "
          f"{base} {above['base']:+.3f} pp, this tree {above['tree']:+.3f} pp"
          + (f" (ratio tree/base {above['tree'] / above['base']:.2f})" if above["base"] > 0 else ""), flush=True)
    for k in kinds:
        print(f"{'':>7s}  {k:>5s}: misses % each round "
              + ", ".join(f"{r['missed_ratio'] * 100:.3f}" for r in runs[k]), flush=True)
    # Misses not "stalled" by the CPU clock: the emulator's own, and host time the clock counts as the thread's
    # (not steal: tools/bench_catch_up.py counts such gaps in a bare loop). The floor, classified by the same
    # rule, has only the latter: the difference is the emulator's.
    own = {k: [own_misses(r) for r in runs[k]] for k in kinds}
    for k in kinds:
        if None not in own[k]:
            print(f"{'':>7s}  {k:>5s}: misses not stalled (a pacer with nothing to do, stopped alike, would not have "
                  f"had them), % of deadlines: median {np.median(own[k]):.4f}, each round "
                  + ", ".join(f"{o:.4f}" for o in own[k]), flush=True)
    for floor in [k for k in ("floor", "load", "pty") if k in kinds]:
        if None not in own["tree"] + own[floor]:
            print(f"{'':>7s}  this tree's misses not stalled, above the {floor}'s: "
                  f"{np.median(own['tree']) - np.median(own[floor]):+.4f} pp (medians)", flush=True)
    for floor, name in (("load", "the loaded floor"), ("pty", "the pty floor")):
        if floor in kinds:
            print(f"{'':>7s}  median misses above {name}: this tree {median['tree'] - median[floor]:+.3f} pp, "
                  f"{base} {median['base'] - median[floor]:+.3f} pp", flush=True)


def own_misses(late: dict) -> float | None:
    """The share of deadlines (%) missed other than "stalled" (a pacer with nothing to do, stopped alike, would have
    missed those too: realtime.MISS_CAUSES). None for a checkout that does not tell them apart. The host's stalls
    vary several-fold from one minute to the next (the floor 0.2-4.4 % per 20 s run here), so the emulator's run
    and the floor's never meet the same ones; this measure takes out the stalls each run met."""
    causes = late.get("missed_by_cause", {})
    if "stalled" not in causes:
        return None
    if not late["missed"]:
        return 0.0
    return late["missed_ratio"] * (late["missed"] - causes["stalled"]) / late["missed"] * 100


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=30.0, help="duration of each lateness run")
    parser.add_argument("--rates", type=float, nargs="*", default=[1000.0, 10000.0], help="rates of the lateness runs (none: skip)")
    parser.add_argument("--drift-seconds", type=float, default=600.0, help="duration of the drift run (0 = skip)")
    parser.add_argument("--baseline", type=Path, help="another checkout to compare with, interleaved (e.g. /work/main)")
    parser.add_argument("--pairs", type=int, default=3, help="rounds of (floor, baseline, this tree) with --baseline")
    parser.add_argument("--loaded-floor", action="store_true",
                        help="with --baseline: also the floor with another CPU kept as busy as a stream keeps it "
                             "besides its sender (producer, reader)")
    parser.add_argument("--pty-floor", action="store_true",
                        help="with --baseline: also the floor writing a 62-byte packet to a pty read by this process "
                             "at each deadline (what talking to a reader costs, without the emulator)")
    parser.add_argument("--device", choices=("on", "off"), default="on",
                        help="the stream's --device: on (default) answers a driver, and the sender encodes (the "
                             "MAVLink device 16 samples at a time, in its slack); off sends packets the producer "
                             "encoded")
    parser.add_argument("--baseline-device", choices=("on", "off"),
                        help="the --baseline checkout's --device, when not --device's (e.g. --baseline . --device off "
                             "--baseline-device on: what encoding in the sender costs, in one interleaved run)")
    args = parser.parse_args()
    STREAM_OPTIONS[:] = ["--device", args.device]
    BASELINE_OPTIONS[:] = ["--device", args.baseline_device or args.device]
    print(f"{_cpu_model()}, {os.cpu_count()} CPUs; load average at start {_load()}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        directory = Path(tmp)
        first_packet(directory)   # warm the numba caches
        print(f"first packet after launch (warm cache): {first_packet(directory) * 1e3:.0f} ms")
        if args.baseline:
            lateness(directory, 1000, 1.0, args.baseline, BASELINE_OPTIONS)     # its numba caches too
        for rate in args.rates if args.baseline else ():
            compare(directory, rate, args.seconds, args.pairs, args.baseline, args.loaded_floor, args.pty_floor)
        for rate in args.rates if not args.baseline else ():
            s = lateness(directory, rate, args.seconds)
            late = s["lateness"]
            shown = LatenessStats.shown      # a quantile beyond the histogram is None: "> 65536000"
            print(f"{rate:>7.0f} Hz, {args.seconds:g} s: lateness p50 {shown(late['p50_us'])} us, p99 "
                  f"{shown(late['p99_us'])} us, p99.9 {shown(late['p999_us'])} us, max {late['max_us']:.0f} us; missed > 1 period "
                  f"{late['missed_ratio']:.4%}; achieved {s['achieved_hz']:.1f} Hz; dropped {s['dropped']}")
            base = baseline(rate, args.seconds)
            print(f"{'':>7s}    machine floor (same pacer, nothing sent): p99 {shown(base['p99_us'])} us, "
                  f"p99.9 {shown(base['p999_us'])} us, max {base['max_us']:.0f} us; missed {base['missed_ratio']:.4%}")
        if args.drift_seconds > 0:
            total, spread = drift(directory, args.drift_seconds)
            print(f"drift over {args.drift_seconds:g} s at 1 kHz (reader clock - sample time, last s vs first s): "
                  f"{total:+.3f} ms (p99 - p50 of arrival offset in the last s: {spread:.3f} ms)")
    print(f"load average at end {_load()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
