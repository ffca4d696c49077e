"""`imu-emulator check`: validate a scene and say what it will do, without compiling or running anything."""
from __future__ import annotations

import numpy as np
import sys

ORDER = 50     # place in `imu-emulator --help`


def register(subparsers) -> None:
    p = subparsers.add_parser("check", help="validate a scene and describe it without running it",
                              description="Validate a scene file; print its frame and conventions, IMUs and effects, "
                                          "sample count, output sizes, each [[stream]]'s link budget and whether "
                                          "its kernel is compiled in the cache. Exit 2 with one error line if bad.")
    p.add_argument("scene", help="scene file (TOML)")
    p.set_defaults(func=cmd_check)


def _megabytes(n_bytes: float) -> str:
    return f"{n_bytes / 1e6:,.1f} MB"


def output_sizes(scene, truth: bool, increments: bool = False) -> dict[str, int]:
    """Bytes of `generate`'s output per format, by name (each format's estimated_bytes,
    imu_emulator.output.formats: NPZ within its headers, CSV an estimate, Parquet and MCAP uncompressed bounds),
    and "CSV bound", the CSV at its longest."""
    from imu_emulator.output.formats import by_name
    from imu_emulator.output.formats.csv import csv_bytes
    sizes = {name: record.estimated_bytes(scene, truth, increments and record.increments)
             for name, record in by_name().items()}
    return {**sizes, "CSV bound": csv_bytes(scene, truth, increments)}


def _compact(value) -> str:
    """A parameter's value for reading: one number for three equal axes, 6 significant digits."""
    array = np.asarray(value, dtype=float)
    if array.ndim == 1 and array.size and np.all(array == array[0]):
        array = array[0]
    if array.ndim == 0:
        return f"{float(array):.6g}"
    return "[" + ", ".join(_compact(row) for row in array) + "]"


def imu_parameter_lines(imu, effect_names, records) -> list[str]:
    """The non-zero parameters of the effects that are on, one a line in the records' (SI) units, under the
    effect's name; a parameter left at zero means that error is absent and is not listed."""
    lines = []
    for name in effect_names:
        shown = [f"{param.path[4:]} = {_compact(imu.values[param.path])} {param.unit}"
                 for param in records[name].params if np.any(np.asarray(imu.values[param.path], dtype=float) != 0)]
        lines += [f"{name if i == 0 else '':16} {text}" for i, text in enumerate(shown)]
    return lines


def _describe_part(part) -> str:
    from imu_emulator.scene.model import Expressions
    if isinstance(part, Expressions):
        return ", ".join(part.texts)
    return f"{len(part.t)} samples from {part.source}, derivatives by {part.derivative}"


