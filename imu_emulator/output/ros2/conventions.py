"""Where a ROS 2 bag's axes, frame names and time stamps are decided, once, at the file's edge.

REP 103 (https://www.ros.org/reps/rep-0103.html): bodies are x forward, y left, z up (FLU) and the world is
ENU. REP 105 names the frames: a world-fixed frame ("world" here, ENU), the body "base_link", "earth" for
ECEF. The scene's frames are converted, whatever they are: an ENU scene's body is already FLU; a NED scene's
body is forward-right-down (FRD) and its world NED; ECEF and ECI scenes keep their world axes (named "earth"
and "eci") and have an FRD body. With `axes="scene"` nothing is converted and the frame ids say so: "<imu>_frd",
"base_link_frd", "world_ned" (REP 103's suffix convention for frames that are not its own).

Time: ROS tools treat a stamp of 0 as "unset" (tf2, message_filters), so stamps are on a real epoch: a sample
at scene time t is stamped start + t, start being `generate --start-time` (ISO 8601 or "now") or DEFAULT_START,
2024-01-01T00:00:00Z, a fixed instant so that the same scene and seed give the same bytes.
"""
from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np

#: the default instant of scene time 0: 2024-01-01T00:00:00Z, in Unix nanoseconds
DEFAULT_START = "2024-01-01T00:00:00Z"
DEFAULT_START_NS = 1_704_067_200 * 10**9
AXES = ("rep103", "scene")

_FRD_FROM_FLU = np.diag([1.0, -1.0, -1.0])             # its own inverse
_ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])   # its own inverse
_WORLD = {"ENU": "world", "NED": "world", "ECEF": "earth", "ECI": "eci"}


def parse_start_time(text: str) -> int:
    """`--start-time`: ISO 8601 ("2026-03-01T12:00:00Z", "2026-03-01T12:00:00.5+01:00"; no zone is UTC) or
    "now", as Unix nanoseconds. ValueError naming the text otherwise, or before 1970 or from 2038 on
    (builtin_interfaces/Time's sec is an int32)."""
    if text.strip().lower() == "now":
        from time import time_ns
        return time_ns()
    try:
        when = datetime.fromisoformat(text.strip().replace("Z", "+00:00").replace("z", "+00:00"))
    except ValueError:
        raise ValueError(f"{text!r} is not an ISO 8601 time (like {DEFAULT_START}) or 'now'") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=timezone.utc)
    delta = when - datetime(1970, 1, 1, tzinfo=timezone.utc)
    ns = (delta.days * 86_400 + delta.seconds) * 10**9 + delta.microseconds * 1000
    if not 0 <= ns < 2**31 * 10**9:
        raise ValueError(f"{text!r}: a ROS time stamp holds 1970-01-01 to 2038-01-19 (int32 seconds)")
    return ns


@dataclass(frozen=True)
class Axes:
    """How a scene's vectors become the bag's: v_bag = body @ v (body vectors, IMU and body frames) and
    p_bag = world @ p (navigation-frame vectors); frame ids to match."""
    body: np.ndarray            # (3, 3)
    world: np.ndarray           # (3, 3)
    world_id: str
    base_link: str
    suffix: str                 # appended to each IMU's frame id

    def __post_init__(self):
        object.__setattr__(self, "_quaternion_map", _ros_order(self.world, self.body).T.copy())

    def body_vectors(self, v: np.ndarray) -> np.ndarray:
        """(..., 3) scene body (or sensor) vectors in the bag's axes."""
        return turn(self.body, v)

    def world_vectors(self, v: np.ndarray) -> np.ndarray:
        """(..., 3) navigation-frame vectors in the bag's world axes."""
        return turn(self.world, v)

    def imu_frame(self, token: str) -> str:
        return token + self.suffix

    def quaternions(self, q: np.ndarray) -> np.ndarray:
        """(n, 4) scalar-first attitudes (scene body or sensor -> navigation) -> (n, 4) x, y, z, w of the bag's
        body -> the bag's world: q_world (x) q (x) q_body^-1 as one 4x4 matrix (both factors are constant).
        q and -q are one attitude; the bag gets the one with w >= 0, so the same motion written as an ENU or a NED
        scene gives the same message (the frame change's quaternions would otherwise flip the sign of one)."""
        out = q @ self._quaternion_map
        return np.where(out[..., 3:] < 0, -out, out)

    def rotation(self, matrix: np.ndarray) -> np.ndarray:
        """A rotation between two scene-body frames (mounting: sensor -> body) in the bag's body axes."""
        return self.body @ matrix @ self.body.T


