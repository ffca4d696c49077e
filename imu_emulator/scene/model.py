"""Scene files (TOML) and scene dicts -> a frozen, validated Scene.

Validation happens once, here; everything downstream trusts the Scene. Errors name the key
("trajectory.x", "imu[1].lever_arm_m") and the reason.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from imu_emulator.numerics import expressions
from imu_emulator.errors import DataError, SceneError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

FRAMES = ("ENU", "NED", "ECEF", "ECI")
GRAVITY_MODELS = ("constant", "wgs84")
ATTITUDE_MODES = ("euler", "tangent", "file")
DEFAULT_DERIVATIVE = "spline5c"   # see README "What accuracy costs in time"
SEED_LIMIT = 2 ** 64      # [scene] seed: an integer 0 <= seed < 2**64


# Ranges of the scene's numbers; errors state the bound. Wide enough for any vehicle, narrow enough that no
# product the kernel forms (w x (w x r), R * g) overflows and no inf or nan reaches generated code.
RATE_RANGE_HZ = (1e-3, 1e7)
MAX_DURATION_S = 1e9           # 32 years
MAX_GRAVITY_MPS2 = 1e3
MAX_POSITION_M = 1e8           # positions, radii, centres, heights (ECEF is 6.4e6 m)
MAX_LEVER_ARM_M = 1e3
MAX_ANGLE_DEG = 1e4            # mounting angles, initial heading
MAX_TRACK_ANGLE_RAD = 1e9      # track angles may be unwrapped over long runs
MAX_FREQUENCY_HZ = 1e6         # circle shape
MAX_TIME_OFFSET_S = 1e6        # [[imu]] time_offset_s: a clock offset, not a second epoch
MAX_IMUS = 256                 # beyond kernel.INLINE_IMUS, an IMU is a kernel function: ~0.3 s CPU compile each
# Time stamps t0 + k/rate are float64: the spacing of floats at the latest stamp must stay below this
# fraction of the sample period, or stamps collide (t0_s = 1e16 s: spacing 2 s, every stamp equal).
TIME_RESOLUTION = 1e-3
_INF_HINT = " (TOML reads numbers beyond 1.8e308 as inf)"


@dataclass(frozen=True)
class Expressions:
    """Three expressions as validated text (x, y, z or roll, pitch, yaw)."""
    texts: tuple[str, str, str]
    keys: tuple[str, str, str] = ("x", "y", "z")   # ("lat_deg", "lon_deg", "height_m"): a geodetic trajectory


@dataclass(frozen=True)
class SampledData:
    """Sampled input: time stamps and columns, with the derivative method chosen for them."""
    t: np.ndarray = field(repr=False)
    values: np.ndarray = field(repr=False)   # (n, 3)
    derivative: str
    source: str                               # file path or "<array>", for messages
    kind: str = "euler"                       # attitude only: "euler" (roll, pitch, yaw) or "quaternion" (qw..qz)
    noise: float = 0.0                        # stated noise (m or rad, 1 sigma), for derivative = "smooth"
    geodetic: bool = False                    # trajectory only: ECEF metres converted from lat/lon/height columns


@dataclass(frozen=True)
class ImuSpec:
    """One IMU: its name (never in generated source) and the value of every parameter every effect declares
    (imu_emulator.effects), keyed by the parameter's path ("imu.lever_arm_m", "imu.gyro.noise_density"), in
    the parameter's unit; parameters not given hold their defaults, so the kernel key sees all of them."""
    name: str
    values: Mapping[str, Any] = field(default_factory=dict)
    # added to this IMU's time stamps in every output (its own clock's offset; not a kernel parameter: the
    # samples are taken at the scene's instants, only their stamps move)
    time_offset_s: float = 0.0

    @property
    def lever_arm_m(self) -> tuple[float, float, float]:
        return self.values["imu.lever_arm_m"]

    @property
    def mounting_rpy_deg(self) -> tuple[float, float, float]:
        return self.values["imu.mounting_rpy_deg"]


