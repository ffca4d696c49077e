"""Sampled motion for the scene: trajectory files and arrays (imu_emulator.scene.trackfile), the sampled built-in
shapes, and flight logs (imu_emulator.scene.logs), each checked into SampledData with its derivative method
and stated noise; errors name the key, the file and the row."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from imu_emulator.errors import DataError, SceneError
from imu_emulator.scene.checks import no_unknown, number
from imu_emulator.scene.earth import MAX_ORIGIN_HEIGHT_M
from imu_emulator.scene.model import DEFAULT_DERIVATIVE, MAX_POSITION_M, MAX_TRACK_ANGLE_RAD, SampledData


def shape_trajectory(table: Mapping, where: str, frame: str, gravity: float):
    """A built-in shape (imu_emulator.scene.shapes): the trajectory, the sampled track behind it (or None) and the
    [attitude] table the shape implies (empty if none)."""
    from imu_emulator.scene import shapes
    shape = shapes.build(table, where, frame, gravity)
    attitude = shape.attitude or {}
    if shape.track is None:
        return shape.trajectory, None, attitude
    return _sampled_from_track(shape.track, "position", DEFAULT_DERIVATIVE), shape.track, attitude


def track_trajectory(table: Mapping, base_dir: Path, warnings: list[str]) -> tuple[SampledData, object]:
    """[trajectory] file = "track.csv" (or t, position[, euler | quat] arrays in code): the positions as samples,
    and the track (its attitude columns serve mode = "file")."""
    no_unknown(table, {"file", "derivative", "t", "position", "euler", "quat", "position_noise_m"}, "trajectory")
    derivative = _check_derivative(table.get("derivative", DEFAULT_DERIVATIVE), "trajectory.derivative")
    track = _load_track(table, "trajectory", base_dir)
    trajectory = _sampled_from_track(track, "position", derivative,
                                     _noise(table, "position_noise_m", "trajectory", derivative, warnings))
    return trajectory, track


def _sampled_from_track(track, columns: str, derivative: str, noise: float = 0.0) -> SampledData:
    if columns == "attitude" and track.quat is not None:
        return SampledData(t=track.t, values=track.quat, derivative=derivative, source=str(track.source),
                           kind="quaternion", noise=noise)
    if columns == "position" and track.geodetic:
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


def sampled_geodetic(track, derivative: str, noise: float):
    """A track's lat_deg, lon_deg, height_m columns as ECEF samples (WGS-84, imu_emulator.geo.frames): the
    derivatives are fitted in ECEF, where the motion is smooth across the antimeridian and the poles."""
    from imu_emulator.geo import frames
    lat, height = track.position[:, 0], track.position[:, 2]
    for column, values, bound in (("lat_deg", lat, 90.0), ("height_m", height, MAX_ORIGIN_HEIGHT_M)):
        bad = np.abs(values) > bound
        if bad.any():
            i = int(np.argmax(bad))
            raise SceneError(f"trajectory.file: {track.source.name}: {track.row_label(i)}, column '{column}': "
                             f"{float(values[i])!r} is out of range (|value| <= {bound:g})")
    ecef = frames.geodetic_to_ecef(lat, track.position[:, 1], height)
    return SampledData(t=track.t, values=np.ascontiguousarray(ecef), derivative=derivative,
                       source=str(track.source), noise=noise, geodetic=True)


def _noise(table: Mapping, key: str, where: str, derivative: str, warnings: list[str]) -> float:
    """The stated noise of sampled data; the smoothing method needs it, the others ignore it (with a warning)."""
    noise = number(table, key, where, default=None)
    if noise is None:
        if derivative == "smooth":
            raise SceneError(f"{where}.{key}: derivative 'smooth' needs the data's noise (1 sigma)")
        return 0.0
    if noise < 0:
        raise SceneError(f"{where}.{key}: must be >= 0, got {noise}")
    if derivative != "smooth":
        warnings.append(f"{where}.{key} is ignored: only derivative 'smooth' uses it (this one is {derivative!r})")
    return noise


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


def _check_derivative(name: str, where: str) -> str:
    from imu_emulator.numerics.derivatives import METHODS
    if not isinstance(name, str) or name not in METHODS:
        raise SceneError(f"{where}: unknown derivative method {name!r} (known: {', '.join(METHODS)})")
    return name


def check_sample_counts(trajectory, attitude, mode: str) -> None:
    """Before any compile: enough samples for each sampled part's derivative method (tangent attitude
    differentiates the trajectory once more)."""
    for part, key, order in ((trajectory, "trajectory", 3 if mode == "tangent" else 2), (attitude, "attitude", 2)):
        if isinstance(part, SampledData):
            _check_sample_count(part, order, f"{key}.derivative")


def _check_sample_count(part: SampledData, order: int, where: str) -> None:
    """Before any compile: enough samples for the derivative method (a 2-row track used to fail after 8 s)."""
    from imu_emulator.numerics.derivatives import min_samples
    need = min_samples(part.derivative, order)
    if part.t.size < need:
        raise SceneError(f"{where}: method {part.derivative!r} needs at least {need} samples for derivatives up "
                         f"to order {order} ({part.source}), got {part.t.size}")


def sampled_attitude(table: Mapping, trajectory: SampledData, track, log, warnings: list[str]) -> SampledData:
    """[attitude] mode = "file": the attitude columns of the trajectory's file, or the flight log's attitude."""
    no_unknown(table, {"mode", "derivative", "attitude_noise_rad", "reference"}, "attitude")
    if log is None and (track is None or (track.euler is None and track.quat is None)):
        raise SceneError("attitude.mode: 'file' needs a trajectory file with roll, pitch, yaw or qw, qx, qy, "
                         "qz columns")
    derivative = _check_derivative(table.get("derivative", trajectory.derivative), "attitude.derivative")
    noise = _noise(table, "attitude_noise_rad", "attitude", derivative, warnings)
    if log is not None:
        return SampledData(t=log.attitude.t, values=log.attitude.values, derivative=derivative,
                           source=f"{log.source}:{log.attitude.name}", kind="quaternion", noise=noise)
    return _sampled_from_track(track, "attitude", derivative, noise)


# --- flight logs (imu_emulator.scene.logs): replayed motion -----------------------------------------------

LOG_KEYS = {"position_source", "attitude_source", "max_gap_s", "velocity_noise_mps"}


def is_log(table: Mapping) -> bool:
    from imu_emulator.scene.logs import log_kind
    return isinstance(table.get("file"), str) and log_kind(table["file"]) is not None


def logged_trajectory(table: Mapping, base_dir: Path, warnings: list[str]) -> tuple[SampledData, object]:
    """[trajectory] file = a flight log: its positions as samples (smoothed, or fitted jointly with the logged
    velocity), and the log (its attitude, frame and time span serve the rest of the scene)."""
    no_unknown(table, {"file", "derivative", "position_noise_m"} | LOG_KEYS, "trajectory")
    derivative = _check_derivative(table.get("derivative", DEFAULT_DERIVATIVE), "trajectory.derivative")
    log = _load_log(table, "trajectory", base_dir)
    if table.get("position_noise_m") == "velocity":
        noise = _noise_from_velocity(log, derivative, warnings)
    else:
        noise = _noise(table, "position_noise_m", "trajectory", derivative, warnings)
    values = log.position.values
    if "velocity_noise_mps" in table:
        values, noise = _joint_with_velocity(table, log, derivative, noise, warnings), 0.0
    trajectory = SampledData(t=log.position.t, values=values, derivative=derivative,
                             source=f"{log.source}:{log.position.name}", noise=noise)
    warnings.extend(log.notes)
    return trajectory, log


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
    sigma_v = number(table, "velocity_noise_mps", "trajectory", positive=True)
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


def log_window(motion, trajectory: SampledData, attitude: SampledData | None, t0: float, duration: float,
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
