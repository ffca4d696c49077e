"""`imu-emulator replay LOG`: a flight log's motion through the emulator, and a fidelity report against the
IMU the vehicle itself recorded (PX4 `sensor_combined`, ArduPilot `IMU`, a ROS 2 `sensor_msgs/msg/Imu`)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from imu_emulator.output.atomic import save_figure, write_text

AXES = "xyz"
MIN_PART_SAMPLES = 20       # a part between gaps shorter than this is left out (and named)


ORDER = 30     # place in `imu-emulator --help`


def register(subparsers) -> None:
    rep = subparsers.add_parser("replay", help="replay a flight log (.ulg, .bin, .mcap) and compare with its own IMU")
    rep.add_argument("log", help="flight log: PX4 ULog .ulg, ArduPilot DataFlash .bin, ROS 2 bag .mcap")
    rep.add_argument("--scene", help="TOML with overrides: [scene] rate_hz/t0_s/duration_s, [trajectory] "
                                     "derivative/position_source/attitude_source/max_gap_s/..., [[imu]], [effects]")
    rep.add_argument("--report", metavar="DIR", help="write report.md, report.json and PNG plots here")
    rep.add_argument("-o", "--output", help="emulated IMU file (.csv, .npz or .mcap; default DIR/emulated.csv with --report)")
    rep.add_argument("--imu-source", help="the recorded IMU to compare with (topic[:instance], message[:instance])")
    rep.add_argument("--lowpass-hz", type=float, help="cut-off of the low-passed figures (default: 0.4 x the "
                                                     "slower of the log's position and attitude rates)")
    rep.add_argument("--gaps", choices=("split", "error"), default="split",
                     help="a gap in the log's position or attitude longer than max_gap_s: replay each part between "
                          "gaps (split, the default; the output's time stamps jump across the gap) or stop with "
                          "an error naming the time")
    rep.add_argument("--quiet", action="store_true", help="no summary on stderr")
    rep.set_defaults(func=cmd_replay)


def _merge(base: dict, extra: dict) -> dict:
    out = dict(base)
    for key, value in extra.items():
        out[key] = _merge(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def build_scene_table(log: Path, overrides: dict, recorded_rate_hz: float | None) -> dict:
    """The replay scene as a table: the log as trajectory and attitude, gravity on, one IMU at the reference
    point, output at the recorded IMU's rate (or 100 Hz); anything in `overrides` wins, except the log file."""
    base = {"scene": {"rate_hz": round(recorded_rate_hz or 100.0, 6)},
            "trajectory": {}, "imu": [{"name": "imu0"}], "effects": {"gravity": True}}
    raw = _merge(base, overrides)
    raw["trajectory"] = dict(raw["trajectory"], file=str(log.resolve()))
    return raw


def build_scene(log: Path, overrides: dict, recorded_rate_hz: float | None):
    from imu_emulator.scene.load import from_dict
    return from_dict(build_scene_table(log, overrides, recorded_rate_hz), base_dir=log.parent, path=str(log))


def _parts(log: Path, overrides: dict, recorded_rate_hz: float | None) -> list[dict]:
    """The overrides of one scene per part of the log between gaps (within the overrides' own t0_s and
    duration_s). Parts too short for the derivative method are left out and named in an error if none is
    left."""
    import numpy as np

    from imu_emulator.scene import logs
    from imu_emulator.errors import DataError
    probe = build_scene_table(log, overrides, recorded_rate_hz)
    table, head = probe["trajectory"], probe["scene"]
    numbers = [head.get(k, 0.0) for k in ("t0_s", "duration_s", "rate_hz")] + [table.get("max_gap_s", 1.0)]
    if not isinstance(table, dict) or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                              for x in numbers):
        return [overrides]          # the scene's own validation names what is wrong
    motion = logs.load_log(log, table.get("position_source"), table.get("attitude_source"))
    t_lo = head.get("t0_s")
    t_hi = None if t_lo is None or "duration_s" not in head else t_lo + head["duration_s"]
    rate = head["rate_hz"]
    parts, short = [], []
    for lo, hi in logs.segments(motion, table.get("max_gap_s"), t_lo, t_hi):
        n = int(np.floor((hi - lo) * rate + 1e-9)) + 1        # samples lo, lo + 1/rate, ... <= hi
        if n < MIN_PART_SAMPLES:
            short.append(f"{lo:.3f}..{hi:.3f} s")
            continue
        parts.append(_merge(overrides, {"scene": {"t0_s": lo, "duration_s": n / rate}}))
    if not parts:
        raise DataError(f"{log.name}: no part between gaps holds {MIN_PART_SAMPLES} output samples "
                        f"(parts: {', '.join(short) or 'none'})")
    if short:
        print(f"note: parts between gaps too short to replay (under {MIN_PART_SAMPLES} samples), left out: "
              f"{', '.join(short)}", file=sys.stderr)
    return parts


def _read_overrides(path: str | None) -> dict:
    if path is None:
        return {}
    import tomllib

    from imu_emulator.errors import SceneError
    try:
        return tomllib.loads(Path(path).read_text())
    except OSError as exc:
        raise SceneError(f"{path}: cannot read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML: {exc}") from None


