"""Companion sensors (imu_emulator.companions): each against an independent source.

- magnetometer: NOAA's published WMM2025 test values (WMM2025_TEST_VALUES.txt, NCEI, December 2024, as shipped with
  the model: https://www.ncei.noaa.gov/products/world-magnetic-model) and pygeomag called directly at places off
  the memo grid; the rotation into the sensor's axes and the iron terms in closed form;
- barometer: the ICAO standard atmosphere's table (Doc 7488/3, the values the issue quotes) and the ambiance
  package at geometric heights;
- GNSS: white and Gauss-Markov errors' mean, variance and lag-one autocorrelation within confidence intervals
  from the estimators' variances (fixed seeds), latency, rate, outages, GPS time of week of the epoch;
- INS: its errors' statistics and its attitude against scipy's rotation composition.
The runners are driven with synthetic truth (no kernel) except the end-to-end tests at the bottom, which compile
one kernel for the module.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from imu_emulator.companions import COMPANIONS, Truth, documentation_table
from imu_emulator.companions import barometer, magnetometer
from imu_emulator.companions.gnss import offset_llh
from imu_emulator.companions.ins import estimate_quat
from imu_emulator.errors import SceneError
from imu_emulator.geo import wgs84
from imu_emulator.scene.companions import companion_specs
from tests.support.paths import REPO

ROOT = REPO
PLACE = (47.397742, 8.545594, 488.0)
IMU_VALUES = {"imu.temperature_c": "25.0", "imu.warmup_rise_c": 0.0, "imu.warmup_tau_s": 600.0,
              "imu.temperature_ref_c": 25.0}

# NOAA WMM2025_TEST_VALUES.txt: date, height (km), lat, lon, X, Y, Z (nT)
WMM2025_TEST_VALUES = [
    (2025.0, 0.0, 80.0, 0.0, 6521.6, 145.9, 54791.5),
    (2025.0, 0.0, 0.0, 120.0, 39677.8, -109.6, -10580.2),
    (2025.0, 0.0, -80.0, 240.0, 6117.5, 15751.9, -52022.5),
    (2025.0, 100.0, 80.0, 0.0, 6216.0, 92.4, 52598.8),
    (2025.0, 100.0, 0.0, 120.0, 37688.6, -96.2, -10152.1),
    (2025.0, 100.0, -80.0, 240.0, 5907.6, 14780.3, -49540.7),
    (2027.5, 0.0, 80.0, 0.0, 6500.8, 294.5, 54869.4),
    (2027.5, 0.0, 0.0, 120.0, 39701.6, -167.4, -10381.8),
    (2027.5, 0.0, -80.0, 240.0, 6200.7, 15730.3, -51783.7),
    (2027.5, 100.0, 80.0, 0.0, 6196.7, 233.8, 52670.5),
    (2027.5, 100.0, 0.0, 120.0, 37711.5, -148.7, -9969.8),
    (2027.5, 100.0, -80.0, 240.0, 5984.0, 14760.1, -49317.7),
]


def _values(name: str, **keys) -> dict:
    """A companion's parameters as scene validation gives them (units parsed, defaults filled)."""
    return companion_specs({name: keys}, "imu[0]")[name]


def _scene(rate_hz: float, seed: int = 11, t0: float = 0.0, frame: str = "NED"):
    return SimpleNamespace(seed=seed, t0_s=t0, rate_hz=rate_hz, frame=frame)


def _truth(s, rate_hz, llh=None, v_ned=None, c_ns=None, c_nb=None, omega=None) -> Truth:
    s = np.asarray(s, dtype=np.int64)
    n = len(s)

    def rows(value, shape):
        return np.broadcast_to(np.asarray(value, dtype=float), (n,) + shape).copy()
    return Truth(s=s, t=s / rate_hz, rate_hz=rate_hz, llh=rows(PLACE if llh is None else llh, (3,)),
                 v_ned=rows(0.0 if v_ned is None else v_ned, (3,)), c_ns=rows(np.eye(3) if c_ns is None else c_ns,
                                                                             (3, 3)),
                 c_nb=rows(np.eye(3) if c_nb is None else c_nb, (3, 3)),
                 omega_b=rows(0.0 if omega is None else omega, (3,)), values=IMU_VALUES)