@dataclass(frozen=True)
class Scene:
    rate_hz: float
    duration_s: float
    frame: str
    gravity_mps2: float
    t0_s: float
    params: Mapping[str, float]
    trajectory: Expressions | SampledData       # position of S, navigation frame, metres
    attitude_mode: str                           # "euler", "tangent" or "file"
    attitude: Expressions | SampledData | None   # None in tangent mode
    initial_heading_rad: float
    imus: tuple[ImuSpec, ...]
    effects: frozenset[str]
    streams: tuple[dict, ...] = ()
    path: str | None = None
    warnings: tuple[str, ...] = ()
    seed: int = 0                                # root of every random stream (imu_emulator.numerics.counter_rng)
    origin: tuple[float, float, float] | None = None   # lat deg, lon deg, height m where ENU/NED is tangent
    gravity_model: str = "constant"              # "constant" (gravity_mps2) or "wgs84" (normal gravity)
    attitude_reference: str = "local_level"      # what roll, pitch, yaw are relative to (earth_scene.REFERENCES)

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def n_samples(self) -> int:
        """Samples at t0, t0 + dt, ... up to but excluding t0 + duration (so a looped periodic scene is seamless)."""
        return max(1, int(round(self.duration_s * self.rate_hz)))

    @property
    def imu_names(self) -> tuple[str, ...]:
        return tuple(imu.name for imu in self.imus)


# --- helpers that name the key in their errors ------------------------------------------------

def shown_key(key) -> str:
    """A key as an error message shows it: as written when it is a plain word, else repr'd, so that a key
    holding a newline cannot break the one-line message."""
    return key if isinstance(key, str) and key.isprintable() and key and key.strip() == key else repr(key)


def _table(raw: Mapping, key: str, where: str = "") -> dict:
    value = raw.get(key, {})
    if not isinstance(value, Mapping):
        raise SceneError(f"{where}{key}: expected a table, got {type(value).__name__}")
    return dict(value)


def _no_unknown(table: Mapping, allowed: set[str], where: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SceneError(f"{where}.{shown_key(unknown[0])}: unknown key (allowed: {', '.join(sorted(allowed))})")


def _number(table: Mapping, key: str, where: str, default=None, positive=False, required=False,
            bound: float | None = None, unit: str = "") -> float:
    if key not in table:
        if required:
            raise SceneError(f"{where}.{key}: missing (a number is required)")
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where}.{key}: expected a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(f"{where}.{key}: must be a finite number, got {value}{_INF_HINT}")
    if positive and value <= 0:
        raise SceneError(f"{where}.{key}: must be positive, got {value}")
    if bound is not None and abs(value) > bound:
        raise SceneError(f"{where}.{key}: {value!r} is out of range (|value| <= {bound:g}{unit})")
    return value


def _vector3(table: Mapping, key: str, where: str, bound: float, unit: str) -> tuple[float, float, float]:
    value = table.get(key, [0.0, 0.0, 0.0])
    if (not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 3
            or any(isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) for v in value)):
        raise SceneError(f"{where}.{key}: expected a list of three numbers, got {value!r}")
    if not all(math.isfinite(float(v)) for v in value):
        raise SceneError(f"{where}.{key}: values must be finite numbers (each |value| <= {bound:g}{unit}), "
                         f"got {value!r}{_INF_HINT}")
    if any(abs(float(v)) > bound for v in value):
        raise SceneError(f"{where}.{key}: {list(value)!r} is out of range (each |value| <= {bound:g}{unit})")
    return tuple(float(v) for v in value)


def _check_time_resolution(t0: float, duration: float, rate: float, key: str = "scene.t0_s") -> None:
    latest = max(abs(t0), abs(t0 + duration))
    dt = 1.0 / rate
    if float(np.spacing(latest)) > TIME_RESOLUTION * dt:
        # floats below 2**(e+1) are spaced 2**(e-52) apart at most
        limit = 2.0 ** (math.floor(52 + math.log2(TIME_RESOLUTION * dt)) + 1)
        raise SceneError(f"{key}: time stamps reach {latest:g} s, where float64 time stamps are "
                         f"{float(np.spacing(latest)):g} s apart, more than {TIME_RESOLUTION:g} of the sample "
                         f"period ({dt:g} s); at {rate:g} Hz keep |t0_s| + duration_s below {limit:g} s")


