"""Benchmark: how fast the emulated device answers while it streams, and what answering costs the stream.

Runs `imu-emulator stream` (VectorNav binary, 1 kHz by default) on a pty and plays a driver from this
process: in runs "quiet" it only reads; in runs "commands" it also sends `$VNRRG,xx` every 10 ms and times
each reply from the write to the read that delivers its last byte (registers 01, 03, 04 in turn: a reply to
another register than the oldest unanswered one is counted as mismatched — the wrong value a driver would
take — and a reply nobody asked for as surplus; every reply is pooled over the runs for p50/p99/max). Runs
alternate (quiet, commands, quiet, ...) so that machine load hits both alike. Prints per run: reply latency p50/p99/max, the stream's lateness
p50/p99 (from the emulator's --stats-json), the emulator's CPU time per second of wall time (from
/proc/<pid>/stat), and finally the cost of one sample's device output in-process (thread CPU time).

The reader runs in Python on the same machine (under SCHED_FIFO below the emulator's priority unless
--reader-normal): its own wake-up delay is part of the measured latency, so the figures are upper bounds of
what a driver in C would see. A third kind of run, "off", streams with
--device off (encoded ahead in the producer process) as the baseline the sender-side encoding is compared to.

With --baseline PATH (another checkout of the project, e.g. /work/main) a fourth kind, "commands@base",
runs that checkout's emulator the same way, interleaved with the others, so a change to the reply path is
measured against its predecessor under the same load. The load average is printed at the start and end.

    .venv/bin/python tools/bench_device.py [--rate 1000] [--seconds 5] [--pairs 3] [--baseline /work/main]
"""
from __future__ import annotations

import argparse
import json
import os
import re
import select
import subprocess
import sys
import tempfile
import time
from functools import reduce
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_stream import SCENE  # noqa: E402  (a 1 s circle, streamed with --loop)


# off: --device off, encoded ahead by the producer (the baseline); quiet: the device encodes each sample in
# the sender, no commands; commands: the same with $VNRRG,01 every 10 ms; floor: not the emulator but the
# smallest program that does the same on a pty (ECHO below), so its reply latency is what the kernel's pty
# and the scheduler cost under the machine's load at that moment.
KINDS = ("off", "quiet", "commands", "floor")
# A 1 kHz writer of 42-byte packets on a pty master that answers each `$VNRRG,01...` line at once, under the
# emulator's scheduling (SCHED_FIFO 1, 1 ns timer slack): select() until the next deadline or input.
ECHO = r"""
import ctypes, os, select, sys, time, tty
master, slave = os.openpty(); tty.setraw(slave); print("floor -> " + os.ttyname(slave), flush=True)
ctypes.CDLL(None).prctl(29, 1, 0, 0, 0)
os.set_blocking(master, False)
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
period, end = 1_000_000, time.monotonic_ns() + int(float(sys.argv[1]) * 1e9)
packet, deadline, buf = b"\xfa" + bytes(41), time.monotonic_ns(), b""
while time.monotonic_ns() < end:
    wait = deadline - time.monotonic_ns()
    if wait <= 0:
        try:
            os.write(master, packet)
        except BlockingIOError:
            pass
        deadline += period
        continue
    if select.select([master], [], [], wait / 1e9)[0]:
        try:
            buf += os.read(master, 4096)
        except OSError:
            continue
        while b"\n" in buf:
            line, buf = buf.split(b"\n", 1)
            try:
                os.write(master, b"$VNRRG," + line[7:9] + b",X*00\r\n")   # the register asked for
            except BlockingIOError:
                pass
"""
_READER_FIFO = True
# The registers asked for in turn (model, serial number, firmware): a reply to another register than the one asked
# is counted as mismatched, a reply to nothing asked as surplus.
REGISTERS = (b"01", b"03", b"04")