def turn(matrix: np.ndarray, v: np.ndarray) -> np.ndarray:
    """matrix @ v for a signed permutation (every frame change here is one), by picking and negating components:
    exact, signed zeros included (a product sums +0 terms in and turns -0 into +0), and cheaper than a product."""
    columns = np.abs(matrix).argmax(axis=1)
    signs = matrix[np.arange(3), columns]
    if np.array_equal(columns, [0, 1, 2]) and (signs == 1).all():
        return v
    return np.asarray(v)[..., columns] * signs


def axes_for(frame: str | None, axes: str = "rep103") -> Axes:
    """frame: the scene's ("ENU", "NED", "ECEF", "ECI"; None, as for replayed logs, is ENU)."""
    frame = frame or "ENU"
    body_frd = frame != "ENU"
    if axes == "scene":
        return Axes(np.eye(3), np.eye(3), _WORLD[frame] + ("_ned" if frame == "NED" else ""),
                    "base_link_frd" if body_frd else "base_link", "_frd" if body_frd else "")
    return Axes(_FRD_FROM_FLU if body_frd else np.eye(3), _ENU_FROM_NED if frame == "NED" else np.eye(3),
                _WORLD[frame], "base_link", "")


def _quaternion(matrix: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of one rotation matrix (Shepperd's method: the largest of the four
    candidates' squares, so no division by a small number)."""
    m = np.asarray(matrix, float)
    squares = np.array([1 + m[0, 0] + m[1, 1] + m[2, 2], 1 + m[0, 0] - m[1, 1] - m[2, 2],
                        1 - m[0, 0] + m[1, 1] - m[2, 2], 1 - m[0, 0] - m[1, 1] + m[2, 2]])
    i = int(squares.argmax())
    r = np.sqrt(squares[i])
    differences = {0: (m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]),
                   1: (m[2, 1] - m[1, 2], m[0, 1] + m[1, 0], m[0, 2] + m[2, 0]),
                   2: (m[0, 2] - m[2, 0], m[0, 1] + m[1, 0], m[1, 2] + m[2, 1]),
                   3: (m[1, 0] - m[0, 1], m[0, 2] + m[2, 0], m[1, 2] + m[2, 1])}[i]
    q = np.empty(4)
    q[i] = r / 2
    q[[k for k in range(4) if k != i]] = np.array(differences) / (2 * r)
    return q


def _quaternion_matrices(q):
    """L(q) and R(q): q (x) p = L(q) p and p (x) q = R(q) p, scalar-first."""
    w, x, y, z = q
    left = np.array([[w, -x, -y, -z], [x, w, -z, y], [y, z, w, -x], [z, -y, x, w]])
    right = np.array([[w, -x, -y, -z], [x, w, z, -y], [y, -z, w, x], [z, y, -x, w]])
    return left, right


def _ros_order(world: np.ndarray, body: np.ndarray) -> np.ndarray:
    """The 4x4 map from a scene quaternion (w, x, y, z) to the bag's (x, y, z, w): q_world (x) q (x) q_body*,
    where body maps the scene body's vectors to the bag's (so the bag body -> scene body is body^T)."""
    left, _ = _quaternion_matrices(_quaternion(world))
    _, right = _quaternion_matrices(_quaternion(body.T))
    return np.roll(np.eye(4), -1, axis=0) @ left @ right
