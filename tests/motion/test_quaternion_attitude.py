"""Attitude given as quaternions (qw, qx, qy, qz): rates come from the fitted quaternion curve on the rotation
group, never through Euler angles. Oracles: scipy's Rotation builds the quaternions (independently of
imu_emulator.geo.rotations), tests/support/reference.py (sympy, rates from R^T dR/dt) gives the exact IMU output."""
import numpy as np
import pytest
import sympy as sp
from scipy.spatial.transform import Rotation

from imu_emulator import scene_from_dict
from imu_emulator.errors import DataError, SceneError
from imu_emulator.geo.rotations import continuous_quaternions
from imu_emulator.runtime.simulation import Simulation
from imu_emulator.scene.trackfile import load_track
from tests.support.reference import imu_functions, t as T

LEVER = (0.1, -0.05, 0.2)
# pitch sweeps through +90 degrees at t = 1.25 s, where Euler-angle differentiation breaks down
EULER = ("0.8*sin(2*pi*0.7*t)", "pi/2*sin(2*pi*0.2*t)", "1.5*t + 0.4*cos(2*pi*0.5*t)")
POSITION = ("3*cos(2*pi*0.3*t)", "2*sin(2*pi*0.3*t)", "0.5*t")


def _lambdas(texts):
    exprs = [sp.sympify(e, locals={"t": T, "pi": sp.pi}) for e in texts]
    return exprs, [sp.lambdify(T, e, "numpy") for e in exprs]


def sampled_scene(rate_in, method="spline5c", flip_signs=True, rate_out=500.0, duration=2.5):
    t = np.arange(int(duration * rate_in) + 1) / rate_in
    _, fe = _lambdas(EULER)
    _, fp = _lambdas(POSITION)
    roll, pitch, yaw = (np.broadcast_to(f(t), t.shape) for f in fe)
    # scipy: intrinsic z-y-x = R = Rz(yaw) Ry(pitch) Rx(roll), body -> navigation; as_quat is (x, y, z, w)
    xyzw = Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, roll])).as_quat()
    quat = np.column_stack([xyzw[:, 3], xyzw[:, :3]])
    if flip_signs:          # logs flip signs freely; q and -q are the same attitude
        quat *= np.where(np.random.default_rng(3).random(t.size) < 0.5, -1.0, 1.0)[:, None]
    position = np.column_stack([np.broadcast_to(f(t), t.shape) for f in fp])
    return scene_from_dict({
        "scene": {"rate_hz": rate_out, "duration_s": duration - 0.02},
        "trajectory": {"t": t, "position": position, "quat": quat, "derivative": method},
        "attitude": {"mode": "file"},
        "imu": [{"name": "a", "lever_arm_m": list(LEVER)}],
        "effects": {"gravity": True, "lever_arm": True},
    })


def reference_output(times):
    ep, _ = _lambdas(POSITION)
    ee, _ = _lambdas(EULER)
    return imu_functions(ep, ee, lever=LEVER)(times)


@pytest.mark.parametrize("rate_in, tol_f, tol_w", [(50, 1.5e-4, 3e-6), (200, 1.5e-7, 3e-10)])
def test_sampled_quaternions_reproduce_the_symbolic_twin_through_90_degrees_pitch(rate_in, tol_f, tol_w):
    # tolerances: 3x the errors measured at these rates (50 Hz: 4.8e-5, 1.1e-6; 200 Hz: 5.2e-8, 1.0e-10,
    # where the accelerometer meets the float rounding of the sampled positions)
    scene = sampled_scene(rate_in)
    assert scene.attitude.kind == "quaternion"
    out = Simulation(scene, truth=True).run()
    acc, gyro = reference_output(out.t_s)
    assert np.abs(out.accel[0] - acc).max() < tol_f
    assert np.abs(out.gyro[0] - gyro).max() < tol_w
    # pitch really passes 90 degrees inside the run
    assert np.abs(out.truth["euler"][:, 1]).max() > np.radians(89.5)