def _run(runner, truth_of, n: int, block: int) -> dict:
    """A runner over samples 0..n-1 in blocks of `block`, joined."""
    parts = [runner.block(truth_of(np.arange(k, min(k + block, n)))) for k in range(0, n, block)]
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def _ned_error(llh, reference) -> np.ndarray:
    """North, east, down metres of geodetic positions from a reference, through the local radii."""
    lat = math.radians(reference[0])
    r_n, r_e = wgs84.radii(lat)
    h = reference[2]
    return np.column_stack([np.radians(llh[:, 0] - reference[0]) * (r_n + h),
                            np.radians(llh[:, 1] - reference[1]) * (r_e + h) * math.cos(lat), reference[2] - llh[:, 2]])


# --- magnetometer ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("row", WMM2025_TEST_VALUES, ids=lambda r: f"{r[0]}-{r[1]}km-{r[2]}-{r[3]}")
def test_field_matches_noaa_wmm2025_test_values(row):
    year, h_km, lat, lon, x, y, z = row
    field = magnetometer.field_ned([[lat, lon, h_km * 1000.0]], year)[0] * magnetometer.NT_PER_GAUSS
    # the table is rounded to 0.1 nT
    np.testing.assert_allclose(field, [x, y, z], atol=0.051)


def test_field_off_the_memo_grid_agrees_with_pygeomag_within_the_cells_bound():
    from pygeomag import GeoMag
    model = GeoMag(coefficients_file="wmm/WMM_2025.COF")
    rng = np.random.default_rng(3)
    places = np.column_stack([rng.uniform(-85, 85, 40), rng.uniform(-180, 180, 40), rng.uniform(-400, 30000, 40)])
    ours = magnetometer.field_ned(places, 2026.25) * magnetometer.NT_PER_GAUSS
    for place, got in zip(places, ours):
        r = model.calculate(glat=place[0], glon=place[1], alt=place[2] / 1000.0, time=2026.25)
        # half a cell (5.6 m, 5 m) at the main field's gradient, at most ~0.03 nT/m near the poles
        np.testing.assert_allclose(got, [r.x, r.y, r.z], atol=0.5)


def test_magnetometer_turns_the_field_into_the_sensor_axes_through_soft_and_hard_iron():
    values = _values("magnetometer", rate_hz=100, soft_iron=[[1.02, 0.01, 0.0], [0.01, 0.98, 0.0], [0.0, 0.0, 1.0]],
                     hard_iron=["20 uT", "-0.05 G", "1 mG"])
    yaw = math.radians(30.0)   # the sensor's x axis 30 deg east of north, level
    c_ns = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    runner = COMPANIONS["magnetometer"].start(_scene(100.0), 0, values)
    got = runner.block(_truth(np.arange(5), 100.0, c_ns=c_ns))["mag"]
    b = magnetometer.field_ned([PLACE], 2025.0)[0]
    expected = np.array(values["soft_iron"]) @ (c_ns.T @ b) + [0.2, -0.05, 0.001]
    np.testing.assert_allclose(got, np.tile(expected, (5, 1)), rtol=0, atol=1e-12)
    # horizontal intensity and declination come through unchanged by the rotation
    level = c_ns.T @ b
    assert math.hypot(level[0], level[1]) == pytest.approx(math.hypot(b[0], b[1]), rel=1e-12)


