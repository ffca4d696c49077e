"""[attitude] reference = "ECEF" | "ECI": roll, pitch, yaw relative to another frame than local level.

Closed forms: a body whose attitude is fixed in ECI reads zero rotation whatever it flies (the transport and
Earth rates of the level frame cancel exactly); one turning at a constant rate about an ECI or ECEF axis reads
that rate plus, for ECEF with earth_rate, C_e^b omega_ie^e. The accelerometers of the ECEF-referenced body read
C_e^b (r'' + 2 omega_ie x r' - g^e), checked against the same motion with local-level attitude rebuilt in
pymap3d's NED axes.
"""
from __future__ import annotations

import numpy as np
import pytest

from imu_emulator import scene_from_dict
from imu_emulator.errors import SceneError
from imu_emulator.runtime.simulation import Simulation

OMEGA = 7.292115e-5
ORIGIN = {"lat_deg": 40.0, "lon_deg": -105.0, "height_m": 1600.0}
# a fast, turning flight in the origin's NED frame: 20 km of curvature over the run
MOTION = {"x": "200*t + 3*t**2", "y": "-150*t + 400*sin(0.05*t)", "z": "-2*t"}


def _run(reference, attitude, effects, frame="NED", trajectory=MOTION, duration=60.0, t0=0.0):
    scene = scene_from_dict({
        "scene": {"rate_hz": 5, "duration_s": duration, "frame": frame, "origin": ORIGIN, "t0_s": t0,
                  "gravity_model": "wgs84"},
        "trajectory": trajectory, "attitude": {**attitude, "reference": reference},
        "imu": [{"name": "a"}], "effects": effects})
    out = Simulation(scene, attitude=False, truth=True).run()
    return out.accel[0], out.gyro[0], out.truth


@pytest.mark.parametrize("t0", [0.0, 3.0e7])
def test_attitude_fixed_in_eci_reads_no_rotation(t0):
    _, w, _ = _run("ECI", {"roll": "0.3", "pitch": "-0.2", "yaw": "1.1"},
                   {"gravity": True, "earth_rate": True, "coriolis": True}, t0=t0)
    assert np.max(np.abs(w)) < 1e-15
    _, w, _ = _run("ECI", {"roll": "0.3", "pitch": "-0.2", "yaw": "1.1 + 0.02*t"},
                   {"gravity": True, "earth_rate": True, "coriolis": True}, t0=t0)
    # yaw about the ECI z axis, seen in body axes: R_y(pitch)^T R_x(roll)^T ... = E(phi) (0, 0, 0.02)
    want = 0.02 * np.array([-np.sin(-0.2), np.sin(0.3) * np.cos(-0.2), np.cos(0.3) * np.cos(-0.2)])
    np.testing.assert_allclose(w, np.broadcast_to(want, w.shape), rtol=0, atol=1e-15)


def test_attitude_fixed_in_ecef_reads_the_earth_rate_only():
    """omega_ib^b = C_e^b (0, 0, omega_ie) with earth_rate; nothing without it (no transport rate either)."""
    roll, pitch, yaw = 0.3, -0.2, 1.1
    from scipy.spatial.transform import Rotation
    c_be = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    _, w, truth = _run("ECEF", {"roll": repr(roll), "pitch": repr(pitch), "yaw": repr(yaw)},
                       {"gravity": True, "earth_rate": True, "coriolis": True})
    np.testing.assert_allclose(w, np.broadcast_to(c_be.T @ [0.0, 0.0, OMEGA], w.shape), rtol=0, atol=1e-15)
    _, w, _ = _run("ECEF", {"roll": repr(roll), "pitch": repr(pitch), "yaw": repr(yaw)}, {"coriolis": True})
    assert np.max(np.abs(w)) < 1e-15


