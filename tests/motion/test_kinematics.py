"""The kernel against closed forms and an independent sympy derivation (tests/support/reference.py)."""

import numpy as np
import pytest
import sympy as sp
from scipy.spatial.transform import Rotation

from imu_emulator import load_scene, scene_from_dict
from imu_emulator.runtime.simulation import Simulation
from tests.support.reference import imu_functions, t
from tests.support.paths import EXAMPLES

G0 = 9.80665


def circle_scene(frame, rate, lever=(0.1, -0.2, 0.05), radius=5.0, freq=1.0):
    return scene_from_dict({
        "scene": {"rate_hz": rate, "duration_s": max(3.0 / rate, 0.05), "frame": frame},
        "trajectory": {"shape": "circle", "radius_m": radius, "frequency_hz": freq},
        "attitude": {"mode": "tangent"},
        "imu": [{"name": "a", "lever_arm_m": list(lever)}],
        "effects": {"gravity": True, "lever_arm": True},
    })


@pytest.mark.parametrize("frame", ["ENU", "NED"])
@pytest.mark.parametrize("rate", [10, 100, 1000, 10000])
def test_circle_closed_form_with_lever_arm(frame, rate):
    # Spec closed form: a_B = (0, rho w^2, 0), w_B = (0, 0, w), lever terms -w^2 (r_x, r_y, 0).
    # In NED the same parametrisation turns right, so +y (FRD right) is again towards the centre.
    rho, w, r = 5.0, 2 * np.pi, np.array([0.1, -0.2, 0.05])
    out = Simulation(circle_scene(frame, rate)).run()
    gz = G0 if frame == "ENU" else -G0
    expected_f = np.array([-w**2 * r[0], rho * w**2 - w**2 * r[1], gz])
    np.testing.assert_allclose(out.accel[0], np.broadcast_to(expected_f, out.accel[0].shape), atol=1e-9)
    np.testing.assert_allclose(out.gyro[0], np.broadcast_to([0, 0, w], out.gyro[0].shape), atol=1e-12)


def _sym(text, f=1.0):
    return sp.sympify(text, locals={"t": t, "f": sp.Float(f), "pi": sp.pi})


ORIGINAL_EXAMPLES = {
    "helix.toml": (["0.8*5*cos(2*pi*f*t)", "0.8*5*sin(2*pi*f*t)", "0.3*5*cos(2*pi*f*t)"], None),
    "loop_third_harmonic.toml": (["0.8*cos(2*pi*f*t)", "0.8*sin(2*pi*f*t)", "0.3*cos(2*pi*3*f*t)"], ["0", "0", "0"]),
    "orientation_only.toml": (["0", "0", "0"], ["0", "0", "0.3*cos(2*pi*f*t)"]),
    "symbolic_orientation.toml": (["0", "0", "0"],
                                  ["0.8*cos(2*pi*f*t)", "0.8*sin(2*pi*f*t)", "0.3*cos(2*pi*f*t)"]),
}