def test_magnetometer_noise_is_white_with_the_density_times_root_rate_and_held_between_updates():
    rate, imu_rate, density = 25.0, 100.0, 4e-4
    values = _values("magnetometer", rate_hz=rate, noise_density=density)
    runner = COMPANIONS["magnetometer"].start(_scene(imu_rate), 0, values)
    n = 400_000
    out = _run(runner, lambda s: _truth(s, imu_rate), n, 50_000)["mag"]
    held = out.reshape(-1, 4, 3)
    assert np.all(held == held[:, :1, :])          # one update every 4 samples, held
    updates = held[:, 0, :]
    noise = updates - updates.mean(axis=0)
    sigma = density * math.sqrt(rate)
    m = len(updates)
    # sample variance of m normals: relative standard deviation sqrt(2 / (m - 1)); 4.5 sigma
    np.testing.assert_allclose(noise.var(axis=0, ddof=1) / sigma ** 2, 1.0, atol=4.5 * math.sqrt(2 / (m - 1)))
    # independent axes and updates: correlations within 4.5 / sqrt(m)
    assert abs(np.corrcoef(noise[:, 0], noise[:, 1])[0, 1]) < 4.5 / math.sqrt(m)
    assert abs(np.corrcoef(noise[1:, 2], noise[:-1, 2])[0, 1]) < 4.5 / math.sqrt(m)


def test_magnetometer_range_clips_and_counts_and_resolution_rounds():
    values = _values("magnetometer", rate_hz=100, range="0.3 G", resolution="1 mG")
    runner = COMPANIONS["magnetometer"].start(_scene(100.0), 0, values)
    got = runner.block(_truth(np.arange(10), 100.0))["mag"]
    b = magnetometer.field_ned([PLACE], 2025.0)[0]     # Z ~ 0.43 G beyond the range
    assert np.all(got[:, 2] == pytest.approx(0.3))
    assert runner.counts == {"magnetometer.range": 10}
    np.testing.assert_allclose(got[0, :2], np.round(b[:2] / 1e-3) * 1e-3, atol=1e-15)


# --- barometer -------------------------------------------------------------------------------------------------

# ICAO Doc 7488/3 table (the layers' base pressures as the U.S. Standard Atmosphere 1976 lists them): geopotential
# height (m') -> pressure (Pa). Six figures, and the constants' rounding accumulates over the layers: 1e-5.
ISA_TABLE = [(0.0, 101325.0), (1000.0, 89874.6), (5000.0, 54019.9), (11000.0, 22632.1), (20000.0, 5474.89),
             (32000.0, 868.019), (47000.0, 110.906), (51000.0, 66.9389), (71000.0, 3.95642), (-2000.0, 127774.0)]


@pytest.mark.parametrize("height,pressure", ISA_TABLE)
def test_standard_atmosphere_matches_the_icao_table(height, pressure):
    _, p = barometer.isa_geopotential(height)
    assert p[0] == pytest.approx(pressure, rel=1e-5)


def test_standard_atmosphere_at_geometric_heights_matches_ambiance():
    from ambiance import Atmosphere
    h = np.linspace(-4000.0, 80000.0, 211)
    t, p, rho = barometer.isa(h)
    air = Atmosphere(h)
    # ambiance starts each layer from the standard's rounded base pressure, we chain the layers: 2e-6 apart
    np.testing.assert_allclose(p, air.pressure, rtol=1e-5)
    np.testing.assert_allclose(t, air.temperature, rtol=1e-9)
    np.testing.assert_allclose(rho, air.density, rtol=1e-5)


def test_barometer_bias_drift_temperature_and_pitot_in_closed_form():
    values = _values("barometer", rate_hz=10, bias="0.5 hPa", drift="3.6 Pa/h", temperature_coefficient="2 Pa/K")
    runner = COMPANIONS["barometer"].start(_scene(10.0), 0, values)
    imu = dict(IMU_VALUES, **{"imu.temperature_c": "20 + 0.01*t"})
    truth = _truth(np.arange(0, 36000, 600), 10.0, v_ned=[30.0, 40.0, 0.0])
    truth.values = imu
    # body x along the velocity, 50 m/s forward
    heading = math.atan2(40.0, 30.0)
    truth.c_nb[:] = [[math.cos(heading), -math.sin(heading), 0.0], [math.sin(heading), math.cos(heading), 0.0],
                     [0.0, 0.0, 1.0]]
    out = runner.block(truth)
    t = truth.t
    temperature = 20 + 0.01 * t
    _, p, rho = barometer.isa(np.full(len(t), PLACE[2]))
    np.testing.assert_allclose(out["baro_temperature_c"], temperature, rtol=1e-12)
    np.testing.assert_allclose(out["pressure_pa"], p + 50.0 + 1e-3 * t + 2.0 * (temperature - 25.0), rtol=1e-12)
    np.testing.assert_allclose(out["differential_pressure_pa"], 0.5 * rho * 50.0 ** 2, rtol=1e-12)


