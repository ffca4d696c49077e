"""Built-in shapes against their closed forms (derivatives written out by hand below, not by the code under test),
and waypoints: through their points at their times, derivatives continuous across them."""
import math

import numpy as np
import pytest

import imu_emulator as imu
from imu_emulator import SceneError

G = 9.80665


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def _body(R, v):
    """R^T v for stacks of R (n, 3, 3) and v (n, 3)."""
    return np.einsum("nji,nj->ni", R, v)


def _run(trajectory, rate=200, duration=4.0, attitude=None, frame="ENU"):
    raw = {"scene": {"rate_hz": rate, "frame": frame}, "trajectory": trajectory, "imu": [{"name": "a"}],
           "effects": {"gravity": True}}
    if duration is not None:
        raw["scene"]["duration_s"] = duration
    if attitude is not None:
        raw["attitude"] = attitude
    scene = imu.scene_from_dict(raw)
    return scene, imu.simulate(scene, truth=True)


def _tangent_closed_form(t, vel, acc):
    """Specific force and body rate for tangent attitude (roll 0) from hand-derived v(t), a(t), ENU."""
    yaw = np.arctan2(vel[:, 1], vel[:, 0])
    pitch = -np.arcsin(vel[:, 2] / np.linalg.norm(vel, axis=1))
    h2 = vel[:, 0] ** 2 + vel[:, 1] ** 2
    yaw_rate = (vel[:, 0] * acc[:, 1] - vel[:, 1] * acc[:, 0]) / h2
    R = _rz(yaw) @ _ry(pitch)
    f = _body(R, acc + np.array([0.0, 0.0, G]))
    return f, yaw, pitch, yaw_rate


def test_helix():
    r, f, climb = 3.0, 0.5, 1.0
    _, out = _run({"shape": "helix", "radius_m": r, "frequency_hz": f, "climb_mps": climb},
                  attitude={"mode": "tangent"})
    t, w = out.t_s, 2 * math.pi * f
    th = w * t
    pos = np.stack([r * np.cos(th), r * np.sin(th), climb * t], 1)
    vel = np.stack([-r * w * np.sin(th), r * w * np.cos(th), np.full_like(t, climb)], 1)
    acc = np.stack([-r * w * w * np.cos(th), -r * w * w * np.sin(th), 0 * t], 1)
    fb, _, pitch, yaw_rate = _tangent_closed_form(t, vel, acc)
    np.testing.assert_allclose(out.truth["position"], pos, atol=1e-9)
    np.testing.assert_allclose(out.accel[0], fb, atol=1e-9)
    # w_B = (-sin(pitch) yaw', 0, cos(pitch) yaw') for roll 0 and constant pitch
    gyro = np.stack([-np.sin(pitch) * yaw_rate, 0 * t, np.cos(pitch) * yaw_rate], 1)
    np.testing.assert_allclose(out.gyro[0], gyro, atol=1e-9)
    np.testing.assert_allclose(yaw_rate, w)


def test_figure8():
    length, width, f = 10.0, 4.0, 0.25
    _, out = _run({"shape": "figure8", "length_m": length, "width_m": width, "frequency_hz": f},
                  attitude={"mode": "tangent"})
    t, w = out.t_s, 2 * math.pi * f
    a, b = length / 2, width / 2
    pos = np.stack([a * np.sin(w * t), b * np.sin(2 * w * t), 0 * t], 1)
    vel = np.stack([a * w * np.cos(w * t), 2 * b * w * np.cos(2 * w * t), 0 * t], 1)
    acc = np.stack([-a * w * w * np.sin(w * t), -4 * b * w * w * np.sin(2 * w * t), 0 * t], 1)
    fb, _, _, yaw_rate = _tangent_closed_form(t, vel, acc)
    np.testing.assert_allclose(out.truth["position"], pos, atol=1e-9)
    np.testing.assert_allclose(out.accel[0], fb, atol=1e-8)
    np.testing.assert_allclose(out.gyro[0], np.stack([0 * t, 0 * t, yaw_rate], 1), atol=1e-9)
    # the eight crosses itself at the centre twice per period
    assert np.ptp(out.truth["position"][:, 0]) == pytest.approx(length, rel=1e-6)


def test_line_with_acceleration_along_it():
    v0, acc = np.array([1.0, 1.0, 0.5]), np.array([0.2, 0.2, 0.1])
    _, out = _run({"shape": "line", "start_m": [1, 2, 3], "velocity_mps": v0.tolist(),
                   "acceleration_mps2": acc.tolist()}, attitude={"mode": "tangent"})
    t = out.t_s
    np.testing.assert_allclose(out.truth["position"], [1, 2, 3] + np.outer(t, v0) + np.outer(t * t / 2, acc), atol=1e-9)
    fb, _, _, _ = _tangent_closed_form(t, np.tile(v0, (len(t), 1)), np.tile(acc, (len(t), 1)))
    np.testing.assert_allclose(out.accel[0], fb, atol=1e-9)
    np.testing.assert_allclose(out.gyro[0], 0, atol=1e-12)
    # along the body x axis: the acceleration's magnitude; the rest is gravity
    assert np.linalg.norm(out.accel[0] - _body(_rz(np.zeros(len(t))) @ _ry(np.full(len(t), -math.asin(0.5 / 1.5))),
                                               np.tile([0, 0, G], (len(t), 1))), axis=1) == pytest.approx(0.3)