def test_ecef_reference_matches_the_local_level_attitude_it_implies():
    """A body fixed in ECEF, flown along MOTION: euler_ned equals scipy's angles of C_b^n = C_e^n C_b^e with
    pymap3d's NED axes at the truth's geodetic position, and the accelerometers read (C_b^n)^T f^n with f^n
    from the same flight with a level, north-facing body (f^n itself). 1e-9 rad and 1e-8 m/s^2: the axes
    come from the truth's latitude and longitude through pymap3d (~1e-10 rad) and |f| is ~11 m/s^2."""
    pymap3d = pytest.importorskip("pymap3d")
    from scipy.spatial.transform import Rotation
    c_be = Rotation.from_euler("ZYX", [1.1, -0.2, 0.3]).as_matrix()
    f, w, truth = _run("ECEF", {"roll": "0.3", "pitch": "-0.2", "yaw": "1.1"},
                       {"gravity": True, "earth_rate": True, "coriolis": True})
    f_lvl, _, _ = _run("local_level", {"roll": "0", "pitch": "0", "yaw": "0"},
                               {"gravity": True, "earth_rate": True, "coriolis": True})
    for k in (0, 100, 299):
        lat, lon, _ = truth["geodetic"][k]
        r0 = np.array(pymap3d.geodetic2ecef(lat, lon, 0.0))
        c_ne = np.column_stack([np.subtract(pymap3d.ned2ecef(*u, lat, lon, 0.0), r0) for u in np.eye(3)])
        c_bn = c_ne.T @ c_be
        want = Rotation.from_matrix(c_bn).as_euler("ZYX")[::-1]
        np.testing.assert_allclose(truth["euler_ned"][k], want, rtol=0, atol=1e-9)
        # level body's f is f^n (NED) itself
        np.testing.assert_allclose(f[k], c_bn.T @ f_lvl[k], rtol=0, atol=1e-8)


def test_reference_needs_the_earth_model():
    with pytest.raises(SceneError, match=r"attitude.reference: \"ECEF\" needs the Earth model"):
        scene_from_dict({"scene": {"rate_hz": 5, "duration_s": 1.0}, "trajectory": {"shape": "static"},
                         "attitude": {"roll": "0", "pitch": "0", "yaw": "0", "reference": "ECEF"},
                         "imu": [{"name": "a"}], "effects": {"gravity": True}})
    with pytest.raises(SceneError, match=r"attitude.reference: 'ned' is not one of"):
        _run("ned", {"roll": "0", "pitch": "0", "yaw": "0"}, {"earth_rate": True})


@pytest.mark.parametrize("effects, attitude", [
    (("earth_rate", "coriolis"), {"roll": "0.3", "pitch": "-0.2", "yaw": "1.1 + 0.02*t"}),
    # rolling at 0.2 rad/s in ECI: omega_nb x C_n^b omega_ie^n ~ 1.5e-5; using omega_body for omega_nb there
    # is off by |omega_en| |omega_ie| ~ 2e-9, 100x the tolerance
    (("earth_rate",), {"roll": "0.3 + 0.2*t", "pitch": "-0.2", "yaw": "1.1"})])
def test_angular_acceleration_is_the_derivative_of_the_rate(effects, attitude):
    """alpha_body (the kernel's d/dt of omega_body) against a 4th-order central difference of omega_body at
    5 Hz: for a body fixed in ECI, omega_body = omega_ib - C_n^b u (u: omega_ie^n with earth_rate, plus
    omega_en^n with coriolis) changes as the level frame turns. With earth_rate alone omega_body is not the
    rate of C_b^n (omega_nb = omega_body - C_n^b omega_en^n), and d/dt C_n^b u must use omega_nb.
    The difference's truncation (h^4 w^(5)/30) is negligible at these slow rates; its rounding, ~1e-16 |w| / h,
    is what the 1e-6 |alpha| tolerance covers with room."""
    _, _, truth = _run("ECI", attitude, {"gravity": True, **{name: True for name in effects}})
    w, al, h = truth["omega_body"], truth["alpha_body"], 0.2
    diff = (w[:-4] - 8 * w[1:-3] + 8 * w[3:-1] - w[4:]) / (12 * h)
    assert np.max(np.abs(al)) > 1e-6
    np.testing.assert_allclose(al[2:-2], diff, rtol=0, atol=1e-6 * np.max(np.abs(al)))