def test_barometer_noise_variance_within_its_confidence_interval():
    values = _values("barometer", rate_hz=50, noise="1.2 Pa")
    runner = COMPANIONS["barometer"].start(_scene(50.0, seed=5), 0, values)
    n = 200_000
    p = _run(runner, lambda s: _truth(s, 50.0), n, 40_000)["pressure_pa"]
    noise = p - barometer.isa(PLACE[2])[1][0]
    assert abs(noise.mean()) < 4.5 * 1.2 / math.sqrt(n)
    assert noise.var(ddof=1) / 1.2 ** 2 == pytest.approx(1.0, abs=4.5 * math.sqrt(2 / (n - 1)))


# --- GNSS ------------------------------------------------------------------------------------------------------

def test_gnss_white_and_markov_errors_have_their_stated_statistics():
    rate, tau, n = 10.0, 1.0, 200_000
    phi = math.exp(-1.0 / (rate * tau))
    markov = _values("gnss", rate_hz=rate, position_markov=[1.0, 2.0, 3.0], markov_time_s=tau)
    white = _values("gnss", rate_hz=rate, position_noise=[0.5, 0.5, 1.5], velocity_noise=0.1)
    for values, kind in ((markov, "markov"), (white, "white")):
        runner = COMPANIONS["gnss"].start(_scene(rate, seed=21), 0, values)
        out = _run(runner, lambda s: _truth(s, rate), n, 30_000)
        assert np.all(out["gnss_new"] == 1) and np.all(out["gnss_fix"] == 3)
        e = _ned_error(out["gnss_llh"], PLACE)
        sigma = np.asarray(values[f"position_{'markov' if kind == 'markov' else 'noise'}"])
        z = e / sigma
        if kind == "white":
            rho, var_rel, mean_sd, r1_sd = 0.0, math.sqrt(2 / (n - 1)), 1 / math.sqrt(n), 1 / math.sqrt(n)
            v = out["gnss_velocity_ned"] / 0.1
            assert v.var(axis=0, ddof=1) == pytest.approx([1, 1, 1], abs=4.5 * var_rel)
        else:
            # AR(1): var(mean) = (1 + phi) / ((1 - phi) n); var(s^2) / sigma^4 = 2 (1 + phi^2) / ((1 - phi^2) n);
            # var(r1) = (1 - phi^2) / n (Bartlett)
            rho = phi
            mean_sd = math.sqrt((1 + phi) / ((1 - phi) * n))
            var_rel = math.sqrt(2 * (1 + phi ** 2) / ((1 - phi ** 2) * n))
            r1_sd = math.sqrt((1 - phi ** 2) / n)
        assert np.all(np.abs(z.mean(axis=0)) < 4.5 * mean_sd)
        np.testing.assert_allclose(z.var(axis=0), 1.0, atol=4.5 * var_rel)
        centred = z - z.mean(axis=0)
        r1 = (centred[1:] * centred[:-1]).sum(axis=0) / (centred ** 2).sum(axis=0)
        np.testing.assert_allclose(r1, rho, atol=4.5 * r1_sd + 2.0 / n)
        # the stated accuracies are the errors' standard deviations
        assert out["gnss_horizontal_accuracy_m"][0] == pytest.approx(math.hypot(sigma[0], sigma[1]))
        assert out["gnss_vertical_accuracy_m"][0] == pytest.approx(sigma[2])