def cmd_check(args) -> int:
    from imu_emulator.runtime import kernels
    from imu_emulator.effects import EFFECTS
    from imu_emulator.scene.load import load_scene
    from imu_emulator.live.budget import link_budget
    from imu_emulator.live.config import streams_from_tables
    from imu_emulator.live.stream import build_streams

    scene = load_scene(args.scene)
    streams = build_streams(streams_from_tables(scene.streams, scene.imu_names), scene.imu_names, scene.rate_hz)

    print(f"scene {args.scene}: valid")
    body = "forward-left-up" if scene.frame == "ENU" else "forward-right-down"
    gravity = f"(0, 0, {'+' if scene.frame == 'ENU' else '-'}g)"
    print(f"  frame      {scene.frame} (body {body}; at rest and level f = {gravity}, g = {scene.gravity_mps2!r} m/s²)")
    print("  attitude   z-y-x: R = Rz(yaw)·Ry(pitch)·Rx(roll) maps body to navigation; gyros give body-frame rate")
    print("  wires      each in its manual's axes: an unmounted IMU reads as the part upright, facing forward "
          "(`formats --details`)")
    from imu_emulator.motion import earth_truth
    from imu_emulator.scene.earth import model_on
    if model_on(scene):
        for line in earth_truth.conventions(scene)[:2] + earth_truth.conventions(scene)[4:5]:
            print(f"  earth      {line}")
    print(f"  time       {scene.n_samples:,} samples at {scene.rate_hz:g} Hz, t = {scene.t0_s!r} .. "
          f"{scene.t0_s + (scene.n_samples - 1) / scene.rate_hz!r} s")
    if scene.params:
        print("  params     " + ", ".join(f"{k} = {v!r}" for k, v in scene.params.items()))
    print(f"  trajectory {_describe_part(scene.trajectory)}")
    if scene.attitude_mode == "tangent":
        print(f"  attitude   tangent to the velocity, roll 0 (initial heading "
              f"{scene.initial_heading_rad * 57.29577951308232:g}°)")
    else:
        print(f"  attitude   {scene.attitude_mode}: {_describe_part(scene.attitude)}")
    print("  effects    " + (", ".join(sorted(scene.effects)) or "none (no gravity either)"))
    for name in sorted(scene.effects):
        print(f"    {name:16} {EFFECTS[name].description}")
    for imu in scene.imus:
        print(f"  imu {imu.name}:" + (f" time offset {imu.time_offset_s!r} s" if imu.time_offset_s else ""))
        lines = imu_parameter_lines(imu, sorted(scene.effects), EFFECTS)
        for line in lines or ["no parameters"]:
            print(f"    {line}")
        for name, values in sorted(imu.companions.items()):     # companion sensors (imu_emulator.companions)
            print(f"    {name:16} " + ", ".join(f"{key} = {value!r}" for key, value in values.items()
                                                 if (any(value) if isinstance(value, tuple) else value != 0.0)))
    for warning in scene.warnings:
        print(f"  warning: {warning}")
    sizes = output_sizes(scene, truth=False)
    sizes_truth = output_sizes(scene, truth=True)
    sizes_all = output_sizes(scene, truth=True, increments=True)
    print(f"  generate   NPZ {_megabytes(sizes['NPZ'])} ({_megabytes(sizes_truth['NPZ'])} with --truth, "
          f"{_megabytes(sizes_all['NPZ'])} with --truth --increments); CSV about {_megabytes(sizes['CSV'])} "
          f"({_megabytes(sizes_truth['CSV'])}, {_megabytes(sizes_all['CSV'])}; at most "
          f"{_megabytes(sizes_all['CSV bound'])}); Parquet at most {_megabytes(sizes['Parquet'])} "
          f"({_megabytes(sizes_truth['Parquet'])}, {_megabytes(sizes_all['Parquet'])}), MCAP at most "
          f"{_megabytes(sizes['MCAP'])} ({_megabytes(sizes_truth['MCAP'])} with --truth), before compression")

    problems = []
    for stream in streams:
        budget = link_budget(stream, scene.rate_hz)
        c = stream.config
        verdict = ("no rate limit on this link" if budget.load is None
                   else f"{budget.load:.0%} of {budget.capacity}" + (" — DOES NOT FIT" if budget.load > 1 else ""))
        print(f"  stream     {c.imu} as {c.format} to {c.target}: needs {budget.need}; {verdict}")
        if budget.load is not None and budget.load > 1:
            problems.append(f"stream {c.imu} {c.format} to {c.target} needs more than its link carries "
                            f"({budget.load:.0%}); `stream` refuses it without --allow-overload")

    for command, attitude, truth in (("generate", False, False), ("generate --truth", False, True),
                                     ("stream", True, False)):
        path, compiled = kernels.cached_kernel(scene, attitude=attitude, truth=truth)
        state = "compiled in the cache" if compiled else "not compiled yet (the first run compiles it)"
        print(f"  kernel     {command}: {state} ({path.name})")
    if problems:
        print(f"error: {problems[0]}", file=sys.stderr)
        return 2
    return 0