def _choice(table: Mapping, key: str, where: str, choices, default):
    value = table.get(key, default)
    if value not in choices:
        raise SceneError(f"{where}.{key}: {value!r} is not one of {', '.join(map(repr, choices))}")
    return value


# --- the parts of a scene --------------------------------------------------------------------

def _params(raw: Mapping) -> dict[str, float]:
    table = _table(raw, "params")
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


def _shape(table: Mapping, where: str, frame: str, gravity: float):
    """A built-in shape (imu_emulator.scene.shapes): the trajectory, the sampled track behind it (or None) and the
    [attitude] table the shape implies (empty if none)."""
    from imu_emulator.scene import shapes
    shape = shapes.build(table, where, frame, gravity)
    attitude = shape.attitude or {}
    if shape.track is None:
        return shape.trajectory, None, attitude
    return _sampled_from_track(shape.track, "position", DEFAULT_DERIVATIVE), shape.track, attitude


def _sampled_from_track(track, columns: str, derivative: str, noise: float = 0.0) -> SampledData:
    if columns == "attitude" and track.quat is not None:
        return SampledData(t=track.t, values=track.quat, derivative=derivative, source=str(track.source),
                           kind="quaternion", noise=noise)
    if columns == "position" and track.geodetic:
        from imu_emulator.scene.earth import sampled_geodetic
        return sampled_geodetic(track, derivative, noise)
    values = track.position if columns == "position" else track.euler
    bound, unit, names = ((MAX_POSITION_M, "m", "xyz") if columns == "position"
                          else (MAX_TRACK_ANGLE_RAD, "rad", ("roll", "pitch", "yaw")))
    big = np.abs(values) > bound
    if big.any():
        i, j = np.argwhere(big)[0]
        raise SceneError(f"trajectory.file: {track.source.name}: {track.row_label(int(i))}, column '{names[j]}': "
                         f"{float(values[i, j])!r} is out of range (|value| <= {bound:g} {unit})")
    return SampledData(t=track.t, values=values, derivative=derivative, source=str(track.source), noise=noise)


def _noise(table: Mapping, key: str, where: str, derivative: str, warnings: list[str]) -> float:
    """The stated noise of sampled data; the smoothing method needs it, the others ignore it (with a warning)."""
    noise = _number(table, key, where, default=None)
    if noise is None:
        if derivative == "smooth":
            raise SceneError(f"{where}.{key}: derivative 'smooth' needs the data's noise (1 sigma)")
        return 0.0
    if noise < 0:
        raise SceneError(f"{where}.{key}: must be >= 0, got {noise}")
    if derivative != "smooth":
        warnings.append(f"{where}.{key} is ignored: only derivative 'smooth' uses it (this one is {derivative!r})")
    return noise


LOG_KEYS = {"position_source", "attitude_source", "max_gap_s", "velocity_noise_mps"}


def _noise_from_velocity(log, derivative: str, warnings: list[str]) -> float:
    """position_noise_m = "velocity": the smoothing chosen from the log's own velocity (logs/velocity.py)."""
    from imu_emulator.scene.logs.velocity import noise_from_velocity
    where = "trajectory.position_noise_m"
    if derivative != "smooth":
        raise SceneError(f"{where}: \"velocity\" chooses the smoothing of derivative 'smooth' (this one is "
                         f"{derivative!r})")
    if log.velocity is None:
        raise SceneError(f"{where}: \"velocity\": {log.source.name} logs no velocity beside "
                         f"{log.position.name}; state the noise in metres")
    try:
        sigma, _ = noise_from_velocity(log.position, log.velocity, f"{where}: {log.source.name}")
    except DataError as exc:
        raise SceneError(str(exc)) from None
    warnings.append(f"{where}: {sigma:g} m, chosen from the logged velocity {log.velocity.name}")
    return sigma