def test_gnss_errors_do_not_depend_on_how_the_run_is_cut_into_blocks():
    values = _values("gnss", rate_hz=5, position_noise=0.3, position_markov=2.0, velocity_markov=0.2, latency_s=0.07)
    runs = [_run(COMPANIONS["gnss"].start(_scene(100.0), 0, values), lambda s: _truth(s, 100.0), 5000, block)
            for block in (5000, 333, 7)]
    for other in runs[1:]:
        for key in runs[0]:
            np.testing.assert_array_equal(runs[0][key], other[key], err_msg=key)


def test_gnss_rate_latency_and_antenna_lever_arm():
    imu_rate, rate, latency = 100.0, 5.0, 0.1
    values = _values("gnss", rate_hz=rate, latency_s=latency, lever_arm_m=[1.0, 0.0, -2.0])

    def moving(s):     # due north at 10 m/s, turning at 0.5 rad/s about down (body = NED axes, level)
        truth = _truth(s, imu_rate, v_ned=[10.0, 0.0, 0.0], omega=[0.0, 0.0, 0.5])
        truth.llh = offset_llh(truth.llh, np.column_stack([10.0 * s / imu_rate, 0 * s, 0 * s]))
        return truth
    out = _run(COMPANIONS["gnss"].start(_scene(imu_rate), 0, values), moving, 1000, 137)
    new = np.flatnonzero(out["gnss_new"])
    # solution j valid at j / 5 s = sample 20 j, out at 20 j + 10
    np.testing.assert_array_equal(new, 20 * np.arange(len(new)) + 10)
    assert len(new) == 50
    assert np.all(out["gnss_fix"][:10] == 0) and np.all(out["gnss_fix"][10:] == 3)
    np.testing.assert_allclose(out["gnss_age_s"][new], latency, atol=1e-12)
    np.testing.assert_allclose(out["gnss_age_s"][new + 5], latency + 0.05, atol=1e-12)
    # the antenna is 1 m ahead of and 2 m above S; S moved 10 m/s * 0.2 s per solution
    e = _ned_error(out["gnss_llh"][new], PLACE)
    np.testing.assert_allclose(e[:, 0], 2.0 * np.arange(50) + 1.0, atol=1e-6)
    np.testing.assert_allclose(e[:, 2], -2.0, atol=1e-6)
    # v + omega x r: 0.5 rad/s about down times 1 m forward = 0.5 m/s east
    np.testing.assert_allclose(out["gnss_velocity_ned"][new], np.tile([10.0, 0.5, 0.0], (50, 1)), atol=1e-12)


def test_gnss_outage_gives_no_fix_and_holds_the_last_position():
    values = _values("gnss", rate_hz=10, outages_s=[[2.0, 3.5]])
    out = _run(COMPANIONS["gnss"].start(_scene(50.0), 0, values), lambda s: _truth(s, 50.0), 300, 64)
    t = np.arange(300) / 50.0
    inside = (t >= 2.0) & (t < 3.5)
    assert np.all(out["gnss_fix"][inside] == 0) and np.all(out["gnss_satellites"][inside] == 0)
    assert np.all(out["gnss_fix"][~inside] == 3) and np.all(out["gnss_satellites"][~inside] == 12)
    np.testing.assert_allclose(out["gnss_llh"][inside], np.tile(PLACE, (inside.sum(), 1)))
    runner = COMPANIONS["gnss"].start(_scene(50.0), 0, values)
    _run(runner, lambda s: _truth(s, 50.0), 300, 300)
    assert runner.counts == {"gnss.outage_solutions": 15}


