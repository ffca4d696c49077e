"""Built-in motions, so a user need not write expressions: `[trajectory] shape = "..."`.

Shapes with a closed form (static, circle, helix, figure8, line, coordinated_turn) are written as expressions of t
and take the exact symbolic path (sympy derivatives, exact phase reduction). The racetrack and waypoints are
piecewise, which expressions cannot say: they are sampled densely from their exact definition and take the sampled
path (derivatives by the clamped quintic spline), like a trajectory file.

Every number reaches the expressions as the repr of a validated float.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from imu_emulator.errors import SceneError
from imu_emulator.scene.checks import choice, no_unknown, number
from imu_emulator.scene.checks import vector3 as bounded_vector3
from imu_emulator.scene.model import MAX_FREQUENCY_HZ, MAX_POSITION_M, SPEED_RANGE_MPS, Expressions

# Step of the dense sampling of piecewise shapes: fine enough that the quintic spline refitted to the samples
# follows the exact curve to ~1e-9 of its size between junctions.
_SAMPLE_STEP_S = 0.005
_MAX_SAMPLES = 2_000_000


@dataclass(frozen=True)
class Shape:
    """What a shape gives the scene: the trajectory as expressions or as a sampled track (then `track`, with
    `track.euler` when the shape also fixes the attitude), and an Euler attitude when the shape implies one."""
    trajectory: Expressions | None = None
    track: object | None = None           # imu_emulator.scene.trackfile.Track
    attitude: dict | None = None          # an [attitude] table the scene uses when it has none of its own


def _vector3(table, key, where):
    """A position-like triple within the scene's bounds (harden-input's MAX_POSITION_M)."""
    return bounded_vector3(table, key, where, MAX_POSITION_M, " m")


def _speed(table, where, required=True):
    """speed_mps within SPEED_RANGE_MPS: radii and durations divide by it (5e-324 m/s made a zero radius)."""
    v = number(table, "speed_mps", where, required=required, positive=True)
    low, high = SPEED_RANGE_MPS
    if not low <= v <= high:
        raise SceneError(f"{where}.speed_mps: {v!r} is out of range ({low:g} to {high:g} m/s)")
    return v


def _expr(*texts: str) -> Expressions:
    return Expressions(tuple(texts))


def _phase(frequency_hz: float, phase_deg: float) -> str:
    return f"(2*pi*{frequency_hz!r}*t + {math.radians(phase_deg)!r})"


def _static(table, where, frame, g):
    no_unknown(table, {"shape", "position_m"}, where)
    x, y, z = _vector3(table, "position_m", where)
    return Shape(_expr(repr(x), repr(y), repr(z)))


def _circle(table, where, frame, g):
    """x = cx + r cos 2πft, y = cy + r sin 2πft, z = cz + h (f < 0 turns the other way)."""
    no_unknown(table, {"shape", "radius_m", "frequency_hz", "height_m", "center_m"}, where)
    r = number(table, "radius_m", where, required=True, positive=True, bound=MAX_POSITION_M, unit=" m")
    f = number(table, "frequency_hz", where, required=True, bound=MAX_FREQUENCY_HZ, unit=" Hz")
    h = number(table, "height_m", where, default=0.0, bound=MAX_POSITION_M, unit=" m")
    cx, cy, cz = _vector3(table, "center_m", where)
    return Shape(_expr(f"{cx!r} + {r!r}*cos(2*pi*{f!r}*t)", f"{cy!r} + {r!r}*sin(2*pi*{f!r}*t)", repr(cz + h)))


def _helix(table, where, frame, g):
    """A circle climbing at a constant rate: z = cz + climb·t."""
    no_unknown(table, {"shape", "radius_m", "frequency_hz", "climb_mps", "center_m"}, where)
    r = number(table, "radius_m", where, required=True, positive=True)
    f = number(table, "frequency_hz", where, required=True)
    climb = number(table, "climb_mps", where, required=True)
    cx, cy, cz = _vector3(table, "center_m", where)
    return Shape(_expr(f"{cx!r} + {r!r}*cos(2*pi*{f!r}*t)", f"{cy!r} + {r!r}*sin(2*pi*{f!r}*t)",
                       f"{cz!r} + {climb!r}*t"))


def _figure8(table, where, frame, g):
    """Lemniscate of Gerono: x = cx + (L/2) sin 2πft, y = cy + (W/2) sin 4πft; one eight per 1/f seconds."""
    no_unknown(table, {"shape", "length_m", "width_m", "frequency_hz", "height_m", "center_m"}, where)
    length = number(table, "length_m", where, required=True, positive=True)
    width = number(table, "width_m", where, required=True, positive=True)
    f = number(table, "frequency_hz", where, required=True, positive=True)
    h = number(table, "height_m", where, default=0.0)
    cx, cy, cz = _vector3(table, "center_m", where)
    return Shape(_expr(f"{cx!r} + {length / 2!r}*sin(2*pi*{f!r}*t)", f"{cy!r} + {width / 2!r}*sin(4*pi*{f!r}*t)",
                       repr(cz + h)))


def _line(table, where, frame, g):
    """p = start + v·t + a·t²/2."""
    no_unknown(table, {"shape", "start_m", "velocity_mps", "acceleration_mps2"}, where)
    p0 = _vector3(table, "start_m", where)
    v = _vector3(table, "velocity_mps", where)
    a = _vector3(table, "acceleration_mps2", where)
    if not any(v) and not any(a):
        raise SceneError(f"{where}.velocity_mps: a line needs a velocity or an acceleration (use shape = 'static')")
    return Shape(_expr(*(f"{p!r} + {vi!r}*t + {ai / 2!r}*t**2" for p, vi, ai in zip(p0, v, a))))


def _coordinated_turn(table, where, frame, g):
    """A level circle at constant speed, banked so that the specific force has no lateral component.

    bank_deg > 0 is a right turn (right wing down), < 0 a left turn, in either frame. The radius follows:
    r = v² / (g tan|bank|). With a_y the centripetal acceleration along the level body y axis, the roll that
    zeroes the lateral specific force is tan(roll) = -a_y / f_z with f_z = +g (ENU) or -g (NED).
    """
    no_unknown(table, {"shape", "speed_mps", "bank_deg", "height_m", "center_m", "initial_heading_deg"}, where)
    v = _speed(table, where)
    bank = number(table, "bank_deg", where, required=True)
    if not 0 < abs(bank) < 89:
        raise SceneError(f"{where}.bank_deg: must be non-zero and within ±89°, got {bank}")
    h = number(table, "height_m", where, default=0.0)
    heading = math.radians(number(table, "initial_heading_deg", where, default=0.0))
    cx, cy, cz = _vector3(table, "center_m", where)
    r = v * v / (g * math.tan(math.radians(abs(bank))))
    if not 0 < r <= MAX_POSITION_M:
        raise SceneError(f"{where}: speed_mps = {v!r} at bank_deg = {bank!r} makes a turn radius of {r:g} m, "
                         f"outside (0, {MAX_POSITION_M:g}] m")
    right = bank > 0
    # Body y is +90° from x in the navigation x-y plane in both frames (left in ENU, right in NED), so a turn
    # towards +y (counterclockwise in x-y, rate w > 0) is a left turn in ENU and a right turn in NED.
    w = (v / r) * (1.0 if right == (frame == "NED") else -1.0)
    # position angle theta = heading -+ 90° (the centre lies on the turn's side of the initial heading)
    theta0 = heading - math.copysign(math.pi / 2, w)
    a_y = r * w * abs(w)
    roll = math.atan(a_y / g) if frame == "NED" else -math.atan(a_y / g)
    theta = f"({w!r}*t + {theta0!r})"
    return Shape(_expr(f"{cx!r} + {r!r}*cos{theta}", f"{cy!r} + {r!r}*sin{theta}", repr(cz + h)),
                 attitude={"mode": "euler", "roll": repr(roll), "pitch": "0", "yaw": f"{w!r}*t + {heading!r}"})


def _racetrack(table, where, frame, g):
    """Two straights of length L joined by half circles of radius r, driven at constant speed, counterclockwise in
    the x-y plane, starting at the beginning of the first straight (x = cx - L/2, y = cy - r, heading +x).
    The curvature steps at the four junctions (as a car's would without transition curves); the spline through the
    dense samples spreads each step of acceleration over a few sample steps."""
    no_unknown(table, {"shape", "straight_m", "radius_m", "speed_mps", "laps", "height_m", "center_m"}, where)
    length = number(table, "straight_m", where, required=True, positive=True)
    r = number(table, "radius_m", where, required=True, positive=True)
    v = _speed(table, where)
    laps = number(table, "laps", where, default=1.0, positive=True)
    h = number(table, "height_m", where, default=0.0)
    cx, cy, cz = _vector3(table, "center_m", where)
    lap = 2 * length + 2 * math.pi * r
    t = _sample_times(laps * lap / v, where)
    s = np.mod(v * t, lap)
    pos = np.empty((len(t), 3))
    pos[:, 2] = cz + h
    turn = math.pi * r
    bounds = np.cumsum([length, turn, length])
    parts = (s < bounds[0], (s >= bounds[0]) & (s < bounds[1]), (s >= bounds[1]) & (s < bounds[2]), s >= bounds[2])
    u = [s, s - bounds[0], s - bounds[1], s - bounds[2]]
    pos[parts[0], 0], pos[parts[0], 1] = -length / 2 + u[0][parts[0]], -r
    ang = -math.pi / 2 + u[1][parts[1]] / r
    pos[parts[1], 0], pos[parts[1], 1] = length / 2 + r * np.cos(ang), r * np.sin(ang)
    pos[parts[2], 0], pos[parts[2], 1] = length / 2 - u[2][parts[2]], r
    ang = math.pi / 2 + u[3][parts[3]] / r
    pos[parts[3], 0], pos[parts[3], 1] = -length / 2 + r * np.cos(ang), r * np.sin(ang)
    pos[:, 0] += cx
    pos[:, 1] += cy
    return Shape(track=_track(t, pos, None, "racetrack"))


def _sample_times(span: float, where: str) -> np.ndarray:
    n = int(math.ceil(span / _SAMPLE_STEP_S)) + 1
    if n > _MAX_SAMPLES:
        raise SceneError(f"{where}: {span:g} s is too long for a sampled shape (at most "
                         f"{(_MAX_SAMPLES - 1) * _SAMPLE_STEP_S:g} s)")
    return np.linspace(0.0, span, n)


def _track(t, position, euler, name):
    from imu_emulator.scene import trackfile
    return trackfile.track_from_arrays(t, position, euler, source=f"<{name}>")


def _list_of_vectors(table: Mapping, key: str, where: str, required: bool) -> np.ndarray | None:
    if key not in table:
        if required:
            raise SceneError(f"{where}.{key}: missing (a list of [x, y, z] is required)")
        return None
    value = table[key]
    if not isinstance(value, (list, tuple)) or not value:
        raise SceneError(f"{where}.{key}: expected a list of [x, y, z] lists, got {value!r}")
    return np.array([_vector3({f"{key}[{i}]": item}, f"{key}[{i}]", where) for i, item in enumerate(value)])


def _waypoints(table, where, frame, g):
    """Positions (optionally roll, pitch, yaw) at given times, or at a constant speed along the chords; joined by a
    quintic spline (continuous up to the fourth derivative, so jerk and hence tangent angular acceleration are
    continuous). ends = "coast" (default): zero acceleration and jerk at both ends; "rest": zero velocity and
    acceleration. Attitudes are interpolated on the rotation group (scipy's RotationSpline: continuous angular rate
    and acceleration) and become the scene's attitude (as roll, pitch, yaw samples) unless it has an [attitude]."""
    from scipy.interpolate import make_interp_spline
    from scipy.spatial.transform import Rotation, RotationSpline

    no_unknown(table, {"shape", "positions_m", "times_s", "speed_mps", "attitudes_deg", "ends"}, where)
    points = _list_of_vectors(table, "positions_m", where, required=True)
    n = len(points)
    if n < 2:
        raise SceneError(f"{where}.positions_m: at least two waypoints are needed, got {n}")
    ends = choice(table, "ends", where, ("coast", "rest"), "coast")
    if ("times_s" in table) == ("speed_mps" in table):
        raise SceneError(f"{where}: give either times_s or speed_mps")
    if "times_s" in table:
        times = table["times_s"]
        if (not isinstance(times, list) or len(times) != n
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in times)):
            raise SceneError(f"{where}.times_s: expected {n} numbers (one per waypoint), got {times!r}")
        times = np.array(times, dtype=float)
        if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
            raise SceneError(f"{where}.times_s: must be finite and strictly increasing, got {times.tolist()}")
    else:
        speed = _speed(table, where)
        chords = np.linalg.norm(np.diff(points, axis=0), axis=1)
        if np.any(chords == 0):
            i = int(np.argmax(chords == 0)) + 1
            raise SceneError(f"{where}.positions_m[{i}]: repeats the previous waypoint; give times_s to stop there")
        times = np.concatenate([[0.0], np.cumsum(chords) / speed])
    euler_deg = _list_of_vectors(table, "attitudes_deg", where, required=False)
    if euler_deg is not None and len(euler_deg) != n:
        raise SceneError(f"{where}.attitudes_deg: expected {n} [roll, pitch, yaw] (one per waypoint), got {len(euler_deg)}")

    order = (3, 2) if ends == "coast" else (1, 2)
    bc = ([(order[0], np.zeros(3)), (order[1], np.zeros(3))],) * 2
    spline = make_interp_spline(times, points, k=5, bc_type=bc)
    t = _sample_times(times[-1] - times[0], where) + times[0]
    # The dense grid includes every waypoint's time, so the track passes exactly through each waypoint.
    t = np.union1d(t, times)
    t = t[np.concatenate([[True], np.diff(t) > 1e-9 * max(1.0, abs(times[-1]))])]
    euler = None
    if euler_deg is not None:
        rotations = Rotation.from_euler("ZYX", np.radians(euler_deg[:, ::-1]))
        yaw_pitch_roll = RotationSpline(times, rotations)(t).as_euler("ZYX")
        euler = yaw_pitch_roll[:, ::-1]
    return Shape(track=_track(t, spline(t), euler, "waypoints"), attitude=None if euler is None else {"mode": "file"})


BUILDERS = {
    "static": _static, "circle": _circle, "helix": _helix, "figure8": _figure8, "line": _line,
    "coordinated_turn": _coordinated_turn, "racetrack": _racetrack, "waypoints": _waypoints,
}
SHAPES = tuple(BUILDERS)


def build(table: Mapping, where: str, frame: str, gravity_mps2: float) -> Shape:
    shape = choice(table, "shape", where, SHAPES, None)
    return BUILDERS[shape](table, where, frame, gravity_mps2)
