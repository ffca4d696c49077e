"""Scene files (TOML) and scene dicts -> a frozen, validated Scene (imu_emulator.scene.model).

Validation happens once, here, one loader per table; everything downstream trusts the Scene. Errors name the key
("trajectory.x", "imu[1].lever_arm_m") and the reason (imu_emulator.scene.checks).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from imu_emulator.errors import DataError, SceneError
from imu_emulator.numerics import expressions
from imu_emulator.scene import sources
from imu_emulator.scene.checks import check_time_resolution, choice, no_unknown, number, shown_key, subtable
from imu_emulator.scene.files import MAX_SCENE_BYTES, read_regular
from imu_emulator.scene.earth import GEODETIC_KEYS, attitude_reference, earth_keys
from imu_emulator.scene.companions import check_origin
from imu_emulator.scene.imus import imu_specs
from imu_emulator.scene.model import (ATTITUDE_MODES, FRAMES, MAX_ANGLE_DEG, MAX_DURATION_S, MAX_GRAVITY_MPS2,
                                      RATE_RANGE_HZ, SEED_LIMIT, Expressions, SampledData, Scene)

# Deepest nesting of tables and arrays a scene may have (a matrix parameter in an IMU table is 4 levels): the
# checks, the digest and the cache key recurse over values.
MAX_NESTING = 16

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def from_dict(raw: Mapping[str, Any], base_dir: str | Path = ".", path: str | None = None) -> Scene:
    """Validate a scene given as nested dicts (the parsed TOML, or built in code). The tables are read in the
    order their checks need: the attitude after the trajectory (a file's columns, a shape's implied attitude),
    the time span after both (sampled input sets it), the Earth keys after the frame and the effects."""
    if not isinstance(raw, Mapping):
        raise SceneError("scene: expected a table at the top level")
    _check_nesting(raw)
    no_unknown(raw, {"scene", "params", "trajectory", "attitude", "imu", "effects", "stream"}, "scene file")
    warnings: list[str] = []
    head = subtable(raw, "scene")
    seed, rate, frame, gravity = _head(head)
    params = _params(raw)
    traj_table = subtable(raw, "trajectory")
    trajectory, track, log, implied_attitude = _trajectory(traj_table, frame, gravity, params, Path(base_dir),
                                                           warnings)
    att_table = subtable(raw, "attitude") or implied_attitude
    mode, heading, attitude = _attitude(att_table, trajectory, track, log, params, warnings)
    sources.check_sample_counts(trajectory, attitude, mode)
    frame, t0, duration, trajectory, attitude = _time_span(head, traj_table, frame, rate, trajectory, attitude, log)
    effects = _effects(raw)
    origin, gravity_model = earth_keys(head, frame, effects, mode, "shape" in traj_table, trajectory, warnings)
    reference = attitude_reference(att_table, frame, effects, trajectory, gravity_model)
    imus = imu_specs(raw, effects, t0, duration, rate, warnings)
    check_origin(imus, frame, origin, trajectory)
    streams = _streams(raw)
    return Scene(rate_hz=rate, duration_s=duration, frame=frame, gravity_mps2=gravity, t0_s=t0,
                 params=params, trajectory=trajectory, attitude_mode=mode, attitude=attitude,
                 initial_heading_rad=heading, imus=imus, effects=effects,
                 streams=streams, path=path, warnings=tuple(warnings), seed=seed,
                 origin=origin, gravity_model=gravity_model, attitude_reference=reference)


def _check_nesting(raw: Mapping) -> None:
    """Refuse values nested beyond MAX_NESTING, naming the key, without recursing (the value may be deeper than
    Python's stack)."""
    pending = [(raw, "", 0)]
    while pending:
        value, where, depth = pending.pop()
        if depth > MAX_NESTING:
            raise SceneError(f"{where}: nested more than {MAX_NESTING} levels deep")
        if isinstance(value, Mapping):
            pending.extend((v, f"{where}.{shown_key(k)}" if where else shown_key(k), depth + 1)
                           for k, v in value.items())
        elif isinstance(value, (list, tuple)):
            pending.extend((v, f"{where}[{i}]", depth + 1) for i, v in enumerate(value))


def _deep_line(text: str) -> str:
    """"line N (key K)" where brackets first nest beyond MAX_NESTING, for the message when tomllib's recursion
    fails (then there is no parsed value to name the key from). Brackets inside quoted strings are skipped."""
    depth, quote = 0, None
    for line_no, line in enumerate(text.splitlines(), start=1):
        for char in line:
            if quote:
                quote = None if char == quote else quote
            elif char in "\"'":
                quote = char
            elif char == "#":
                break
            elif char in "[{":
                depth += 1
                if depth > MAX_NESTING:
                    key = line.split("=", 1)[0].strip() if "=" in line else ""
                    return f"line {line_no}" + (f" (key {shown_key(key)})" if key else "")
            elif char in "]}":
                depth = max(depth - 1, 0)
    return "a value"


def load_scene(path: str | Path) -> Scene:
    """Read and validate a TOML scene file."""
    path = Path(path)
    try:
        text = read_regular(path, MAX_SCENE_BYTES).decode("utf-8")
    except OSError as exc:
        raise SceneError(f"{path}: cannot read scene file: {exc.strerror}") from None
    except DataError as exc:
        raise SceneError(f"{path}: cannot read scene file: {exc}") from None
    except UnicodeDecodeError as exc:
        raise SceneError(f"{path}: not UTF-8 text (byte {exc.start} is {exc.object[exc.start]:#04x}); "
                         "TOML scene files are UTF-8") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:
        # tomllib recurses once per level of nested arrays and inline tables: a few hundred exhaust the stack
        raise SceneError(f"{path}: {_deep_line(text)}: arrays or inline tables nested too deeply to read (a scene "
                         f"nests at most {MAX_NESTING} levels)") from None
    try:
        return from_dict(raw, base_dir=path.parent, path=str(path))
    except SceneError as exc:
        raise SceneError(f"{path}: {exc}") from None


# --- one loader per table ---------------------------------------------------------------------------------

def _head(head: Mapping) -> tuple[int, float, str, float]:
    """[scene]: (seed, rate_hz, frame, gravity_mps2); its time keys wait for the trajectory (_time_span), its
    Earth keys for the effects (imu_emulator.scene.earth.earth_keys)."""
    no_unknown(head, {"rate_hz", "duration_s", "frame", "gravity_mps2", "t0_s", "name", "seed", "origin",
                      "gravity_model"}, "scene")
    seed = _seed(head)
    rate = number(head, "rate_hz", "scene", required=True, positive=True)
    if not RATE_RANGE_HZ[0] <= rate <= RATE_RANGE_HZ[1]:
        raise SceneError(f"scene.rate_hz: {rate!r} is out of range ({RATE_RANGE_HZ[0]:g} to {RATE_RANGE_HZ[1]:g} Hz)")
    frame = choice(head, "frame", "scene", FRAMES, "ENU")
    gravity = number(head, "gravity_mps2", "scene", default=9.80665, bound=MAX_GRAVITY_MPS2, unit=" m/s^2")
    return seed, rate, frame, gravity


def _seed(head: Mapping) -> int:
    value = head.get("seed", 0)
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= int(value) < SEED_LIMIT:
        raise SceneError(f"scene.seed: expected an integer from 0 to 2**64 - 1, got {value!r}")
    return int(value)


def _params(raw: Mapping) -> dict[str, float]:
    table = subtable(raw, "params")
    values: dict[str, float] = {}
    reserved = {"t", *expressions.CONSTANTS, *expressions.FUNCTIONS}
    for name, value in table.items():
        where = f"params.{shown_key(name)}"
        if not name.isidentifier() or name in reserved:
            raise SceneError(f"{where}: not a usable name (reserved or not an identifier)")
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise SceneError(f"{where}: expected a number or an expression of earlier params, got {value!r}")
        tree = expressions.check(value, where, values)
        if expressions.uses_time(tree):
            raise SceneError(f"{where}: params are constants; 't' is not allowed here")
        values[name] = expressions.evaluate_constant(tree, values, where)
    return values


def _expressions(table: Mapping, keys, where: str, params: Mapping[str, float]) -> Expressions:
    texts = []
    for key in keys:
        text = table.get(key, 0)
        expressions.check(text, f"{where}.{key}", params)
        texts.append(str(text))
    return Expressions(tuple(texts))


def _trajectory(table: Mapping, frame: str, gravity: float, params: Mapping[str, float], base_dir: Path,
                warnings: list[str]):
    """[trajectory]: (the trajectory, the track behind it or None, the flight log behind it or None, the
    [attitude] table a shape implies or {})."""
    if not table:
        raise SceneError("trajectory: missing (give x/y/z expressions, a shape, or a file)")
    if "shape" in table:
        trajectory, track, implied_attitude = sources.shape_trajectory(table, "trajectory", frame, gravity)
        return trajectory, track, None, implied_attitude
    if sources.is_log(table):
        trajectory, log = sources.logged_trajectory(table, base_dir, warnings)
        return trajectory, None, log, {}
    if "file" in table or "t" in table:
        trajectory, track = sources.track_trajectory(table, base_dir, warnings)
        return trajectory, track, None, {}
    if {"lat_deg", "lon_deg", "height_m"} & set(table):
        no_unknown(table, set(GEODETIC_KEYS), "trajectory")
        trajectory = _expressions(table, GEODETIC_KEYS, "trajectory", params)
        return Expressions(trajectory.texts, GEODETIC_KEYS), None, None, {}
    no_unknown(table, {"x", "y", "z"}, "trajectory")
    return _expressions(table, ("x", "y", "z"), "trajectory", params), None, None, {}


def _attitude(table: Mapping, trajectory, track, log, params: Mapping[str, float], warnings: list[str]):
    """[attitude]: (mode, initial heading in rad, the attitude: expressions, samples, or None in tangent mode)."""
    # a log's attitude is what a replay is for: it is the default there
    mode = choice(table, "mode", "attitude", ATTITUDE_MODES, "file" if log is not None else "euler")
    heading = math.radians(number(table, "initial_heading_deg", "attitude", default=0.0,
                                  bound=MAX_ANGLE_DEG, unit=" deg"))
    if mode == "euler":
        no_unknown(table, {"mode", "roll", "pitch", "yaw", "reference"}, "attitude")
        if track is not None and (track.euler is not None or track.quat is not None) \
                and not {"roll", "pitch", "yaw"} & set(table):
            # Zero rotation while the file holds angles is what the user least expects: say how to use them.
            columns = "roll, pitch, yaw" if track.euler is not None else "qw, qx, qy, qz"
            raise SceneError(f"attitude: {track.source.name} has {columns} columns, but attitude.mode is "
                             "'euler' without expressions (zero rotation); set mode = \"file\" to use the "
                             "columns, or give roll/pitch/yaw expressions")
        return mode, heading, _expressions(table, ("roll", "pitch", "yaw"), "attitude", params)
    if mode == "tangent":
        no_unknown(table, {"mode", "initial_heading_deg"}, "attitude")
        return mode, heading, None
    return mode, heading, sources.sampled_attitude(table, trajectory, track, log, warnings)


def _time_span(head: Mapping, traj_table: Mapping, frame: str, rate: float, trajectory, attitude, log):
    """[scene] t0_s, duration_s: (frame, t0, duration, trajectory, attitude). Sampled input sets the time span
    unless the scene says otherwise; a flight log also sets the frame, and its series are cropped to the span."""
    if log is not None:
        if "frame" in head and frame != log.frame:
            raise SceneError(f"scene.frame: {log.source.name} is a {log.frame} log; this scene says {frame!r} "
                             f"(leave frame out, or set it to {log.frame!r})")
        frame = log.frame
        # both series must cover the replay; their spans may differ (separate topics)
        spans = [trajectory] + ([attitude] if isinstance(attitude, SampledData) else [])
        first, last = max(float(p.t[0]) for p in spans), min(float(p.t[-1]) for p in spans)
        t0 = number(head, "t0_s", "scene", default=first)
        duration = number(head, "duration_s", "scene", default=last - first, positive=True)
        if t0 < first or t0 + duration - 1.0 / rate > last + 1e-9:
            raise SceneError(f"scene.duration_s: {t0}..{t0 + duration} s reaches beyond the data "
                             f"({first}..{last} s, where both position and attitude are logged)")
        max_gap = number(traj_table, "max_gap_s", "trajectory", default=None, positive=True)
        trajectory, window_att = sources.log_window(log, trajectory, attitude if isinstance(attitude, SampledData)
                                                    else None, t0, duration, rate, max_gap)
        attitude = window_att if window_att is not None else attitude
    elif isinstance(trajectory, SampledData):
        span = float(trajectory.t[-1] - trajectory.t[0])
        t0 = number(head, "t0_s", "scene", default=float(trajectory.t[0]))
        duration = number(head, "duration_s", "scene", default=span, positive=True, bound=MAX_DURATION_S, unit=" s")
        if t0 < trajectory.t[0] or t0 + duration - 1.0 / rate > trajectory.t[-1] + 1e-9:
            raise SceneError(f"scene.duration_s: {t0}..{t0 + duration} s reaches beyond the data "
                             f"({trajectory.t[0]}..{trajectory.t[-1]} s in {trajectory.source})")
    else:
        t0 = number(head, "t0_s", "scene", default=0.0)
        duration = number(head, "duration_s", "scene", required=True, positive=True, bound=MAX_DURATION_S,
                          unit=" s")
    check_time_resolution(t0, duration, rate)
    return frame, t0, duration, trajectory, attitude


def _effects(raw: Mapping) -> frozenset[str]:
    from imu_emulator.effects import EFFECTS
    table = subtable(raw, "effects")
    for name, value in table.items():
        if name not in EFFECTS:
            raise SceneError(f"effects.{shown_key(name)}: unknown effect (known: {', '.join(EFFECTS)})")
        if not isinstance(value, bool):
            raise SceneError(f"effects.{name}: expected true or false, got {value!r}")
    return frozenset(name for name, on in table.items() if on)


def _streams(raw: Mapping) -> tuple[dict, ...]:
    """[[stream]] tables as given: imu_emulator.live checks them when it builds the streams (streams_from_tables)."""
    streams = raw.get("stream", [])
    if isinstance(streams, Mapping):
        streams = [streams]
    if not isinstance(streams, list) or not all(isinstance(s, Mapping) for s in streams):
        raise SceneError("stream: expected [[stream]] tables")
    return tuple(dict(s) for s in streams)