def test_gnss_time_of_week_of_the_sample_less_its_age_is_the_solutions_epoch():
    from firmware_protocols.gnss_time import GNSS_DEFAULTS, gnss_pvt_rows
    epoch_ns = 1_767_225_600 * 10 ** 9         # 2026-01-01 00:00:00 UTC, a stream's --start-time
    values = _values("gnss", rate_hz=4, latency_s=0.03)
    out = _run(COMPANIONS["gnss"].start(_scene(100.0), 0, values), lambda s: _truth(s, 100.0), 1000, 250)
    time_ns = epoch_ns + np.arange(1000) * 10_000_000
    valid = out["gnss_fix"] == 3
    epoch = time_ns[valid] - np.rint(out["gnss_age_s"][valid] * 1e9).astype(np.int64)
    itow = gnss_pvt_rows(epoch, out["gnss_llh"][valid], out["gnss_velocity_ned"][valid], dict(GNSS_DEFAULTS))[:, 0]
    # 2026-01-01 is a Thursday: 4 days into the GPS week, plus 18 leap seconds; solutions every 250 ms
    assert np.all((itow - (4 * 86400 + 18) * 1000) % 250 == 0)
    expected = (4 * 86400 + 18) * 1000 + 250 * np.floor((np.flatnonzero(valid) / 100.0 - 0.03) * 4 + 1e-9)
    np.testing.assert_array_equal(itow, expected)


# --- INS estimate ----------------------------------------------------------------------------------------------

def test_ins_errors_are_markov_with_their_sigmas_and_the_mode_reports_alignment():
    rate, n = 100.0, 200_000
    values = _values("ins", attitude_error=["0.5 deg", "0.5 deg", "2 deg"], position_error=[1, 1, 2],
                     velocity_error=0.05, error_time_s=0.5, aligning_s=30)
    out = _run(COMPANIONS["ins"].start(_scene(rate, seed=4), 0, values), lambda s: _truth(s, rate), n, 50_000)
    phi = math.exp(-1.0 / (rate * 0.5))
    var_rel = math.sqrt(2 * (1 + phi ** 2) / ((1 - phi ** 2) * n))
    sigma = np.radians([0.5, 0.5, 2.0])
    np.testing.assert_allclose(out["ins_attitude_error_rad"].var(axis=0) / sigma ** 2, 1.0, atol=4.5 * var_rel)
    np.testing.assert_allclose(_ned_error(out["position_llh"], PLACE).var(axis=0) / np.array([1, 1, 4.0]), 1.0,
                               atol=4.5 * var_rel)
    np.testing.assert_allclose(out["velocity_ned"].var(axis=0) / 0.05 ** 2, 1.0, atol=4.5 * var_rel)
    np.testing.assert_allclose(out["attitude_sigma_rad"][-1], sigma)
    t = np.arange(n) / rate
    np.testing.assert_array_equal(out["ins_mode"], np.where(t < 30, 1.0, 2.0))


def test_ins_attitude_error_turns_the_attitude_on_the_navigation_side():
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(8)
    truth = Rotation.random(50, random_state=9)
    error = rng.normal(0, 0.05, (50, 3))
    q = truth.as_quat()
    got = estimate_quat(np.column_stack([q[:, 3], q[:, :3]]), error)
    expected = (Rotation.from_rotvec(error) * truth).as_quat()
    expected = np.column_stack([expected[:, 3], expected[:, :3]])
    np.testing.assert_allclose(got * np.sign(got[:, :1] * expected[:, :1]), expected, atol=1e-12)


# --- scene -----------------------------------------------------------------------------------------------------

def _scene_dict(**imu):
    return {"scene": {"rate_hz": 100, "duration_s": 1.0, "frame": "NED",
                      "origin": {"lat_deg": PLACE[0], "lon_deg": PLACE[1], "height_m": PLACE[2]}},
            "trajectory": {"x": "0", "y": "0", "z": "0"}, "attitude": {"roll": "0", "pitch": "0", "yaw": "0"},
            "imu": [{"name": "imu0", **imu}], "effects": {"gravity": True}}


def test_a_scene_without_origin_naming_a_companion_is_refused_in_one_line():
    from imu_emulator.scene.load import from_dict
    raw = _scene_dict(gnss={})
    del raw["scene"]["origin"]
    with pytest.raises(SceneError) as exc:
        from_dict(raw)
    assert str(exc.value).startswith("scene.origin: imu[0].gnss needs the point") and "\n" not in str(exc.value)
    assert from_dict(_scene_dict(gnss={})).imus[0].companions["gnss"]["rate_hz"] == 5.0


