"""Start-up cost of the command line, warm cache: `generate examples/circle.toml -o x.npz` (600 s at 1 kHz) end to
end (kernel loaded as machine code, and with IMU_EMULATOR_NATIVE=0 from numba's cache), and the time from
launching `stream` to its first packet on a pty. Each run is a fresh process; the two are
interleaved; wall time and the child's CPU time (user + sys) are printed as min/median/max. With --importtime,
also the slowest imports of one `generate` (python -X importtime). Prints figures, asserts nothing.

    .venv/bin/python tools/bench_startup.py [--repeats 7] [--importtime]

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


def first_packet(directory: Path, native: bool = True) -> float:
    os.environ["IMU_EMULATOR_NATIVE"] = "1" if native else "0"     # launch() passes our environment on
    try:
        proc, fd, started = launch(directory, 1000, 1.0, directory / "first.json")
        return read_until_exit(proc, fd) - started
    finally:
        del os.environ["IMU_EMULATOR_NATIVE"]


def summary(values, unit="s") -> str:
    return f"{min(values):.3f}/{statistics.median(values):.3f}/{max(values):.3f} {unit}"


def importtime(env, out: Path, top: int = 12) -> None:
    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", "imu_emulator", "generate", "examples/circle.toml",
                           "-o", str(out), "--quiet"], cwd=REPO, env=env, capture_output=True, text=True, check=True)
    rows = []
    for line in proc.stderr.splitlines():
        if line.startswith("import time:") and "cumulative" not in line:
            _, cumulative, name = line[len("import time:"):].split("|")
            rows.append((int(cumulative), name[1:]))
    top_level = [(c, n) for c, n in rows if not n.startswith(" ")]
    print("slowest top-level imports of a warm generate (cumulative, -X importtime):")
    for cumulative, name in sorted(top_level, reverse=True)[:top]:
        print(f"  {cumulative / 1e3:8.1f} ms  {name}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--importtime", action="store_true")
    parser.add_argument("--no-cold", action="store_true")
    args = parser.parse_args()
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
        # DroneCAN's encoders take structured arrays and stay on numba: the whole process to one frame in a file
        to_file = [[sys.executable, "-m", "imu_emulator", "stream", "examples/circle.toml", "--format", f, "--to",
                    f"file:{tmp / name}", "--count", "1"] for f, name in (("dronecan-rawimu", "x.log"),
                                                                           ("mavlink-highres", "x.bin"))]
        for command in to_file:          # warm their encoders' caches
            run_timed(command, env)
        dronecan = [run_timed(command, env)[0] for _ in range(args.repeats) for command in to_file]
        print(f"warm stream to a file, whole process to one sample: dronecan-rawimu wall {summary(dronecan[0::2])}, "
              f"mavlink-highres wall {summary(dronecan[1::2])}")
        print(f"(min/median/max of {args.repeats}; 1-minute load average {load:.1f} on {os.cpu_count()} CPUs)")
        if args.importtime:
            importtime(env, tmp / "x.npz")


if __name__ == "__main__":
    main()
