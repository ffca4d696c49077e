"""The scene's Earth keys: [scene] origin, gravity_model, and what the ECEF frame and the Earth effects need; and
whether the scene is on the Earth (model_on), which the motion, the effects (Scene.earth_model) and the outputs ask.

With the Earth model on, the motion computes the Earth's geometry and the navigation stage follows the Earth
(imu_emulator.motion.earth)."""
from __future__ import annotations

from typing import Mapping

from imu_emulator.errors import SceneError
from imu_emulator.scene.checks import choice, no_unknown, number, subtable

#: effects that switch the Earth model on when named (so do the ECEF and ECI frames, geodetic trajectories and
#: gravity_model = "wgs84" with effects.gravity)
EARTH_EFFECTS = ("earth_rate", "coriolis")
#: [scene] gravity_model: "constant" (gravity_mps2) or "wgs84" (normal gravity)
GRAVITY_MODELS = ("constant", "wgs84")

#: [attitude] reference: what roll, pitch, yaw (or a file's attitude) are relative to
REFERENCES = ("local_level", "ECEF", "ECI")

ORIGIN_KEYS = ("lat_deg", "lon_deg", "height_m")
GEODETIC_KEYS = ORIGIN_KEYS     # a geodetic trajectory's [trajectory] keys
MAX_ORIGIN_HEIGHT_M = 1e7      # beyond geostationary orbit is not a place to put a tangent frame


def position_frame(scene) -> str:
    """The frame of the kernel's px..pz: the scene's, except ECEF for ECI (rewritten) and geodetic
    trajectories (converted to ECEF, imu_emulator.motion.earth)."""
    geodetic = (getattr(scene.trajectory, "keys", ("x", "y", "z")) != ("x", "y", "z")
                or getattr(scene.trajectory, "geodetic", False))
    return "ECEF" if geodetic or scene.frame in ("ECEF", "ECI") else scene.frame


def model_on(scene) -> bool:
    """Whether the navigation stage follows the Earth (see imu_emulator.motion.earth's docstring)."""
    return (position_frame(scene) == "ECEF" or any(name in scene.effects for name in EARTH_EFFECTS)
            or ("gravity" in scene.effects and scene.gravity_model == "wgs84"))


def _origin(head: Mapping):
    if "origin" not in head:
        return None
    table = subtable(head, "origin", "scene.")
    no_unknown(table, set(ORIGIN_KEYS), "scene.origin")
    lat = number(table, "lat_deg", "scene.origin", required=True, bound=90.0, unit=" deg")
    lon = number(table, "lon_deg", "scene.origin", required=True, bound=360.0, unit=" deg")
    height = number(table, "height_m", "scene.origin", default=0.0, bound=MAX_ORIGIN_HEIGHT_M, unit=" m")
    return (lat, lon, height)


def earth_keys(head: Mapping, frame: str, effects: frozenset[str], attitude_mode: str, shape: bool,
               trajectory, warnings: list[str]):
    """(origin or None, gravity model), validated against the frame and the effects named."""
    origin = _origin(head)
    model = choice(head, "gravity_model", "scene", GRAVITY_MODELS, "constant")
    earth = [name for name in EARTH_EFFECTS if name in effects]
    if model == "wgs84":
        if "gravity" not in effects:
            warnings.append("scene.gravity_model is ignored because effects.gravity is not true")
        else:
            earth.append("gravity")
            if "gravity_mps2" in head:
                warnings.append("scene.gravity_mps2 is ignored: gravity_model = \"wgs84\" computes gravity")
    geodetic = getattr(trajectory, "keys", None) == GEODETIC_KEYS or getattr(trajectory, "geodetic", False)
    if geodetic:
        if frame == "ECI":
            raise SceneError("trajectory.lat_deg: a geodetic trajectory is fixed to the Earth; use frame = \"NED\", "
                             "\"ENU\" (the attitude's level axes) or \"ECEF\"")
        if origin is not None:
            warnings.append("scene.origin is ignored: the trajectory is geodetic")
        return None, model
    if frame in ("ECEF", "ECI"):
        if shape:
            raise SceneError(f"trajectory.shape: shapes are built in a local frame; with frame = \"{frame}\" give "
                             f"x, y, z expressions{' or a file' if frame == 'ECEF' else ''} in {frame} metres")
        if frame == "ECI":
            missing = [name for name in EARTH_EFFECTS if name not in effects]
            if missing:
                raise SceneError(f"effects.{missing[0]}: frame = \"ECI\" needs it (an inertial trajectory seen "
                                 "from the rotating Earth: name effects.earth_rate and effects.coriolis)")
        if origin is not None:
            warnings.append(f"scene.origin is ignored with frame = \"{frame}\" (positions are {frame} already)")
            origin = None
    if frame in ("ENU", "NED") and earth and origin is None:
        raise SceneError(f"scene.origin: effects.{earth[0]} needs the point where the {frame} frame is tangent to "
                         "the Earth (origin = { lat_deg = ..., lon_deg = ..., height_m = ... })")
    return origin, model


def attitude_reference(att_table: Mapping, frame: str, effects, trajectory, gravity_model: str) -> str:
    """[attitude] reference, validated: another frame than local level needs the Earth model (the attitude is
    converted to local level at the current position, imu_emulator.motion.earth.reference_lines)."""
    from types import SimpleNamespace

    reference = choice(att_table, "reference", "attitude", REFERENCES, "local_level")
    if reference != "local_level":
        scene = SimpleNamespace(frame=frame, effects=effects, trajectory=trajectory, gravity_model=gravity_model)
        if not model_on(scene):
            raise SceneError(f"attitude.reference: \"{reference}\" needs the Earth model (frame = \"ECEF\" or "
                             "\"ECI\", a geodetic trajectory, or effects.earth_rate / coriolis with an origin)")
    return reference