@pytest.mark.parametrize("frame", ["ENU", "NED"])
@pytest.mark.parametrize("bank", [30.0, -45.0])
def test_coordinated_turn(frame, bank):
    """No lateral specific force; |f| = g / cos(bank); radius v²/(g tan|bank|); positive bank is a right turn with
    right wing down (roll > 0 in both frames: FLU and FRD both roll positive right-wing-down)."""
    v = 50.0
    _, out = _run({"shape": "coordinated_turn", "speed_mps": v, "bank_deg": bank, "center_m": [5, 6, 0]}, frame=frame)
    phi = math.radians(bank)
    up = 1.0 if frame == "ENU" else -1.0
    np.testing.assert_allclose(out.accel[0][:, :2], 0, atol=1e-9)
    np.testing.assert_allclose(out.accel[0][:, 2], up * G / math.cos(phi), rtol=1e-12)
    radius = np.hypot(out.truth["position"][:, 0] - 5, out.truth["position"][:, 1] - 6)
    np.testing.assert_allclose(radius, v * v / (G * math.tan(abs(phi))), rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(out.truth["velocity"], axis=1), v, rtol=1e-12)
    np.testing.assert_allclose(out.truth["euler"][:, 0], phi, atol=1e-12)
    # a right turn turns clockwise seen from above: yaw decreases in ENU (z up), increases in NED (z down)
    yaw_rate = G * math.tan(phi) / v * (1 if frame == "NED" else -1)
    np.testing.assert_allclose(np.unwrap(out.truth["euler"][:, 2]), out.truth["euler"][0, 2] + yaw_rate * out.t_s,
                               atol=1e-9)
    np.testing.assert_allclose(out.gyro[0], np.tile([0, yaw_rate * math.sin(phi), yaw_rate * math.cos(phi)],
                                                    (len(out.t_s), 1)), atol=1e-12)


def test_racetrack_straights_and_turns():
    straight, r, v = 20.0, 5.0, 5.0
    scene, out = _run({"shape": "racetrack", "straight_m": straight, "radius_m": r, "speed_mps": v},
                      duration=None, attitude={"mode": "tangent"})
    lap = 2 * straight + 2 * math.pi * r
    assert scene.duration_s == pytest.approx(lap / v)
    s = v * out.t_s
    legs = np.cumsum([0, straight, math.pi * r, straight, math.pi * r])
    for i in range(4):
        # the middle half of each leg, away from the curvature steps at the junctions
        inner = (s > legs[i] + 0.25 * (legs[i + 1] - legs[i])) & (s < legs[i + 1] - 0.25 * (legs[i + 1] - legs[i]))
        if i % 2 == 0:   # straight: level, unaccelerated
            np.testing.assert_allclose(out.accel[0][inner], np.tile([0, 0, G], (inner.sum(), 1)), atol=1e-6)
            np.testing.assert_allclose(out.gyro[0][inner], 0, atol=1e-6)
            np.testing.assert_allclose(out.truth["position"][inner, 1], -r if i == 0 else r, atol=1e-9)
        else:            # half circle to the left: centripetal v²/r towards +y body, yaw rate v/r
            np.testing.assert_allclose(out.accel[0][inner], np.tile([0, v * v / r, G], (inner.sum(), 1)), atol=1e-6)
            np.testing.assert_allclose(out.gyro[0][inner], np.tile([0, 0, v / r], (inner.sum(), 1)), atol=1e-6)
            centre = np.array([straight / 2 if i == 1 else -straight / 2, 0.0])
            np.testing.assert_allclose(np.linalg.norm(out.truth["position"][inner, :2] - centre, axis=1), r, atol=1e-9)


WAYPOINTS = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 10.0, 2.0], [0.0, 10.0, 0.0], [-5.0, 3.0, 1.0]]
TIMES = [0.0, 2.0, 4.0, 6.5, 9.0]


def test_waypoints_pass_through_their_points_at_their_times():
    _, out = _run({"shape": "waypoints", "positions_m": WAYPOINTS, "times_s": TIMES}, rate=400, duration=None,
                  attitude={"mode": "tangent"})
    for p, t in zip(WAYPOINTS[:-1], TIMES[:-1]):    # the last one is the scene's end, one step past the last sample
        k = int(round(t * 400))
        np.testing.assert_allclose(out.truth["position"][k], p, atol=1e-9)
    assert out.t_s[-1] == pytest.approx(TIMES[-1] - 1 / 400)


