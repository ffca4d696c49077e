"""Figures for issue 16 (not a test): does the emulator's scheduling starve the program it feeds?

For the default (`--realtime auto`) and each mode (spin, fifo, off), a receiver at normal priority reads what
the emulator streams and the run reports, per case:
- completeness at the receiver: samples whose packet (MAVLink HIGHRES_IMU, by its time stamp) or whole
  DroneCAN RawIMU transfer (every frame, reassembled by the dronecan library) arrived, out of those due;
- the emulator's own counts (sent, dropped) and what the link reported (refusals by errno, interface counters);
- the emulator's lateness p50/p99/p99.9/max against its deadlines, deadlines missed by more than a period, and
  how often the sender fell so far behind that it gave SCHED_FIFO up;
- the emulator's CPU time per second streamed (user + system, producer included): what the mode costs.

Cases: mavlink-highres at 1 kHz over a pty on the host, without and with CPU-bound competitors (one busy
loop per usable CPU by default); inside the one-CPU User Mode Linux guest: the same pty case and
dronecan-rawimu at 100 Hz and 1 kHz to vcan0 recorded by `candump -L` (classic CAN at 1 kHz needs
--allow-overload: 7 frames at 1 kHz exceed a 1 Mbit/s bus's worst-case budget, which vcan does not have), and
at 1 kHz over CAN FD (one 64-byte frame per sample, within a 1/5 Mbit/s budget: the admissible configuration).
The guest's figures are for completeness; its system calls cost ~50 us, so its lateness says little about a
real machine. Each run ends with a markdown table: min / median / max over the --repeat windows.
Modes are interleaved (default, spin, fifo, off, default, ...) so that load from others hits all alike.

    python tools/bench_coexist.py [--seconds 10] [--repeat 1] [--modes auto spin fifo off] [--no-guest] [--no-host]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench_stream import SCENE, read_until_exit  # noqa: E402  (tools/ is on the path: this script's folder)
from tests.support.stream import candump_frames, dronecan_rawimu  # noqa: E402  (the tests' receiver: dronecan reassembles)
from imu_emulator.live.realtime import LatenessStats  # noqa: E402
MODES = ("auto", "spin", "fifo", "off")
BUSY = "while True: pass"


def emulator(directory: Path, fmt: str, target: str, rate: float, seconds: float, mode: str, *extra: str):
    scene = directory / f"scene_{int(rate)}.toml"
    scene.write_text(SCENE.format(rate=rate))
    stats = directory / "stats.json"
    stats.unlink(missing_ok=True)
    command = [sys.executable, "-m", "imu_emulator", "stream", str(scene), "--format", fmt, "--to", target,
               "--loop", "--duration", str(seconds), "--quiet", "--stats-json", str(stats), *extra]
    if mode != "auto":   # the default is what a user gets without the option
        command += ["--realtime", mode]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, cwd=REPO, text=True)
    proc.usage_before = _children_cpu()   # the busy loops are reaped only after their cases
    return proc, stats


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def finish(proc, stats: Path, seconds: float) -> dict:
    """Wait for the emulator; its summary plus CPU seconds per streamed second."""
    proc.wait()
    if proc.returncode != 0 or not stats.exists():
        raise RuntimeError(f"emulator exited {proc.returncode}")
    summary = json.loads(stats.read_text())
    summary["cpu_per_s"] = (_children_cpu() - proc.usage_before) / seconds
    return summary


def pty_case(directory: Path, rate: float, seconds: float, mode: str) -> dict:
    """mavlink-highres to a pty read by this process at normal priority; completeness by time stamps."""
    from pymavlink.dialects.v20 import common as mavlink2
    proc, stats = emulator(directory, "mavlink-highres", "pty", rate, seconds, mode)
    path = proc.stdout.readline().split("-> ")[1].split()[0]
    fd = os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    chunks = []
    # Only read while streaming: parsing waits until the end, so the reader costs what a driver's would.
    read_until_exit(proc, fd, lambda now, data: chunks.append(data))
    summary = finish(proc, stats, seconds)
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    # Samples due before the reader opened the port are dropped as "no-reader": not due to this reader.
    first = summary["streams"][0]["link"].get("send_errors", {}).get("no-reader", 0)
    due = range(first, int(round(seconds * rate)))
    got = {round(m.time_usec * 1e-6 * rate) for m in mav.parse_buffer(b"".join(chunks)) or []
           if m.get_type() == "HIGHRES_IMU"}
    missing = sorted(set(due) - got)
    return {**summary, "due": len(due), "received": len(got & set(due)), "missing": missing[:10]}


def vcan_case(directory: Path, rate: float, seconds: float, mode: str, fd: bool = False) -> dict:
    """dronecan-rawimu to vcan0 recorded by candump at normal priority; complete transfers reassembled.
    Classic CAN: 7 frames per sample, which at 1 kHz exceed a 1 Mbit/s bus with worst-case stuffing (vcan has
    no bit rate to mind: --allow-overload); CAN FD: one 64-byte frame per sample, within a 1/5 Mbit/s budget."""
    log = directory / "candump.log"
    link = (["--fd", "--bitrate", "1000000", "--data-bitrate", "5000000", "--option", "fd=true"] if fd
            else ["--allow-overload"])
    with open(log, "w") as out:
        candump = subprocess.Popen(["candump", "-L", "vcan0"], stdout=out)
        try:
            proc, stats = emulator(directory, "dronecan-rawimu", "can:socketcan:vcan0", rate, seconds, mode, *link)
            proc.stdout.readline()
            summary = finish(proc, stats, seconds)
            time.sleep(0.5)   # candump drains what is queued for it
        finally:
            candump.terminate()
            candump.wait()
    frames = candump_frames(log.read_text())
    due = int(round(seconds * rate))
    transfers = dronecan_rawimu(frames, fd)
    got = {round(t.payload.timestamp.usec * 1e-6 * rate) for t in transfers}
    return {**summary, "due": due, "received": len(got & set(range(due))), "frames": len(frames),
            "frames_per_sample": 1 if fd else 7}


def vcan_fd_case(directory: Path, rate: float, seconds: float, mode: str) -> dict:
    return vcan_case(directory, rate, seconds, mode, fd=True)


def run_cases(cases, modes, repeat: int, seconds: float, competitors: int, place: str, emit) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        directory = Path(tmp)
        pty_case(directory, 100, 1.0, "off")   # warm the kernel cache
        for busy in sorted({0, competitors}):
            hogs = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(busy)]
            try:
                for name, case, rate in cases:
                    for _ in range(repeat):
                        for mode in modes:
                            row = case(directory, rate, seconds, mode)
                            emit({"place": place, "case": name, "rate": rate, "competitors": busy, "mode": mode,
                                  **row})
            finally:
                for hog in hogs:
                    hog.kill()
                    hog.wait()


def row_text(r: dict) -> str:
    late, shown = r["lateness"], LatenessStats.shown
    link = r["streams"][0]["link"]
    refused = sum(link.get("send_errors", {}).values())
    moved = {k: v for k, v in link.get("interface", {}).items() if v}
    frames = f" frames {r['frames']}/{r.get('frames_per_sample', 7) * r['due']}" if "frames" in r else ""
    return (f"{r['place']:5s} {r['case']:22s} {r['rate']:>5.0f} Hz  busy {r['competitors']}  {r['mode']:4s} "
            f"({r['scheduling']:4s})  received {r['received']}/{r['due']} ({100 * r['received'] / r['due']:6.2f} %)"
            f"{frames}  sent {r['streams'][0]['sent']} dropped {r['dropped']} refused {refused}"
            f"{' ' + str(moved) if moved else ''}  late p50/p99/p99.9/max {shown(late['p50_us'])}/{shown(late['p99_us'])}/"
            f"{shown(late['p999_us'])}/{late['max_us']:.0f} us, missed {late['missed']}, fifo given up "
            f"{r['fifo_given_up']}  sender cpu "
            f"{r['sender_cpu_ratio'] * 100:.1f} %, whole process {r['cpu_per_s'] * 100:.0f} %")


def _spread(values, digits: int = 0) -> str:
    """min / median / max of the windows, or the one value (a lateness quantile beyond the histogram, None, is
    shown as "> 65536000")."""
    over = [v for v in values if v is None]
    values = sorted(v for v in values if v is not None) + [float("inf")] * len(over)
    shown = [(LatenessStats.shown(None) if v == float("inf") else f"{v:.{digits}f}")
             for v in (values[0], statistics.median(values), values[-1])]
    return shown[0] if len(set(shown)) == 1 else " / ".join(shown)


def markdown_table(rows: list) -> str:
    """One line per case and mode over the repeated windows, for the README: min / median / max."""
    groups = {}
    for r in rows:
        key = (r["place"], r["case"], r["rate"], r["competitors"], r["mode"], r["scheduling"])
        groups.setdefault(key, []).append(r)
    lines = ["| where | case | busy loops | mode | windows | received % | late p50 µs | late p99 µs | "
             "late p99.9 µs | sender CPU % |", "|" + "---|" * 10]
    for (place, case, rate, busy, mode, scheduling), rs in groups.items():
        chosen = mode if mode == scheduling else f"{mode} ({scheduling})"
        lines.append(f"| {place} | {case} {rate:g} Hz | {busy} | {chosen} | {len(rs)} | "
                     f"{_spread([100 * r['received'] / r['due'] for r in rs], 2)} | "
                     f"{_spread([r['lateness']['p50_us'] for r in rs])} | "
                     f"{_spread([r['lateness']['p99_us'] for r in rs])} | "
                     f"{_spread([r['lateness']['p999_us'] for r in rs])} | "
                     f"{_spread([100 * r['sender_cpu_ratio'] for r in rs], 1)} |")
    return "\n".join(lines)


def guest(args) -> int:
    """The one-CPU guest's half (runs inside UML): rows as JSON lines on stdout."""
    cases = [("pty mavlink-highres", pty_case, 1000.0), ("vcan dronecan-rawimu", vcan_case, 100.0),
             ("vcan dronecan-rawimu", vcan_case, 1000.0), ("vcanfd dronecan-rawimu", vcan_fd_case, 1000.0)]
    cases = [c for c in cases if f"{c[0].split()[0]}{c[2]:g}" in args.guest_cases]
    run_cases(cases, args.modes, args.repeat, args.seconds, args.guest_competitors, "guest",
              lambda row: print("ROW " + json.dumps(row), flush=True))
    return 0


