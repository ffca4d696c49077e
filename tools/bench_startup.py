"""Start-up cost of the command line, warm cache: `generate examples/circle.toml -o x.npz` (600 s at 1 kHz) end to
end (kernel loaded as machine code, and with IMU_EMULATOR_NATIVE=0 from numba's cache), and the time from
launching `stream` to its first packet on a pty. Each run is a fresh process; the two are
interleaved; wall time and the child's CPU time (user + sys) are printed as min/median/max.

Then, for every format of `imu-emulator formats` (interleaved): launch to the first packet (serial formats on a
pty, CAN formats on a virtual SLCAN adapter's pty, both read by this process) and the whole process of a stream of
one sample to a file, wall and CPU. With --importtime, also the slowest imports of one `generate` and the total
(python -X importtime). Prints figures, asserts nothing.

    .venv/bin/python tools/bench_startup.py [--repeats 7] [--importtime] [--formats a,b] [--no-formats]

Also prints the cold-start compile time of examples/helix.toml (empty kernel cache) unless --no-cold.
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

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_stream import launch, read_until_exit  # noqa: E402


def run_timed(args, env) -> tuple[float, float]:
    """Wall seconds and the child's CPU seconds (user + sys) of one command."""
    started = time.monotonic()
    proc = subprocess.Popen(args, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.monotonic() - started
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise SystemExit(f"{' '.join(map(str, args))} failed: {proc.stderr.read().decode()}")
    return wall, usage.ru_utime + usage.ru_stime


def first_packet(directory: Path, native: bool = True, fmt: str = "mavlink-highres", kind: str = "serial",
                 seconds: float = 1.0) -> float:
    os.environ["IMU_EMULATOR_NATIVE"] = "1" if native else "0"     # launch() passes our environment on
    # CAN formats on a virtual SLCAN adapter; beyond its nominal 1 Mbit/s at 1 kHz for the 7-frame formats
    target, extra = ("can:slcan:pty", ("--allow-overload",)) if kind == "can" else ("pty", ())
    try:
        proc, fd, started = launch(directory, 1000, seconds, directory / "first.json", fmt, target, extra)
        first = read_until_exit(proc, fd)
        if first is None:
            raise SystemExit(f"stream of {fmt} to {target}: nothing arrived")
        return first - started
    finally:
        del os.environ["IMU_EMULATOR_NATIVE"]


def summary(values, unit="s") -> str:
    return f"{min(values):.3f}/{statistics.median(values):.3f}/{max(values):.3f} {unit}"


def every_format(tmp: Path, env: dict, repeats: int, only: list[str] | None) -> None:
    """Per format: launch to the first packet, and a stream of one sample to a file as a whole process."""
    import firmware_protocols as fp
    kinds = {name: info.kind for name, info in sorted(fp.formats().items()) if not only or name in only}

    def to_file(name: str) -> list:
        path = tmp / f"one.{'log' if kinds[name] == 'can' else 'bin'}"
        return [sys.executable, "-m", "imu_emulator", "stream", "examples/circle.toml", "--format", name, "--to",
                f"file:{path}", "--count", "1", "--quiet"]
    first, wall, cpu = ({name: [] for name in kinds} for _ in range(3))
    for name in kinds:                 # fill the encoders' and devices' caches
        run_timed(to_file(name), env)
        first_packet(tmp, fmt=name, kind=kinds[name], seconds=0.2)
    for _ in range(repeats):           # interleaved, the machine is shared
        for name in kinds:
            first[name].append(first_packet(tmp, fmt=name, kind=kinds[name], seconds=0.2))
            w, c = run_timed(to_file(name), env)
            wall[name].append(w)
            cpu[name].append(c)
    print(f"every format, warm (min/median/max of {repeats}): launch to first packet (serial: pty, CAN: can:slcan:pty);"
          " whole process of `stream --to file:... --count 1`")
    print(f"  {'format':22s} {'first packet wall':>24s} {'one sample to a file, wall':>28s} {'CPU':>22s}")
    for name in kinds:
        print(f"  {name:22s} {summary(first[name]):>24s} {summary(wall[name]):>28s} {summary(cpu[name]):>22s}")
    worst = max(kinds, key=lambda n: statistics.median(first[n]))
    print(f"  slowest median first packet: {worst} {statistics.median(first[worst]):.3f} s")


def importtime(env, out: Path, top: int = 12) -> None:
    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", "imu_emulator", "generate", "examples/circle.toml",
                           "-o", str(out), "--quiet"], cwd=REPO, env=env, capture_output=True, text=True, check=True)
    rows = []
    for line in proc.stderr.splitlines():
        if line.startswith("import time:") and "cumulative" not in line:
            _, cumulative, name = line[len("import time:"):].split("|")
            rows.append((int(cumulative), name[1:]))
    top_level = [(c, n) for c, n in rows if not n.startswith(" ")]
    print(f"imports of a warm generate (-X importtime): {sum(c for c, _ in top_level) / 1e3:.1f} ms in all "
          f"(top-level cumulative), {len(rows)} modules; imu_emulator.effects "
          f"{'imported' if any(n.strip() == 'imu_emulator.effects' for _, n in rows) else 'not imported'}")
    print("slowest top-level imports of a warm generate (cumulative, -X importtime):")
    for cumulative, name in sorted(top_level, reverse=True)[:top]:
        print(f"  {cumulative / 1e3:8.1f} ms  {name}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--importtime", action="store_true")
    parser.add_argument("--no-cold", action="store_true")
    parser.add_argument("--no-formats", action="store_true", help="skip the per-format table")
    parser.add_argument("--formats", help="comma-separated formats for the per-format table (default: all)")
    args = parser.parse_args()
    # Start-up as users see it: with the package's bytecode cached (a shell that sets PYTHONDONTWRITEBYTECODE would
    # time compiling every changed module's source instead)
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        env = dict(os.environ, IMU_EMULATOR_CACHE=str(tmp / "cache"))
        os.environ["IMU_EMULATOR_CACHE"] = env["IMU_EMULATOR_CACHE"]   # for bench_stream.launch
        generate = [sys.executable, "-m", "imu_emulator", "generate", "examples/circle.toml", "-o", str(tmp / "x.npz"),
                    "--quiet"]
        if not args.no_cold:
            wall, cpu = run_timed([sys.executable, "-m", "imu_emulator", "generate", "examples/helix.toml", "-o",
                                   str(tmp / "h.npz"), "--quiet"], env)
            print(f"cold generate examples/helix.toml (compiles its kernel): {wall:.2f} s wall, {cpu:.2f} s CPU")
        numba_env = dict(env, IMU_EMULATOR_NATIVE="0")     # kernels and encoders from numba's own cache
        run_timed(generate, env)          # warm the kernel caches
        run_timed(generate, numba_env)
        first_packet(tmp)
        first_packet(tmp, native=False)
        gen_wall, gen_cpu = {"machine code": [], "numba": []}, {"machine code": [], "numba": []}
        packet = {"machine code": [], "numba": []}
        for _ in range(args.repeats):     # interleaved, the machine is shared
            for name, variant_env in (("machine code", env), ("numba", numba_env)):
                wall, cpu = run_timed(generate, variant_env)
                gen_wall[name].append(wall)
                gen_cpu[name].append(cpu)
                packet[name].append(first_packet(tmp, native=name == "machine code"))
        load = os.getloadavg()[0]
        for name in gen_wall:
            print(f"warm generate examples/circle.toml -o x.npz (600 000 samples), kernel loaded as {name}: "
                  f"wall {summary(gen_wall[name])}, CPU {summary(gen_cpu[name])}")
        ratio = statistics.median(gen_cpu["numba"]) / statistics.median(gen_cpu["machine code"])
        print(f"  CPU median ratio numba / machine code: {ratio:.2f}")
        for name in packet:
            print(f"warm stream (mavlink-highres, 1 kHz), launch to first packet on a pty, {name}: "
                  f"wall {summary(packet[name])}")
        print(f"(min/median/max of {args.repeats}; 1-minute load average {load:.1f} on {os.cpu_count()} CPUs)")
        if not args.no_formats:
            every_format(tmp, env, args.repeats, args.formats.split(",") if args.formats else None)
            print(f"(1-minute load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs)")
        if args.importtime:
            importtime(env, tmp / "x.npz")


if __name__ == "__main__":
    main()