@pytest.mark.parametrize("table,message", [
    ({"gnss": {"rate_hz": 50}}, "imu[0].gnss.rate_hz: receivers give 1 to 20"),
    ({"gnss": {"rates_hz": 5}}, "imu[0].gnss"),
    ({"gnss": {"outages_s": [[5, 2]]}}, "imu[0].gnss.outages_s[0]: expected [start_s, stop_s] with start < stop"),
    ({"magnetometer": {"noise_density": "3 m/s"}}, "imu[0].magnetometer.noise_density"),
    ({"magnetometer": {"date_year": 2040}}, "imu[0].magnetometer.date_year: WMM2025 holds"),
    ({"barometer": {"noise": -1}}, "imu[0].barometer.noise"),
    ({"ins": {"error_time_s": 0}}, "imu[0].ins.error_time_s"),
    ({"barometer": 3}, "imu[0].barometer: expected a table"),
])
def test_bad_companion_keys_are_refused_naming_the_key(table, message):
    from imu_emulator.scene.load import from_dict
    with pytest.raises(SceneError) as exc:
        from_dict(_scene_dict(**table))
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_the_docs_companion_table_is_generated_from_the_declarations():
    """docs/companions.md asks the site's build for the table made from the records (tools/docs_tables.py);
    tests/project/test_docs_site.py reads every parameter back from the built page."""
    assert "<!-- generated: companions -->" in (ROOT / "docs" / "companions.md").read_text()
    assert "| `[imu.gnss]` | `rate_hz` |" in documentation_table()


# --- end to end: the kernel's truth through the simulation, the files and the live stream ---------------------

@pytest.fixture(scope="module")
def run():
    from imu_emulator.runtime.simulation import Simulation
    from imu_emulator.scene.load import from_dict
    raw = {"scene": {"rate_hz": 100, "duration_s": 12.0, "frame": "ENU", "seed": 3,
                     "origin": {"lat_deg": PLACE[0], "lon_deg": PLACE[1], "height_m": PLACE[2]}},
           "trajectory": {"shape": "circle", "radius_m": 20.0, "frequency_hz": 0.1, "height_m": 50.0},
           "attitude": {"mode": "tangent"},
           "imu": [{"name": "imu0", "magnetometer": {"rate_hz": 50, "noise_density": "400 ugauss/sqrt(Hz)"},
                    "barometer": {"noise": "1 Pa"}, "gnss": {"position_markov": 1.0, "latency_s": 0.05},
                    "ins": {"attitude_error": "1 deg"}},
                   {"name": "imu1", "mounting_rpy_deg": [0, 0, 90]}],
           "effects": {"gravity": True, "mounting": True}}
    scene = from_dict(raw)
    sim = Simulation(scene, attitude=False)
    return scene, sim, sim.run(block_size=250)


def test_simulated_magnetometer_is_the_field_in_the_sensor_axes_and_blocks_out_of_order_agree(run):
    scene, sim, whole = run
    mag = whole.companion[0]["mag"]
    # noise-free part: |m| is the field's intensity wherever the body turns (rotation keeps length)
    intensity = np.linalg.norm(magnetometer.field_ned([PLACE], 2025.0)[0])
    sigma = 4e-4 * math.sqrt(50.0)
    assert np.abs(np.linalg.norm(mag, axis=1) - intensity).max() < 6 * sigma
    assert whole.companion[1] == {}
    again = sim.fresh()
    late = again.block(900, 100)          # out of order: replayed from the start
    early = again.block(100, 50)
    for key in whole.companion[0]:
        np.testing.assert_array_equal(late.companion[0][key], whole.companion[0][key][900:1000], err_msg=key)
        np.testing.assert_array_equal(early.companion[0][key], whole.companion[0][key][100:150], err_msg=key)
    # the barometer reads the ISA at the true height (origin + 50 m up)
    p = whole.companion[0]["pressure_pa"]
    assert abs(p.mean() - barometer.isa(PLACE[2] + 50.0)[1][0]) < 4.5 / math.sqrt(600)