def _joint_with_velocity(table: Mapping, log, derivative: str, noise: float, warnings: list[str]) -> np.ndarray:
    """velocity_noise_mps: the logged velocity as data in the position fit (logs/joint_fit.py); the fitted
    positions at the log's stamps replace the logged ones, which are then smooth (noise 0 from here on)."""
    from imu_emulator.scene.logs.joint_fit import choose_joint_fit
    where = "trajectory.velocity_noise_mps"
    sigma_v = _number(table, "velocity_noise_mps", "trajectory", positive=True)
    if derivative != "smooth" or noise <= 0:
        raise SceneError(f"{where}: needs derivative 'smooth' with position_noise_m > 0 (the fit weighs the two "
                         "noises)")
    if log.velocity is None:
        raise SceneError(f"{where}: {log.source.name} logs no velocity beside {log.position.name}")
    try:
        fit, spacing = choose_joint_fit(log.position, log.velocity, noise, sigma_v, f"{where}: {log.source.name}")
    except DataError as exc:
        raise SceneError(str(exc)) from None
    warnings.append(f"trajectory: positions fitted jointly with the logged velocity {log.velocity.name} "
                    f"(knot spacing {spacing:.3g} s, position noise {noise:g} m, velocity noise {sigma_v:g} m/s)")
    return fit.evaluate(log.position.t, 0)[0]


def _is_log(table: Mapping) -> bool:
    from imu_emulator.scene.logs import log_kind
    return isinstance(table.get("file"), str) and log_kind(table["file"]) is not None


def _load_log(table: Mapping, where: str, base_dir: Path):
    from imu_emulator.scene import logs
    path = Path(table["file"])
    full = path if path.is_absolute() else base_dir / path
    if not full.exists():
        raise SceneError(f"{where}.file: no such file: {full}")
    for key in ("position_source", "attitude_source"):
        if key in table and not isinstance(table[key], str):
            raise SceneError(f"{where}.{key}: expected a topic or message name, got {table[key]!r}")
    try:
        return logs.load_log(full, table.get("position_source"), table.get("attitude_source"))
    except DataError as exc:
        raise SceneError(f"{where}.file: {exc}") from None


def _log_window(motion, trajectory: SampledData, attitude: SampledData | None, t0: float, duration: float,
                rate: float, max_gap: float | None):
    """Crop the log's series to the replayed span (gaps outside it do not matter) and check them there."""
    from dataclasses import replace

    from imu_emulator.scene import logs
    t_hi = t0 + duration - 1.0 / rate
    parts = []
    for part, s in ((trajectory, motion.position), (attitude, motion.attitude)):
        if part is None:
            parts.append(None)
            continue
        try:
            # the part's own values: the positions may come from the joint fit with the velocity
            cropped = logs.window(replace(s, t=part.t, values=part.values), t0, t_hi, motion.source.name, max_gap)
        except DataError as exc:
            raise SceneError(f"trajectory.file: {exc}") from None
        parts.append(replace(part, t=cropped.t, values=cropped.values))
    return parts


def _check_derivative(name: str, where: str) -> str:
    from imu_emulator.numerics.derivatives import METHODS
    if not isinstance(name, str) or name not in METHODS:
        raise SceneError(f"{where}: unknown derivative method {name!r} (known: {', '.join(METHODS)})")
    return name


def _check_sample_count(part: SampledData, order: int, where: str) -> None:
    """Before any compile: enough samples for the derivative method (a 2-row track used to fail after 8 s)."""
    from imu_emulator.numerics.derivatives import min_samples
    need = min_samples(part.derivative, order)
    if part.t.size < need:
        raise SceneError(f"{where}: method {part.derivative!r} needs at least {need} samples for derivatives up "
                         f"to order {order} ({part.source}), got {part.t.size}")


def _load_track(table: Mapping, where: str, base_dir: Path):
    from imu_emulator.scene import trackfile
    if "file" in table:
        path = table["file"]
        if not isinstance(path, str):
            raise SceneError(f"{where}.file: expected a path string, got {path!r}")
        full = (base_dir / path) if not Path(path).is_absolute() else Path(path)
        if not full.exists():
            raise SceneError(f"{where}.file: no such file: {full}")
        try:
            return trackfile.load_track(full)
        except DataError as exc:
            raise SceneError(f"{where}.file: {exc}") from None
    # Arrays given in code (Python API): t, position[, euler]
    try:
        return trackfile.track_from_arrays(np.asarray(table["t"], float), np.asarray(table["position"], float),
                                           None if table.get("euler") is None else np.asarray(table["euler"], float),
                                           source="<arrays>",
                                           quat=None if table.get("quat") is None else np.asarray(table["quat"], float))
    except DataError as exc:
        raise SceneError(f"{where}: {exc}") from None