def cmd_replay(args) -> int:
    import numpy as np

    from imu_emulator.scene import logs
    from imu_emulator.errors import ImuEmulatorError
    from imu_emulator.analysis.fidelity import compare
    from imu_emulator.output.formats import check_path, open_writer
    from imu_emulator.runtime.simulation import Simulation

    log = Path(args.log)
    if not log.exists():
        raise ImuEmulatorError(f"{log}: no such file")
    if logs.log_kind(log) is None:
        raise ImuEmulatorError(f"{log}: not a flight log (expected {', '.join(logs.SUFFIXES)})")
    if args.report is None and args.output is None:
        raise ImuEmulatorError("replay: give --report DIR, -o FILE or both")
    report = Path(args.report) if args.report else None
    if report is not None:
        report.mkdir(parents=True, exist_ok=True)
    output = check_path(args.output or report / "emulated.csv")

    recorded = logs.load_recorded_imu(log, args.imu_source)
    rate = 1.0 / float(np.median(np.diff(recorded.t))) if recorded is not None else None
    overrides = _read_overrides(args.scene)
    parts = _parts(log, overrides, rate) if args.gaps == "split" else [overrides]
    from imu_emulator.effects.noise import variances
    writer, out, written = None, None, 0
    for i, part in enumerate(parts):
        scene = build_scene(log, part, rate)
        for warning in scene.warnings if i == 0 else ():
            print(f"warning: {warning}", file=sys.stderr)
        block = Simulation(scene).run()
        if writer is None:
            writer = open_writer(output, scene.imu_names, truth=False, covariances=variances(scene))
        writer.write(block)
        written += len(block)
        if out is None or len(block) > len(out):    # the fidelity report compares the longest part
            out, compared = block, scene
    writer.close()
    if len(parts) > 1:
        spans = ", ".join(f"{p['scene']['t0_s']:.3f}..{p['scene']['t0_s'] + p['scene']['duration_s']:.3f} s"
                          for p in parts)
        print(f"note: the log has gaps; replayed {len(parts)} parts ({spans}); the report compares the longest",
              file=sys.stderr)
    scene = compared
    if not args.quiet:
        print(f"wrote {written} samples x {len(scene.imus)} IMU(s) to {output}", file=sys.stderr)
    if report is None:
        return 0
    if recorded is None:
        write_text(report / "report.md", f"# Replay of {log.name}\n\nThe log holds no recorded IMU to compare "
                                   "with; only the emulated IMU was written.\n")
        print(f"note: {log.name} holds no recorded IMU; no fidelity figures", file=sys.stderr)
        return 0
    lowpass_hz = args.lowpass_hz or 0.4 * min(_rate(scene.trajectory.t), _rate(scene.attitude.t))
    results = [compare(q, out.t_s, getattr(out, q)[0], recorded.t, getattr(recorded, q), scene.rate_hz, lowpass_hz)
               for q in ("gyro", "accel")]
    figures = {"log": str(log), "recorded_imu": recorded.name, "emulated_imu": scene.imu_names[0],
               "position_source": scene.trajectory.source, "attitude_source": scene.attitude.source,
               "derivative": scene.trajectory.derivative, "rate_hz": scene.rate_hz, "frame": scene.frame,
               "comparisons": [r.figures() for r in results]}
    write_text(report / "report.json", json.dumps(figures, indent=2) + "\n")
    write_text(report / "report.md", _markdown(figures))
    _plots(results, report)
    if not args.quiet:
        print(_markdown(figures), file=sys.stderr)
    return 0


def _rate(t) -> float:
    import numpy as np
    return 1.0 / float(np.median(np.diff(t)))


def _markdown(figures: dict) -> str:
    lines = [f"# Replay of {Path(figures['log']).name}", "",
             f"Recorded IMU `{figures['recorded_imu']}` against the emulated `{figures['emulated_imu']}` "
             f"({figures['rate_hz']:g} Hz, {figures['frame']}, derivative `{figures['derivative']}`; position from "
             f"`{figures['position_source']}`, attitude from `{figures['attitude_source']}`).", ""]
    for c in figures["comparisons"]:
        unit = "rad/s" if c["quantity"] == "gyro" else "m/s²"
        lines += [f"## {c['quantity']} ({unit}), {c['samples']} samples; time offset {c['time_offset_s'] * 1e3:+.1f} ms "
                  f"(recorded lags emulated when positive); low-pass {c['lowpass_hz']:.2g} Hz", "",
                  "| axis | correlation | correlation low-passed | RMS difference | RMS difference low-passed | bias |",
                  "|---|---|---|---|---|---|"]
        for axis, a in zip(AXES, c["axes"]):
            lines.append(f"| {axis} | {a['correlation']:.3f} | {a['correlation_lowpassed']:.3f} | "
                         f"{a['rms_difference']:.3g} | {a['rms_difference_lowpassed']:.3g} | {a['bias']:+.3g} |")
        lines.append("")
    return "\n".join(lines)


def _plots(results, report: Path) -> None:
    try:
        import matplotlib
    except ImportError:
        print("note: matplotlib is not installed (pip install 'imu-emulator[plot]'); no plots", file=sys.stderr)
        return
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    for r in results:
        unit = "rad/s" if r.quantity == "gyro" else "m/s²"
        fig, axes = plt.subplots(3, 2, figsize=(12, 8), sharex=True)
        t = r.t - r.t[0]
        for i in range(3):
            axes[i, 0].plot(t, r.recorded[:, i], lw=0.6, label="recorded")
            axes[i, 0].plot(t, r.emulated[:, i], lw=0.8, label="emulated")
            axes[i, 0].set_ylabel(f"{r.quantity} {AXES[i]} ({unit})")
            axes[i, 1].plot(t, r.recorded[:, i] - r.emulated[:, i], lw=0.6, color="C3")
            axes[i, 1].set_ylabel("recorded - emulated")
        axes[0, 0].legend(loc="upper right")
        axes[2, 0].set_xlabel("s from start")
        axes[2, 1].set_xlabel("s from start")
        fig.tight_layout()
        save_figure(fig, report / f"{r.quantity}.png", dpi=110)
        plt.close(fig)