def test_simulated_magnetometer_reads_the_heading_in_closed_form_in_an_enu_scene(run):
    """A level body flying a circle with tangent attitude: heading psi = atan2(v_e, v_n) from the truth velocity;
    the field in forward-right-down axes is (X cos psi + Y sin psi, -X sin psi + Y cos psi, Z), and the ENU scene's
    body axes are forward-left-up (y, z negated)."""
    scene, _, whole = run
    updates = np.arange(0, len(whole), 2)          # the 50 Hz magnetometer updates at even 100 Hz samples
    v = whole.truth["velocity_ned"][updates]
    psi = np.arctan2(v[:, 1], v[:, 0])
    x, y, z = magnetometer.field_ned(whole.truth["geodetic"][updates], 2025.0).T
    frd = np.column_stack([x * np.cos(psi) + y * np.sin(psi), -x * np.sin(psi) + y * np.cos(psi), z])
    flu = frd * [1.0, -1.0, -1.0]
    got = whole.companion[0]["mag"][updates]
    sigma = 4e-4 * math.sqrt(50.0)
    assert np.abs(got - flu).max() < 5.5 * sigma
    assert abs(np.mean(got - flu)) < 5.5 * sigma / math.sqrt(got.size)


def test_generate_columns_carry_the_companions_and_nan_for_an_imu_without(run):
    from imu_emulator.output.columns import block_columns, scene_layout
    scene, _, whole = run
    columns = block_columns(whole, scene.imu_names, scene_layout(scene, truth=False))
    for name in ("mag_x", "mag_y", "mag_z", "pressure_pa", "baro_temperature_c", "gnss_lat_deg", "gnss_lon_deg",
                 "gnss_h_m", "gnss_vn", "gnss_ve", "gnss_vd", "gnss_fix", "gnss_new"):
        assert name in columns
    np.testing.assert_array_equal(columns["mag_x"][0::2], whole.companion[0]["mag"][:, 0])
    assert np.isnan(columns["gnss_h_m"][1::2]).all()
    np.testing.assert_array_equal(columns["gnss_new"][0::2], whole.companion[0]["gnss_new"])


def test_stream_samples_carry_the_companions_and_the_units_estimate(run):
    import firmware_protocols
    from firmware_protocols import attitude
    from imu_emulator.live.config import StreamConfig
    from imu_emulator.live.stream import Stream
    scene, _, whole = run
    stream = Stream(StreamConfig("imu0", "mavlink-highres", "pty"), 0, firmware_protocols.get("mavlink-highres"),
                    100.0)
    stream.frame = scene.frame
    samples = stream.samples(whole, whole.time_ns())
    c = whole.companion[0]
    # The wire's axes are the upright part's forward-right-down: the ENU scene's forward-left-up turned by pi about x
    flu_to_frd = np.array([1.0, -1.0, -1.0])
    np.testing.assert_array_equal(samples.mag, c["mag"] * flu_to_frd)
    np.testing.assert_array_equal(samples.pressure_pa, c["pressure_pa"])
    np.testing.assert_array_equal(samples.temperature_c, c["baro_temperature_c"])
    np.testing.assert_array_equal(samples.gnss_llh, c["gnss_llh"])
    np.testing.assert_array_equal(samples.ins_mode, c["ins_mode"])
    from scipy.spatial.transform import Rotation
    truth_q = attitude.to_ned(whole.quat[0], "ENU")
    expected = Rotation.from_quat(estimate_quat(truth_q, c["ins_attitude_error_rad"])[:, [1, 2, 3, 0]]) \
        * Rotation.from_matrix(np.diag(flu_to_frd))
    got = Rotation.from_quat(samples.quat[:, [1, 2, 3, 0]])
    assert np.max((got.inv() * expected).magnitude()) < 1e-12