def _jumps_across(out, times, key):
    """Largest change of a truth quantity between the samples either side of each interior waypoint."""
    rate = 1 / (out.t_s[1] - out.t_s[0])
    return max(np.max(np.abs(out.truth[key][int(round(t * rate)) + 1] - out.truth[key][int(round(t * rate)) - 1]))
               for t in times[1:-1])


def test_waypoint_derivatives_are_continuous_across_waypoints():
    """A continuous quantity changes across a point by O(dt): at 8x the rate the change shrinks ~8x. A quantity
    that jumps there (acceleration of a cubic spline makes the body rate jump, its jerk the angular acceleration)
    would not shrink at all. Angular rate needs acceleration, angular acceleration needs jerk (tangent attitude)."""
    traj = {"shape": "waypoints", "positions_m": WAYPOINTS, "times_s": TIMES}
    coarse = _run(traj, rate=200, duration=None, attitude={"mode": "tangent"})[1]
    fine = _run(traj, rate=1600, duration=None, attitude={"mode": "tangent"})[1]
    for key in ("velocity", "omega_body", "alpha_body"):
        assert _jumps_across(fine, TIMES, key) < _jumps_across(coarse, TIMES, key) / 4, key


def test_waypoints_by_speed_with_attitudes_and_rest_at_the_ends():
    points = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 10.0, 2.0]]
    attitudes = [[0.0, 0.0, 0.0], [10.0, 0.0, 90.0], [0.0, 5.0, 180.0]]
    scene, out = _run({"shape": "waypoints", "positions_m": points, "speed_mps": 5.0, "attitudes_deg": attitudes,
                       "ends": "rest"}, rate=400, duration=None)
    assert scene.attitude_mode == "file"
    chords = [10.0, math.sqrt(104.0)]
    assert scene.duration_s == pytest.approx(sum(chords) / 5.0)
    np.testing.assert_allclose(out.truth["velocity"][0], 0, atol=1e-6)
    k = int(round(2.0 * 400))          # second waypoint at 10 m / 5 m/s
    np.testing.assert_allclose(out.truth["position"][k], points[1], atol=1e-9)
    np.testing.assert_allclose(out.truth["euler"][k], np.radians(attitudes[1]), atol=1e-9)
    np.testing.assert_allclose(out.truth["euler"][0], np.radians(attitudes[0]), atol=1e-9)


def test_two_waypoints_coasting_are_a_straight_line_at_constant_velocity():
    _, out = _run({"shape": "waypoints", "positions_m": [[0, 0, 0], [8, 6, 0]], "times_s": [0, 2]}, duration=None,
                  attitude={"mode": "tangent"})
    np.testing.assert_allclose(out.truth["velocity"], np.tile([4.0, 3.0, 0.0], (len(out.t_s), 1)), atol=1e-9)
    np.testing.assert_allclose(out.accel[0], np.tile([0, 0, G], (len(out.t_s), 1)), atol=1e-7)


@pytest.mark.parametrize("trajectory, message", [
    ({"shape": "spiral"}, "trajectory.shape: 'spiral' is not one of"),
    ({"shape": "helix", "radius_m": 1.0, "frequency_hz": 1.0}, "trajectory.climb_mps: missing"),
    ({"shape": "coordinated_turn", "speed_mps": 10.0, "bank_deg": 90.0}, "trajectory.bank_deg: must be non-zero"),
    ({"shape": "line", "start_m": [0, 0, 0]}, "trajectory.velocity_mps: a line needs"),
    ({"shape": "waypoints", "positions_m": [[0, 0, 0]], "times_s": [0]}, "at least two waypoints"),
    ({"shape": "waypoints", "positions_m": [[0, 0, 0], [1, 0, 0]]}, "give either times_s or speed_mps"),
    ({"shape": "waypoints", "positions_m": [[0, 0, 0], [1, 0, 0]], "times_s": [1, 1]}, "strictly increasing"),
    ({"shape": "waypoints", "positions_m": [[0, 0, 0], [1, 0]], "times_s": [0, 1]}, "positions_m[1]: expected a list of three"),
    ({"shape": "waypoints", "positions_m": [[0, 0, 0], [0, 0, 0]], "speed_mps": 1.0}, "positions_m[1]: repeats"),
    ({"shape": "racetrack", "straight_m": 1.0, "radius_m": 1.0, "speed_mps": 1.0, "lap": 2}, "trajectory.lap: unknown key"),
])
def test_bad_shapes_name_the_key(trajectory, message):
    with pytest.raises(SceneError) as info:
        imu.scene_from_dict({"scene": {"rate_hz": 100, "duration_s": 1.0}, "trajectory": trajectory,
                             "imu": [{"name": "a"}]})
    assert message in str(info.value)