def command(body: bytes) -> bytes:
    return b"$" + body + b"*%02X\r\n" % reduce(lambda a, b: a ^ b, body, 0)


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def one_run(scene: Path, rate: float, seconds: float, kind: str, repo: Path = REPO) -> dict:
    with_commands = kind.startswith("commands")
    stats = Path(tempfile.mkstemp(suffix=".json")[1])
    if kind == "floor":
        with_commands = True
        proc = subprocess.Popen([sys.executable, "-c", ECHO, str(seconds + 3)], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
    else:
        proc = subprocess.Popen([sys.executable, "-m", "imu_emulator", "stream", str(scene), "--format",
                                 "vectornav-binary", "--to", "pty", "--quiet", "--loop", "--duration",
                                 str(seconds + 3), "--stats-json", str(stats),
                                 "--device", "off" if kind == "off" else "on"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, cwd=repo)      # `-m` imports the package of the working directory
    path = re.search(r"-> (\S+)", proc.stdout.readline()).group(1)
    if _READER_FIFO:     # after the fork: the emulator sets its own scheduling
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    marker = re.compile(rb"\$VNRRG,(\d\d),[^*]*\*[0-9A-F]{2}\r\n")
    pending, latencies = [], []         # (register, time written) of the commands not answered yet, oldest first
    mismatched = surplus = 0
    asked = 0
    buf = bytearray()
    # Wait for the stream to run before timing anything.
    while not select.select([fd], [], [], 10)[0]:
        pass
    cpu0, wall0 = cpu_seconds(proc.pid), time.monotonic()
    end = wall0 + seconds
    next_command = wall0
    while time.monotonic() < end:
        now = time.monotonic()
        if with_commands and now >= next_command:
            register = REGISTERS[asked % len(REGISTERS)]
            asked += 1
            os.write(fd, command(b"VNRRG," + register))
            pending.append((register, time.monotonic_ns()))
            next_command += 0.010
        timeout = max(0.0, min(next_command if with_commands else end, end) - time.monotonic())
        if select.select([fd], [], [], timeout)[0]:
            try:
                buf += os.read(fd, 65536)
            except BlockingIOError:
                continue
            arrived = time.monotonic_ns()
            for match in list(marker.finditer(buf)):
                if not pending:
                    surplus += 1          # an answer nobody asked for: a command answered twice
                    continue
                register, written = pending.pop(0)
                # A driver takes the next reply as the answer to its oldest question: another register's reply
                # is the wrong value VectorNav's library would return (the serial number read as "2").
                mismatched += match.group(1) != register
                latencies.append((arrived - written) / 1000)
            last = None
            for match in marker.finditer(buf):
                last = match
            if last is not None:
                del buf[:last.end()]
            elif len(buf) > 1 << 16:
                del buf[:-256]
    cpu = (cpu_seconds(proc.pid) - cpu0) / (time.monotonic() - wall0)
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    os.close(fd)
    proc.send_signal(2)
    proc.communicate(timeout=30)
    late = json.loads(stats.read_text())["lateness"] if kind != "floor" else {"p50_us": 0.0, "p99_us": 0.0,
                                                                             "missed": 0}
    stats.unlink()
    out = {"kind": kind, "late_p50_us": late["p50_us"],
           "late_p99_us": late["p99_us"], "missed": late["missed"], "cpu_per_s": cpu,
           "asked": asked, "unanswered": len(pending), "mismatched": mismatched, "surplus": surplus}
    out["replies"] = len(latencies)
    out.update(_quantiles(latencies))
    out["latencies_us"] = latencies
    return out


# Fewer replies than this give no p99 (the 99th percentile of fewer than 100 values is the maximum or a guess).
_MIN_FOR_P99 = 100


def _quantiles(latencies: list) -> dict:
    """p50/p99/max of reply latencies in us; a quantile the count cannot support is left out, never None."""
    if not latencies:
        return {}
    lat = np.array(latencies)
    out = {"reply_p50_us": float(np.percentile(lat, 50)), "reply_max_us": float(lat.max())}
    if len(lat) >= _MIN_FOR_P99:
        out["reply_p99_us"] = float(np.percentile(lat, 99))
    return out


def _latency_text(runs: list) -> str:
    """Reply latency over every reply of these runs pooled, and what went wrong with the replies."""
    pooled = [x for r in runs for x in r.get("latencies_us", [])]
    q = _quantiles(pooled)
    asked = sum(r["asked"] for r in runs)
    if not q:
        text = f"no reply to {asked} commands"
    else:
        p99 = f"{q['reply_p99_us']:.0f} us" if "reply_p99_us" in q else f"n/a (only {len(pooled)} replies)"
        text = (f"reply latency over {len(pooled)} replies: p50 {q['reply_p50_us']:.0f} us, p99 {p99}, "
                f"max {q['reply_max_us']:.0f} us")
    return (text + f"; of {asked} commands {sum(r['unanswered'] for r in runs)} unanswered, "
            f"{sum(r['mismatched'] for r in runs)} answered with another register's reply, "
            f"{sum(r['surplus'] for r in runs)} surplus replies")


def output_cost(rate: float, repeats: int = 20000) -> dict:
    """Thread CPU time of one device.output (the encode a device stream does per sample in the sender)."""
    import firmware_protocols
    from firmware_protocols import Samples
    n = 100
    samples = Samples(np.arange(n) * 1_000_000, np.random.default_rng(1).normal(size=(n, 3)),
                      np.random.default_rng(2).normal(size=(n, 3)), quat=np.tile([1.0, 0, 0, 0], (n, 1)),
                      euler=np.zeros((n, 3)))
    out = {}
    for name in ("vectornav-binary", "mavlink-highres", "xsens-mtdata2"):
        device = firmware_protocols.create_device(name, rate)
        device.output(samples, 0)
        t0 = time.thread_time_ns()
        for k in range(repeats):
            device.output(samples, k % n)
        out[name] = (time.thread_time_ns() - t0) / repeats / 1000
    return out


def _cpu_model() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return "unknown CPU"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--pairs", type=int, default=3)
    parser.add_argument("--reader-normal", action="store_true",
                        help="read at normal priority (default: SCHED_FIFO 10, below the emulator's 20, so the "
                             "reader's own wake-up delay under load weighs less in the reply latency)")
    parser.add_argument("--baseline", type=Path, help="another checkout whose emulator answers commands too "
                                                          "(kind commands@base), interleaved with these runs")
    args = parser.parse_args()
    global _READER_FIFO
    _READER_FIFO = not args.reader_normal
    kinds = KINDS + (("commands@base",) if args.baseline else ())
    print(f"load average at start: {' '.join(Path('/proc/loadavg').read_text().split()[:3])}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "scene.toml"
        scene.write_text(SCENE.format(rate=args.rate))
        runs = []
        for _ in range(args.pairs):
            for kind in kinds:
                run = one_run(scene, args.rate, args.seconds, kind,
                              args.baseline if kind == "commands@base" else REPO)
                runs.append(run)
                print(json.dumps({k: round(v, 1) if isinstance(v, float) else v for k, v in run.items()
                                  if k != "latencies_us"}), flush=True)
    def listed(sel, key):
        return ", ".join(f"{r[key]:.0f}" for r in sel)

    print(f"load average at end: {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    print(f"CPU: {_cpu_model()}, {os.cpu_count()} cores")
    for kind in kinds:
        sel = [r for r in runs if r["kind"] == kind]
        if kind == "floor":
            print(f"{kind:9}: bare pty echo at 1 kHz, {_latency_text(sel)}")
            continue
        line = (f"{kind:9}: stream lateness p99 median of runs {np.median([r['late_p99_us'] for r in sel]):.0f} us "
                f"(runs: {listed(sel, 'late_p99_us')}), emulator CPU {np.median([r['cpu_per_s'] for r in sel]) * 100:.0f} %")
        if kind.startswith("commands"):
            line += "; " + _latency_text(sel)
        print(line)
    costs = output_cost(args.rate)
    print("one sample's device output, thread CPU: " + ", ".join(f"{k} {v:.1f} us" for k, v in costs.items()))


if __name__ == "__main__":
    main()