@pytest.mark.parametrize("name", sorted(ORIGINAL_EXAMPLES))
def test_original_examples_match_independent_sympy_derivation(name):
    position, euler = ORIGINAL_EXAMPLES[name]
    scene = load_scene(EXAMPLES / name)
    reference = imu_functions([_sym(e) for e in position], None if euler is None else [_sym(e) for e in euler],
                              lever=scene.imus[0].lever_arm_m)
    out = Simulation(scene).run()
    k = np.random.default_rng(7).choice(scene.n_samples, size=25, replace=False)
    acc, gyro = reference(out.t_s[k])
    np.testing.assert_allclose(out.accel[0, k], acc, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(out.gyro[0, k], gyro, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("frame, expected_z", [("ENU", G0), ("NED", -G0)])
def test_at_rest_level_specific_force_is_minus_g(frame, expected_z):
    scene = scene_from_dict({"scene": {"rate_hz": 100, "duration_s": 0.1, "frame": frame},
                             "trajectory": {"shape": "static", "position_m": [1.0, 2.0, 3.0]},
                             "imu": [{"name": "a"}], "effects": {"gravity": True}})
    out = Simulation(scene).run()
    np.testing.assert_array_equal(out.accel[0], np.broadcast_to([0, 0, expected_z], out.accel[0].shape))
    np.testing.assert_array_equal(out.gyro[0], 0.0)


def test_gravity_off_means_no_gravity():
    scene = scene_from_dict({"scene": {"rate_hz": 100, "duration_s": 0.1},
                             "trajectory": {"shape": "static"}, "imu": [{"name": "a"}]})
    np.testing.assert_array_equal(Simulation(scene).run().accel, 0.0)


def test_enu_and_ned_scenes_of_one_motion_relate_by_the_axis_change():
    # ENU (x east, y north, z up; body FLU) -> NED (x north, y east, z down; body FRD).
    enu = load_scene(EXAMPLES / "helix.toml")
    rx, ry, rz = enu.imus[0].lever_arm_m
    ned = scene_from_dict({
        "scene": {"rate_hz": 200, "duration_s": 5.0, "frame": "NED"},
        "trajectory": {"x": "0.8*5*sin(2*pi*t)", "y": "0.8*5*cos(2*pi*t)", "z": "-0.3*5*cos(2*pi*t)"},
        "attitude": {"mode": "tangent"},
        "imu": [{"name": "a", "lever_arm_m": [rx, -ry, -rz]}],
        "effects": {"gravity": True, "lever_arm": True},
    })
    a, b = Simulation(enu).run(), Simulation(ned).run()
    flu_to_frd = np.array([1.0, -1.0, -1.0])
    np.testing.assert_allclose(b.accel[0], a.accel[0] * flu_to_frd, atol=1e-9)
    np.testing.assert_allclose(b.gyro[0], a.gyro[0] * flu_to_frd, atol=1e-9)


def test_tangent_climb_pitch_sign_enu_and_ned():
    # The spec: a climb gives pitch < 0 in ENU (FLU body) and pitch > 0 in NED (FRD, nose-up positive).
    def climb(frame, z):
        return scene_from_dict({"scene": {"rate_hz": 10, "duration_s": 1.0, "frame": frame},
                                "trajectory": {"x": "t", "y": "0", "z": z}, "attitude": {"mode": "tangent"},
                                "imu": [{"name": "a"}]})
    enu = Simulation(climb("ENU", "t"), truth=True).run().truth["euler"]
    ned = Simulation(climb("NED", "-t"), truth=True).run().truth["euler"]
    np.testing.assert_allclose(enu[:, 1], -np.pi / 4, atol=1e-12)
    np.testing.assert_allclose(ned[:, 1], np.pi / 4, atol=1e-12)


def test_mounting_rotation_and_lever_arm_per_imu():
    scene = load_scene(EXAMPLES / "two_imus.toml")
    out = Simulation(scene).run()
    imu1 = scene.imus[1]
    # Reference: body-frame output at imu1's lever arm (no mounting), rotated with scipy's Rotation.
    bare = scene_from_dict({
        "scene": {"rate_hz": scene.rate_hz, "duration_s": scene.duration_s, "frame": scene.frame},
        "trajectory": {"shape": "circle", "radius_m": 20.0, "frequency_hz": 0.1, "height_m": -50.0},
        "attitude": {"mode": "tangent"}, "imu": [{"name": "b", "lever_arm_m": list(imu1.lever_arm_m)}],
        "effects": {"gravity": True, "lever_arm": True}})
    body = Simulation(bare).run()
    roll, pitch, yaw = np.radians(imu1.mounting_rpy_deg)
    M = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()     # sensor -> body
    np.testing.assert_allclose(out.accel[1], body.accel[0] @ M, atol=1e-9)
    np.testing.assert_allclose(out.gyro[1], body.gyro[0] @ M, atol=1e-12)
    # Attitude output: sensor -> nav = body -> nav composed with the mounting
    q_expected = (Rotation.from_quat(body.quat[0][:, [1, 2, 3, 0]]) * Rotation.from_matrix(M)).as_quat()
    q = out.quat[1][:, [1, 2, 3, 0]]
    np.testing.assert_allclose(np.abs(np.sum(q * q_expected, axis=1)), 1.0, atol=1e-12)


def test_time_far_from_zero_gives_the_same_samples():
    helix = load_scene(EXAMPLES / "helix.toml")
    base = {"scene": {"rate_hz": 200, "duration_s": 2.0},
            "trajectory": {"x": "0.8*5*cos(2*pi*t)", "y": "0.8*5*sin(2*pi*t)", "z": "0.3*5*cos(2*pi*t)"},
            "attitude": {"mode": "tangent"}, "imu": [{"name": "a", "lever_arm_m": list(helix.imus[0].lever_arm_m)}],
            "effects": {"gravity": True, "lever_arm": True}}
    near = Simulation(scene_from_dict(base)).run()
    base["scene"]["t0_s"] = 1e7          # a whole number of periods later
    far = Simulation(scene_from_dict(base)).run()
    scale = np.abs(near.accel).max()
    assert np.abs(far.accel - near.accel).max() <= 1e-9 * scale
    assert np.abs(far.gyro - near.gyro).max() <= 1e-9 * np.abs(near.gyro).max()


def test_tangent_attitude_standing_still_holds_heading_and_stays_finite():
    # x = t^3: v = 0 at t = 0 (start from rest); then along +x. Initial heading 30 deg is held while still.
    scene = scene_from_dict({"scene": {"rate_hz": 100, "duration_s": 0.5, "t0_s": -0.1},
                             "trajectory": {"x": "t**3", "y": "0", "z": "0"},
                             "attitude": {"mode": "tangent", "initial_heading_deg": 30.0},
                             "imu": [{"name": "a", "lever_arm_m": [0.1, 0.1, 0]}],
                             "effects": {"gravity": True, "lever_arm": True}})
    out = Simulation(scene, truth=True).run()
    assert np.isfinite(out.accel).all() and np.isfinite(out.gyro).all()
    yaw = out.truth["euler"][:, 2]
    still = np.isclose(out.t_s, 0.0, atol=1e-12)
    assert still.sum() == 1
    # Before t=0 the body moves along +x (v = 3t^2 > 0), at t=0 it holds that heading (0), not NaN.
    np.testing.assert_allclose(yaw, 0.0, atol=1e-12)


def test_effects_that_are_off_are_absent_from_generated_code():
    from imu_emulator.codegen.generate import generate_source
    on = circle_scene("ENU", 100)
    off = scene_from_dict({"scene": {"rate_hz": 100, "duration_s": 1.0},
                           "trajectory": {"shape": "circle", "radius_m": 5.0, "frequency_hz": 1.0},
                           "attitude": {"mode": "tangent"}, "imu": [{"name": "a", "lever_arm_m": [0.1, 0, 0]}]})
    src_on, src_off = generate_source(on, False, False), generate_source(off, False, False)
    assert "fax +=" in src_on and "fnz = fnz +" in src_on
    assert "fax +=" not in src_off and "fnz = fnz" not in src_off


def test_block_partition_does_not_change_samples():
    sim = Simulation(load_scene(EXAMPLES / "helix.toml"))
    whole = sim.block(0, 600)
    parts = [sim.block(k0, 100) for k0 in range(0, 600, 100)]
    np.testing.assert_array_equal(whole.accel, np.concatenate([p.accel for p in parts], axis=1))


def _sampled_scene(rate_in, method, attitude_mode="euler"):
    """The original's loop example given as arrays sampled at rate_in, output at 1 kHz."""
    t = np.arange(0.0, 2.0 + 1e-12, 1.0 / rate_in)
    w = 2 * np.pi
    position = np.column_stack([0.8 * np.cos(w * t), 0.8 * np.sin(w * t), 0.3 * np.cos(3 * w * t)])
    euler = np.column_stack([0.2 * np.sin(w * t), 0.1 * np.cos(w * t), 0.3 * np.cos(w * t)])
    return scene_from_dict({
        "scene": {"rate_hz": 1000, "duration_s": 1.5, "t0_s": 0.25},
        "trajectory": {"t": t, "position": position, "euler": euler, "derivative": method},
        "attitude": {"mode": "file"},
        "imu": [{"name": "a", "lever_arm_m": [0.1, -0.1, 0.05]}],
        "effects": {"gravity": True, "lever_arm": True}})


def _symbolic_twin():
    return scene_from_dict({
        "scene": {"rate_hz": 1000, "duration_s": 1.5, "t0_s": 0.25},
        "trajectory": {"x": "0.8*cos(2*pi*t)", "y": "0.8*sin(2*pi*t)", "z": "0.3*cos(6*pi*t)"},
        "attitude": {"mode": "euler", "roll": "0.2*sin(2*pi*t)", "pitch": "0.1*cos(2*pi*t)",
                     "yaw": "0.3*cos(2*pi*t)"},
        "imu": [{"name": "a", "lever_arm_m": [0.1, -0.1, 0.05]}],
        "effects": {"gravity": True, "lever_arm": True}})


# Specific force needs 2nd derivatives of position and (through alpha) of the angles.
# Interior orders: gradient 2, central4 4, spline5 4 (degree-5 spline, 2nd derivative: 6 - 2).
@pytest.mark.parametrize("method, order", [("gradient", 2), ("central4", 4), ("spline5", 4)])
def test_sampled_path_error_falls_with_the_methods_order(method, order):
    truth = Simulation(_symbolic_twin()).run()
    interior = slice(100, -100)    # away from the data's ends (the study reports the ends separately)
    errors = []
    for rate_in in (100, 200, 400):
        out = Simulation(_sampled_scene(rate_in, method)).run()
        errors.append(np.abs(out.accel[0, interior] - truth.accel[0, interior]).max())
    slopes = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(slopes > order - 0.7), (method, errors, slopes)