def boot_guest(args, show) -> None:
    sys.path.insert(0, str(REPO / "tests" / "support" / "uml"))
    import boot as uml
    reason = uml.unavailable()
    if reason:
        print(f"guest: skipped ({reason})")
        return
    with tempfile.TemporaryDirectory() as tmp:   # on the host's filesystem: the guest mounts its own /dev/shm
        script = Path(tmp) / "bench.sh"
        cache = os.environ.get("IMU_EMULATOR_CACHE")
        script.write_text((f"export IMU_EMULATOR_CACHE={cache!r}\n" if cache else "")
                          + f"{sys.executable!r} {str(Path(__file__).resolve())!r} --inside-guest "
                          f"--seconds {args.seconds} --repeat {args.repeat} --guest-competitors "
                          f"{args.guest_competitors} --modes {' '.join(args.modes)} --guest-cases {' '.join(args.guest_cases)}\n")
        # a loaded host slows the guest tenfold or more (3 s streams at 1 kHz took 35-50 s at load 9)
        runs = len(args.guest_cases) * len(args.modes) * args.repeat * (2 if args.guest_competitors else 1)
        budget = 120 + runs * (20 * args.seconds + 30)
        result = uml.boot(Path(tmp) / "result", script, timeout=budget)
    rows = [json.loads(line[4:]) for line in result.output.splitlines() if line.startswith("ROW ")]
    for row in rows:
        show(row)
    if result.exit_code != 0:
        print(f"guest: exit {result.exit_code}\n{result.output[-3000:]}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0, help="streamed seconds per run")
    parser.add_argument("--repeat", type=int, default=1, help="interleaved rounds over the modes")
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    parser.add_argument("--competitors", type=int, default=len(os.sched_getaffinity(0)),
                        help="CPU-bound busy loops on the host in the loaded runs (default: one per usable CPU)")
    parser.add_argument("--guest-competitors", type=int, default=0, help="busy loops in the guest (default none)")
    parser.add_argument("--guest-cases", nargs="+", choices=("pty1000", "vcan100", "vcan1000", "vcanfd1000"),
                        default=["pty1000", "vcan100", "vcan1000", "vcanfd1000"])
    parser.add_argument("--no-host", action="store_true")
    parser.add_argument("--no-guest", action="store_true")
    parser.add_argument("--json", metavar="PATH", help="also write every row as JSON lines")
    parser.add_argument("--inside-guest", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.inside_guest:
        return guest(args)
    out = open(args.json, "w") if args.json else None
    rows = []

    def show(row):
        rows.append(row)
        print(row_text(row), flush=True)
        if out:
            out.write(json.dumps(row) + "\n")

    print(f"host: {len(os.sched_getaffinity(0))} usable CPUs, load average {os.getloadavg()[0]:.1f} at start")
    if not args.no_host:
        run_cases([("pty mavlink-highres", pty_case, 1000.0)], args.modes, args.repeat, args.seconds,
                  args.competitors, "host", show)
    if not args.no_guest:
        boot_guest(args, show)
    print(f"load average {os.getloadavg()[0]:.1f} at end")
    if rows:
        print("\nmin / median / max over the windows (--repeat), markdown:\n")
        print(markdown_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