def _seed(head: Mapping) -> int:
    value = head.get("seed", 0)
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= int(value) < SEED_LIMIT:
        raise SceneError(f"scene.seed: expected an integer from 0 to 2**64 - 1, got {value!r}")
    return int(value)


def _effects(raw: Mapping) -> frozenset[str]:
    from imu_emulator.effects import EFFECTS
    table = _table(raw, "effects")
    for name, value in table.items():
        if name not in EFFECTS:
            raise SceneError(f"effects.{shown_key(name)}: unknown effect (known: {', '.join(EFFECTS)})")
        if not isinstance(value, bool):
            raise SceneError(f"effects.{name}: expected true or false, got {value!r}")
    return frozenset(name for name, on in table.items() if on)


#: plain-number limits of IMU parameters (the records' units), so no huge value reaches the kernel's literals
BOUNDS = {"imu.lever_arm_m": (MAX_LEVER_ARM_M, " m"), "imu.mounting_rpy_deg": (MAX_ANGLE_DEG, " deg")}


def _check_bound(value, bound, where: str) -> None:
    if bound is None:
        return
    limit, unit = bound
    flat = np.ravel(np.asarray(value, dtype=float))
    if np.any(np.abs(flat) > limit):
        raise SceneError(f"{where}: {value!r} is out of range (each |value| <= {limit:g}{unit})")


def _imu(table, where: str, effects: frozenset[str], taken: set[str], warnings: list[str]) -> ImuSpec:
    """An [[imu]] table: the keys and sub-tables ([imu.gyro], [imu.accel]) the effects declare, nothing else."""
    from imu_emulator.scene import units
    from imu_emulator.effects import all_params
    if not isinstance(table, Mapping):
        raise SceneError(f"{where}: expected a table")
    declared = all_params()
    subtables = {p.table.split(".", 1)[1] for _, p in declared if p.table != "imu"}
    _no_unknown(table, {"name", "model", "time_offset_s", *subtables,
                        *(k for _, p in declared if p.table == "imu" for k in (p.key, *p.aliases))}, where)
    name = table.get("name", where.replace("[", "").replace("]", ""))
    # names become CSV cells and labels on the wire: one printable line, no comma
    if not isinstance(name, str) or not name or "," in name or not name.isprintable() or len(name) > 64:
        raise SceneError(f"{where}.name: expected a printable name of 1 to 64 characters without commas, "
                         f"got {name!r}")
    if name in taken:
        raise SceneError(f"{where}.name: {name!r} is used twice")
    sources = {"imu": (table, where)}
    for sub in sorted(subtables):
        sources[f"imu.{sub}"] = (_table(table, sub, f"{where}."), f"{where}.{sub}")
        _no_unknown(sources[f"imu.{sub}"][0],
                    {k for _, p in declared if p.table == f"imu.{sub}" for k in (p.key, *p.aliases)}, f"{where}.{sub}")
    # a preset (model = "NAME") fills what the IMU's own keys leave open, without "ignored" warnings: it is a
    # datasheet, not a request for effects
    preset = {}
    if "model" in table:
        from imu_emulator.scene import presets
        for sub, keys in presets.load(table["model"], f"{where}.model").items():
            preset[f"imu.{sub}"] = (keys, f"{where}.model({table['model']}).{sub}")
            _no_unknown(keys, {k for _, p in declared if p.table == f"imu.{sub}" for k in (p.key, *p.aliases)},
                        preset[f"imu.{sub}"][1])
    values = {}
    for effect, param in declared:
        source, prefix = sources[param.table]
        given = [key for key in (param.key, *param.aliases) if key in source]
        if len(given) > 1:
            raise SceneError(f"{prefix}.{given[1]}: give either {given[0]} or {given[1]}, not both")
        default = units.parse(param.default, param.unit, param.shape, f"{prefix}.{param.key}")
        values[param.path] = default
        from_preset = [key for key in (param.key, *param.aliases) if key in preset.get(param.table, ({},))[0]]
        if not given and from_preset:
            preset_table, preset_prefix = preset[param.table]
            values[param.path] = units.parse(preset_table[from_preset[0]], param.unit, param.shape,
                                             f"{preset_prefix}.{from_preset[0]}")
        elif given:
            bound = BOUNDS.get(param.path)
            try:
                values[param.path] = units.parse(source[given[0]], param.unit, param.shape, f"{prefix}.{given[0]}")
            except SceneError as exc:
                if bound is None:
                    raise
                raise SceneError(f"{exc} (each |value| <= {bound[0]:g}{bound[1]})") from None
            _check_bound(values[param.path], bound, f"{prefix}.{given[0]}")
            # a value that changes nothing (the default, e.g. a zero lever arm) is not worth a warning
            if effect.name not in effects and values[param.path] != default:
                warnings.append(f"{prefix}.{given[0]} is ignored because effects.{effect.name} is not true")
    from imu_emulator.effects import EFFECTS
    for effect in EFFECTS.values():
        if effect.name in effects and effect.validate is not None:
            effect.validate(values, where)
    time_offset = _number(table, "time_offset_s", where, default=0.0, bound=MAX_TIME_OFFSET_S, unit=" s")
    return ImuSpec(name, values, time_offset)


