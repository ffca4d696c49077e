"""Sampled trajectories with the Earth model: geodetic columns (lat_deg, lon_deg, height_m) in CSV/NPZ track
files, and ECI track files whose Earth rotation angle is reduced exactly as the symbolic path reduces it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_emulator import scene_from_dict
from imu_emulator.errors import SceneError
from imu_emulator.runtime.simulation import Simulation

ORIGIN = (-33.9, 151.2, 45.0)
EFFECTS = {"gravity": True, "earth_rate": True, "coriolis": True}


def _run(head, trajectory, attitude=None, t0=0.0, duration=20.0, rate=10):
    scene = scene_from_dict({"scene": {"rate_hz": rate, "duration_s": duration, "t0_s": t0, "gravity_model": "wgs84",
                                       **head},
                             "trajectory": trajectory, "attitude": attitude or {"roll": "0", "pitch": "0", "yaw": "0"},
                             "imu": [{"name": "a"}], "effects": EFFECTS})
    out = Simulation(scene, attitude=False, truth=True).run()
    return out.accel[0], out.gyro[0], out.truth


def test_geodetic_columns_match_the_geodetic_expressions(tmp_path):
    """A CSV of lat_deg, lon_deg, height_m: the path is linear in latitude and longitude and height, sampled at 10 Hz beyond the
    scene's span, and compared with the same expressions given symbolically: the files' derivatives are
    fitted (quintic spline), so f and omega agree to the fit's error. The path's own smoothness costs nothing
    (its ECEF fifth derivative, ~v^5 / R^4 ~ 1e-17 m/s^5, times h^3 = 1e-3 s^3); what is left is the rounding of
    6e6 m positions (1e-9 m) through the spline's second-derivative weights (~10 / h^2 = 1e3 /s^2): 1e-5 m/s^2
    bound (1.1e-6 seen), and through the velocity (~1e-8 m/s) into Coriolis and transport rate, 1e-10 rad/s."""
    lat, lon, h = "-33.9 + 0.0005*t", "151.2 + 0.001*t", "45 + 3*t"
    t = [x / 10.0 for x in range(-20, 321)]
    rows = ["t,lat_deg,lon_deg,height_m"] + [f"{x!r},{-33.9 + 0.0005 * x!r},{151.2 + 0.001 * x!r},{45 + 3 * x!r}"
                                             for x in t]
    (tmp_path / "geo.csv").write_text("\n".join(rows) + "\n")
    head = {"frame": "NED", "t0_s": 0.0}
    f_file, w_file, tr = _run(head, {"file": str(tmp_path / "geo.csv")}, duration=30.0)
    f_sym, w_sym, _ = _run(head, {"lat_deg": lat, "lon_deg": lon, "height_m": h}, duration=30.0)
    assert np.max(np.abs(f_file - f_sym)) < 1e-5
    assert np.max(np.abs(w_file - w_sym)) < 1e-10
    # the truth reads the columns back (pymap3d: an independent geodetic conversion)
    pymap3d = pytest.importorskip("pymap3d")
    ecef = np.array([pymap3d.geodetic2ecef(-33.9 + 0.0005 * x, 151.2 + 0.001 * x, 45 + 3 * x) for x in t[20:320]])
    np.testing.assert_allclose(tr["position_ecef"], ecef, rtol=0, atol=1e-6)
    np.testing.assert_allclose(tr["geodetic"][:, 0], -33.9 + 0.0005 * np.array(t[20:320]), rtol=0, atol=1e-10)


def test_geodetic_npz_and_tangent_attitude(tmp_path):
    """NPZ arrays t, lat_deg, lon_deg, height_m with tangent attitude: the heading is the path's (eastward along
    the equator: 90 deg), pitch 0, and the gyros read omega_ie + v/(a) about north as in the closed form."""
    v, a = 250.0, 6378137.0
    t = np.arange(-30, 331) / 10.0
    np.savez(tmp_path / "geo.npz", t=t, lat_deg=0 * t, lon_deg=np.degrees(v * t / a), height_m=0 * t)
    f, w, tr = _run({"frame": "NED"}, {"file": str(tmp_path / "geo.npz")}, attitude={"mode": "tangent"},
                    duration=30.0)
    # the fitted velocity's rounding error (~1e-8 m/s of 250 m/s, as above) sets the angles' floor
    np.testing.assert_allclose(tr["euler_ned"][:, 2], math.pi / 2, atol=1e-9)
    np.testing.assert_allclose(tr["euler_ned"][:, 1], 0.0, atol=1e-9)
    # the fitted acceleration's rounding error (up to 1e-5 m/s^2, as above) over 250 m/s turns the heading by
    # up to 4e-8 rad/s; the transport rate itself is 3.9e-5 rad/s
    np.testing.assert_allclose(w[:, 1], -(7.292115e-5 + v / a), rtol=0, atol=4e-8)


def test_geodetic_columns_refused_where_they_cannot_be(tmp_path):
    (tmp_path / "bad.csv").write_text("t,lat_deg,lon_deg,height_m\n0,91,0,0\n1,91,0,0\n2,91,0,0\n3,91,0,0\n"
                                      "4,91,0,0\n5,91,0,0\n6,91,0,0\n")
    with pytest.raises(SceneError, match=r"bad.csv: row 2, column 'lat_deg': 91.0 is out of range"):
        _run({"frame": "NED"}, {"file": str(tmp_path / "bad.csv")})
    (tmp_path / "mix.csv").write_text("t,lat_deg,lon_deg,z\n0,1,2,3\n")
    with pytest.raises(SceneError, match=r"mix.csv: missing column height_m \(need t, lat_deg, lon_deg, height_m\)"):
        _run({"frame": "NED"}, {"file": str(tmp_path / "mix.csv")})


@pytest.mark.parametrize("t0", [0.0, 3.0e7])
def test_sampled_eci_point_fixed_on_the_earth_is_static(tmp_path, t0):
    """A point fixed on the Earth, as an ECI track (it turns at omega_ie about z), reads like the static point,
    also at t = 3e7 s (omega t = 2188 rad): the rotation angle of the file's time is reduced exactly. Sampled
    at 1 Hz: positions of 6e6 m round to 1e-9 m, which the fitted acceleration turns into ~1e-9 m/s^2."""
    pymap3d = pytest.importorskip("pymap3d")
    x0, y0, z0 = (float(c) for c in pymap3d.geodetic2ecef(*ORIGIN))
    t = t0 + np.arange(-10, 31, dtype=float)
    from fractions import Fraction
    # the file's positions from the exact angle (Fraction time, mpmath-free: omega t mod 2 pi in double after an
    # exact reduction of the integer part of t)
    theta = np.array([float((Fraction(7292115, 10 ** 11) * Fraction(x)) % Fraction(math.tau)) for x in t])
    np.savez(tmp_path / "eci.npz", t=t, x=x0 * np.cos(theta) - y0 * np.sin(theta),
             y=x0 * np.sin(theta) + y0 * np.cos(theta), z=np.full_like(t, z0))
    f, w, _ = _run({"frame": "ECI"}, {"file": str(tmp_path / "eci.npz")}, t0=t0, duration=10.0, rate=1)
    f_ref, w_ref, _ = _run({"frame": "NED", "origin": dict(zip(("lat_deg", "lon_deg", "height_m"), ORIGIN))},
                           {"shape": "static"}, t0=t0, duration=10.0, rate=1)
    np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-8)
    # the fitted velocity's ~1e-9 m/s rounding error over R ~ 6.4e6 m: transport rate below 1e-15 rad/s
    np.testing.assert_allclose(w, w_ref, rtol=0, atol=1e-15)