def test_converges_at_the_spline_order():
    errors = []
    for rate_in in (50, 100):
        out = Simulation(sampled_scene(rate_in)).run()
        errors.append(np.abs(out.gyro[0] - reference_output(out.t_s)[1]).max())
    # spline5c: first derivative O(h^5); halving h divides the error by >= 32 (measured 530; accept >= 16)
    assert errors[0] / errors[1] > 16, errors


def test_sign_flips_change_nothing():
    a = Simulation(sampled_scene(200, flip_signs=False)).run()
    b = Simulation(sampled_scene(200, flip_signs=True)).run()
    np.testing.assert_allclose(b.gyro, a.gyro, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.accel, a.accel, rtol=0, atol=1e-11)


def test_attitude_at_the_samples_is_scipys():
    scene = sampled_scene(100, flip_signs=True, rate_out=100.0)
    out = Simulation(scene).run()
    t = np.arange(int(2.5 * 100) + 1) / 100
    _, fe = _lambdas(EULER)
    angles = np.column_stack([np.broadcast_to(f(t), t.shape) for f in fe])
    expected = Rotation.from_euler("ZYX", angles[:, ::-1])
    got = Rotation.from_quat(out.quat[0][:, [1, 2, 3, 0]])
    n = out.t_s.size
    assert (expected[:n].inv() * got).magnitude().max() < 1e-12


def test_continuous_quaternions_pick_one_sheet():
    q = Rotation.from_euler("z", np.linspace(0, 4 * np.pi, 200)[:, None]).as_quat()[:, [3, 0, 1, 2]]
    q[q[:, 0] < 0] *= -1                               # PX4 style: w >= 0 always, so signs jump at 180 deg
    c = continuous_quaternions(q * 3.0)
    assert np.all(np.einsum("ij,ij->i", c[1:], c[:-1]) > 0.99)
    np.testing.assert_allclose(np.linalg.norm(c, axis=1), 1.0, rtol=1e-15)
    assert (Rotation.from_quat(c[:, [1, 2, 3, 0]]).inv() * Rotation.from_quat(q[:, [1, 2, 3, 0]])).magnitude().max() < 1e-12


def test_csv_quaternion_columns(tmp_path):
    path = tmp_path / "q.csv"
    path.write_text("t,x,y,z,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n0.1,0,0,0,0,0,0,-1\n")
    track = load_track(path)
    np.testing.assert_array_equal(track.quat, [[1, 0, 0, 0], [0, 0, 0, -1]])
    assert track.euler is None


@pytest.mark.parametrize("header, row, match", [
    ("t,x,y,z,qw,qx,qy", "0,0,0,0,1,0,0", r"qw, qx, qy and qz come together: found qw, qx, qy but not qz"),
    ("t,x,y,z,roll,pitch,yaw,qw,qx,qy,qz", "0,0,0,0,0,0,0,1,0,0,0", r"either as roll, pitch, yaw or as qw"),
    ("t,x,y,z,qw,qx,qy,qz", "0,0,0,0,0,0,0,0", r"row 2: quaternion norm 0\.0 is not a rotation"),
    ("t,x,y,z,qw,qx,qy,qz", "0,0,0,0,1,nan,0,0", r"row 2, column 'qx': value nan is not finite"),
])
def test_csv_quaternion_errors(tmp_path, header, row, match):
    path = tmp_path / "q.csv"
    path.write_text(f"{header}\n{row}\n{row.replace('0', '1', 1)}\n")
    with pytest.raises(DataError, match=match):
        load_track(path)


def test_file_mode_without_attitude_columns_names_both_forms(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("t,x,y,z\n0,0,0,0\n1,1,1,1\n")
    with pytest.raises(SceneError, match=r"roll, pitch, yaw or qw, qx, qy, qz columns"):
        scene_from_dict({"scene": {"rate_hz": 10}, "trajectory": {"file": str(path)}, "attitude": {"mode": "file"},
                         "imu": [{}]})