def from_dict(raw: Mapping[str, Any], base_dir: str | Path = ".", path: str | None = None) -> Scene:
    """Validate a scene given as nested dicts (the parsed TOML, or built in code)."""
    if not isinstance(raw, Mapping):
        raise SceneError("scene: expected a table at the top level")
    _no_unknown(raw, {"scene", "params", "trajectory", "attitude", "imu", "effects", "stream"}, "scene file")
    base_dir = Path(base_dir)
    warnings: list[str] = []

    head = _table(raw, "scene")
    _no_unknown(head, {"rate_hz", "duration_s", "frame", "gravity_mps2", "t0_s", "name", "seed", "origin",
                       "gravity_model"}, "scene")
    seed = _seed(head)
    rate = _number(head, "rate_hz", "scene", required=True, positive=True)
    if not RATE_RANGE_HZ[0] <= rate <= RATE_RANGE_HZ[1]:
        raise SceneError(f"scene.rate_hz: {rate!r} is out of range ({RATE_RANGE_HZ[0]:g} to {RATE_RANGE_HZ[1]:g} Hz)")
    frame = _choice(head, "frame", "scene", FRAMES, "ENU")
    gravity = _number(head, "gravity_mps2", "scene", default=9.80665, bound=MAX_GRAVITY_MPS2, unit=" m/s^2")

    params = _params(raw)

    traj_table = _table(raw, "trajectory")
    if not traj_table:
        raise SceneError("trajectory: missing (give x/y/z expressions, a shape, or a file)")
    track = None
    log = None
    implied_attitude = {}
    if "shape" in traj_table:
        trajectory, track, implied_attitude = _shape(traj_table, "trajectory", frame, gravity)
    elif _is_log(traj_table):
        _no_unknown(traj_table, {"file", "derivative", "position_noise_m"} | LOG_KEYS, "trajectory")
        derivative = _check_derivative(traj_table.get("derivative", DEFAULT_DERIVATIVE), "trajectory.derivative")
        log = _load_log(traj_table, "trajectory", base_dir)
        if traj_table.get("position_noise_m") == "velocity":
            noise = _noise_from_velocity(log, derivative, warnings)
        else:
            noise = _noise(traj_table, "position_noise_m", "trajectory", derivative, warnings)
        values = log.position.values
        if "velocity_noise_mps" in traj_table:
            values, noise = _joint_with_velocity(traj_table, log, derivative, noise, warnings), 0.0
        trajectory = SampledData(t=log.position.t, values=values, derivative=derivative,
                                 source=f"{log.source}:{log.position.name}", noise=noise)
        warnings.extend(log.notes)
    elif "file" in traj_table or "t" in traj_table:
        _no_unknown(traj_table, {"file", "derivative", "t", "position", "euler", "quat", "position_noise_m"},
                    "trajectory")
        derivative = _check_derivative(traj_table.get("derivative", DEFAULT_DERIVATIVE), "trajectory.derivative")
        track = _load_track(traj_table, "trajectory", base_dir)
        trajectory = _sampled_from_track(track, "position", derivative,
                                         _noise(traj_table, "position_noise_m", "trajectory", derivative, warnings))
    elif {"lat_deg", "lon_deg", "height_m"} & set(traj_table):
        from imu_emulator.scene.earth import GEODETIC_KEYS
        _no_unknown(traj_table, set(GEODETIC_KEYS), "trajectory")
        trajectory = _expressions(traj_table, GEODETIC_KEYS, "trajectory", params)
        trajectory = Expressions(trajectory.texts, GEODETIC_KEYS)
    else:
        _no_unknown(traj_table, {"x", "y", "z"}, "trajectory")
        trajectory = _expressions(traj_table, ("x", "y", "z"), "trajectory", params)

    att_table = _table(raw, "attitude") or implied_attitude
    # a log's attitude is what a replay is for: it is the default there
    mode = _choice(att_table, "mode", "attitude", ATTITUDE_MODES, "file" if log is not None else "euler")
    heading = math.radians(_number(att_table, "initial_heading_deg", "attitude", default=0.0,
                                   bound=MAX_ANGLE_DEG, unit=" deg"))
    if mode == "euler":
        _no_unknown(att_table, {"mode", "roll", "pitch", "yaw", "reference"}, "attitude")
        if track is not None and (track.euler is not None or track.quat is not None) \
                and not {"roll", "pitch", "yaw"} & set(att_table):
            # Zero rotation while the file holds angles is what the user least expects: say how to use them.
            columns = "roll, pitch, yaw" if track.euler is not None else "qw, qx, qy, qz"
            raise SceneError(f"attitude: {track.source.name} has {columns} columns, but attitude.mode is "
                             "'euler' without expressions (zero rotation); set mode = \"file\" to use the "
                             "columns, or give roll/pitch/yaw expressions")
        attitude = _expressions(att_table, ("roll", "pitch", "yaw"), "attitude", params)
    elif mode == "tangent":
        _no_unknown(att_table, {"mode", "initial_heading_deg"}, "attitude")
        attitude = None
    else:
        _no_unknown(att_table, {"mode", "derivative", "attitude_noise_rad", "reference"}, "attitude")
        if log is None and (track is None or (track.euler is None and track.quat is None)):
            raise SceneError("attitude.mode: 'file' needs a trajectory file with roll, pitch, yaw or qw, qx, qy, "
                             "qz columns")
        derivative = _check_derivative(att_table.get("derivative", trajectory.derivative), "attitude.derivative")
        noise = _noise(att_table, "attitude_noise_rad", "attitude", derivative, warnings)
        if log is not None:
            attitude = SampledData(t=log.attitude.t, values=log.attitude.values, derivative=derivative,
                                   source=f"{log.source}:{log.attitude.name}", kind="quaternion", noise=noise)
        else:
            attitude = _sampled_from_track(track, "attitude", derivative, noise)

    for part, key, order in ((trajectory, "trajectory", 3 if mode == "tangent" else 2), (attitude, "attitude", 2)):
        if isinstance(part, SampledData):
            _check_sample_count(part, order, f"{key}.derivative")

    # Sampled input sets the time span unless the scene says otherwise.
    if log is not None:
        if "frame" in head and frame != log.frame:
            raise SceneError(f"scene.frame: {log.source.name} is a {log.frame} log; this scene says {frame!r} "
                             f"(leave frame out, or set it to {log.frame!r})")
        frame = log.frame
        # both series must cover the replay; their spans may differ (separate topics)
        spans = [trajectory] + ([attitude] if isinstance(attitude, SampledData) else [])
        first, last = max(float(p.t[0]) for p in spans), min(float(p.t[-1]) for p in spans)
        t0 = _number(head, "t0_s", "scene", default=first)
        duration = _number(head, "duration_s", "scene", default=last - first, positive=True)
        if t0 < first or t0 + duration - 1.0 / rate > last + 1e-9:
            raise SceneError(f"scene.duration_s: {t0}..{t0 + duration} s reaches beyond the data "
                             f"({first}..{last} s, where both position and attitude are logged)")
        max_gap = _number(traj_table, "max_gap_s", "trajectory", default=None, positive=True)
        trajectory, window_att = _log_window(log, trajectory, attitude if isinstance(attitude, SampledData)
                                             else None, t0, duration, rate, max_gap)
        attitude = window_att if window_att is not None else attitude
    elif isinstance(trajectory, SampledData):
        span = float(trajectory.t[-1] - trajectory.t[0])
        t0 = _number(head, "t0_s", "scene", default=float(trajectory.t[0]))
        duration = _number(head, "duration_s", "scene", default=span, positive=True, bound=MAX_DURATION_S, unit=" s")
        if t0 < trajectory.t[0] or t0 + duration - 1.0 / rate > trajectory.t[-1] + 1e-9:
            raise SceneError(f"scene.duration_s: {t0}..{t0 + duration} s reaches beyond the data "
                             f"({trajectory.t[0]}..{trajectory.t[-1]} s in {trajectory.source})")
    else:
        t0 = _number(head, "t0_s", "scene", default=0.0)
        duration = _number(head, "duration_s", "scene", required=True, positive=True, bound=MAX_DURATION_S,
                           unit=" s")
    _check_time_resolution(t0, duration, rate)

    effects = _effects(raw)
    from imu_emulator.scene.earth import earth_keys
    origin, gravity_model = earth_keys(head, frame, effects, mode, "shape" in traj_table,
                                       trajectory, warnings)
    from imu_emulator.scene.earth import attitude_reference
    reference = attitude_reference(att_table, frame, effects, trajectory, gravity_model)
    imu_list = raw.get("imu", [])
    if isinstance(imu_list, Mapping):
        imu_list = [imu_list]
    if not isinstance(imu_list, list) or not imu_list:
        raise SceneError("imu: at least one [[imu]] table is required")
    if len(imu_list) > MAX_IMUS:
        raise SceneError(f"imu: {len(imu_list)} [[imu]] tables; the limit is {MAX_IMUS} per scene")
    imus: list[ImuSpec] = []
    for i, table in enumerate(imu_list):
        imus.append(_imu(table, f"imu[{i}]", effects, {imu.name for imu in imus}, warnings))
        if imus[-1].time_offset_s:
            _check_time_resolution(t0 + imus[-1].time_offset_s, duration, rate, f"imu[{i}].time_offset_s")
    from imu_emulator.effects import EFFECTS
    for i, imu in enumerate(imus):   # effects' warnings that need the sample rate (vibration above Nyquist)
        warnings += [line for effect in EFFECTS.values() if effect.name in effects and effect.warn is not None
                     for line in effect.warn(imu.values, f"imu[{i}]", rate)]

    streams = raw.get("stream", [])
    if isinstance(streams, Mapping):
        streams = [streams]
    if not isinstance(streams, list) or not all(isinstance(s, Mapping) for s in streams):
        raise SceneError("stream: expected [[stream]] tables")

    return Scene(rate_hz=rate, duration_s=duration, frame=frame, gravity_mps2=gravity, t0_s=t0,
                 params=params, trajectory=trajectory, attitude_mode=mode, attitude=attitude,
                 initial_heading_rad=heading, imus=tuple(imus), effects=effects,
                 streams=tuple(dict(s) for s in streams), path=path, warnings=tuple(warnings), seed=seed,
                 origin=origin, gravity_model=gravity_model, attitude_reference=reference)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a TOML scene file."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise SceneError(f"{path}: cannot read scene file: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise SceneError(f"{path}: not UTF-8 text (byte {exc.start} is {exc.object[exc.start]:#04x}); "
                         "TOML scene files are UTF-8") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML: {exc}") from None
    try:
        return from_dict(raw, base_dir=path.parent, path=str(path))
    except SceneError as exc:
        raise SceneError(f"{path}: {exc}") from None
