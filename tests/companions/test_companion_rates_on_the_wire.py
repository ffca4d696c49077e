"""The companions' own rates reach the wire (issue 24, "rates"): a 400 Hz IMU with a 100 Hz magnetometer, a 50 Hz
barometer and a 5 Hz GNSS receiver (50 ms latency), streamed with no rate option to capture files. A reading is
new at the sample where floor(t * rate) changes (update j at j / rate, README "Companion sensors"); on the 400 Hz
clock that is closed-form integer arithmetic, k * rate // 400. `generate`'s mag_new / baro_new / gnss_new columns
must say exactly that, pymavlink's HIL_SENSOR fields_updated bits and SCALED_PRESSURE / HIL_GPS messages and
pydronecan's MagneticFieldStrength2 / StaticPressure / StaticTemperature / Fix2 transfers must come exactly there,
so each second carries the scene's rates: 100, 50 and 5 a second."""
import re

import numpy as np
import pytest

from tests.companions.test_sensor_head_end_to_end import ROOT, START_NS, candump_transfers, cli, mavlink

RATE = 400
SECONDS = 2
MAG_HZ, BARO_HZ, GNSS_HZ, LATENCY_SAMPLES = 100, 50, 5, 20      # latency_s 50 ms = 20 samples of 400 Hz
MAG_BITS, BARO_BITS = 0b111000000, 0b1101000000000               # PX4 SimulatorMavlink SensorSource MAG, BARO
K = np.arange(RATE * SECONDS)


def closed_form_new(rate_hz: int, delay_samples: int = 0) -> np.ndarray:
    """(n,) bool: the sensor's update index floor((k - delay) * rate / 400) changes at sample k (and is >= 0)."""
    j = (K - delay_samples) * rate_hz // RATE
    return (j != np.r_[-1, j[:-1]]) & (j >= 0)


MAG_NEW, BARO_NEW = closed_form_new(MAG_HZ), closed_form_new(BARO_HZ)
GNSS_NEW = closed_form_new(GNSS_HZ, LATENCY_SAMPLES)
# generate and stream in subprocesses: some 20 s
pytestmark = [pytest.mark.slow, pytest.mark.subprocess, pytest.mark.streams]

STREAMS = (("hil_sensor", "mavlink-hil-sensor", "bin"), ("scaled_pressure", "mavlink-scaled-pressure", "bin"),
           ("hil_gps", "mavlink-hil-gps", "bin"), ("dronecan", "dronecan-gnss-compass-baro", "log"),
           ("mag2", "dronecan-mag2", "log"), ("static_pressure", "dronecan-static-pressure", "log"))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("rates")
    text = (ROOT / "examples" / "companions.toml").read_text()
    text = re.sub(r"\nrate_hz = 200\n", f"\nrate_hz = {RATE}\n", text)
    text = re.sub(r"duration_s = [0-9.]+", f"duration_s = {SECONDS}.0", text)
    text = re.sub(r"outages_s = .*", "", text)
    text = text.replace("[imu.barometer]\n", f"[imu.barometer]\nrate_hz = {BARO_HZ}\n")
    assert f"rate_hz = {RATE}\n" in text and f"[imu.magnetometer]\nrate_hz = {MAG_HZ}\n" in text
    assert f"[imu.gnss]\nrate_hz = {GNSS_HZ}\nlatency_s = \"50 ms\"" in text
    for name, fmt, suffix in STREAMS:
        text += f'\n[[stream]]\nimu = "imu0"\nformat = "{fmt}"\nto = "file:{out / name}.{suffix}"\n'
    (out / "scene.toml").write_text(text)
    cli("generate", out / "scene.toml", "-o", out / "reference.npz", "--quiet")
    cli("stream", out / "scene.toml", "--speed", "0", "--quiet")
    with np.load(out / "reference.npz") as z:
        ref = {k: z[k][0] for k in ("mag_new", "baro_new", "gnss_new")}
    return out, ref


def per_second(samples) -> list:
    """How many of the sample indices fall in each whole second of the run."""
    return np.bincount(np.asarray(samples) // RATE, minlength=SECONDS).tolist()


def test_generate_columns_mark_the_closed_form_readings(run):
    _, ref = run
    assert np.array_equal(ref["mag_new"] != 0, MAG_NEW) and np.array_equal(ref["baro_new"] != 0, BARO_NEW)
    assert np.array_equal(ref["gnss_new"] != 0, GNSS_NEW)
    assert per_second(np.flatnonzero(MAG_NEW)) == [MAG_HZ] * SECONDS
    assert per_second(np.flatnonzero(BARO_NEW)) == [BARO_HZ] * SECONDS
    assert per_second(np.flatnonzero(GNSS_NEW)) == [GNSS_HZ] * SECONDS


def test_hil_sensor_fields_updated_at_each_sensor_s_own_readings(run):
    out, ref = run
    sensors = mavlink(out / "hil_sensor.bin")
    assert len(sensors) == len(K)                                  # HIL_SENSOR itself: every IMU sample
    sample = np.array([round(m.time_usec * RATE / 1e6) for m in sensors])
    assert np.array_equal(sample, K)
    updated = np.array([m.fields_updated for m in sensors])
    assert np.array_equal(updated & MAG_BITS == MAG_BITS, ref["mag_new"] != 0)
    assert np.array_equal(updated & BARO_BITS == BARO_BITS, ref["baro_new"] != 0)
    assert set((updated & MAG_BITS).tolist()) == {0, MAG_BITS} and set((updated & BARO_BITS).tolist()) == {0, BARO_BITS}
    assert per_second(np.flatnonzero(updated & MAG_BITS)) == [MAG_HZ] * SECONDS
    assert per_second(np.flatnonzero(updated & BARO_BITS)) == [BARO_HZ] * SECONDS


def test_mavlink_scaled_pressure_and_hil_gps_at_their_rates(run):
    out, ref = run
    pressure = [round(m.time_boot_ms * RATE / 1e3) for m in mavlink(out / "scaled_pressure.bin")]
    assert pressure == np.flatnonzero(ref["baro_new"]).tolist() and per_second(pressure) == [BARO_HZ] * SECONDS
    # HIL_GPS time_usec is the fix's time of validity in UTC: its arrival is that plus the latency
    fixes = [round((m.time_usec - START_NS // 1000) * RATE / 1e6) + LATENCY_SAMPLES for m in mavlink(out / "hil_gps.bin")]
    assert fixes == np.flatnonzero(GNSS_NEW).tolist() and per_second(fixes) == [GNSS_HZ] * SECONDS


def test_dronecan_node_message_counts_equal_the_rates(run):
    out, ref = run
    by_kind = {}
    for stamp, transfer in candump_transfers(out / "dronecan.log"):
        by_kind.setdefault(transfer.payload._type.full_name, []).append(round((stamp - START_NS / 1e9) * RATE))
    eq = "uavcan.equipment."
    expected = {eq + "ahrs.MagneticFieldStrength2": ref["mag_new"], eq + "air_data.StaticPressure": ref["baro_new"],
                eq + "air_data.StaticTemperature": ref["baro_new"], eq + "gnss.Fix2": GNSS_NEW}
    assert set(by_kind) == set(expected)
    for kind, new in expected.items():
        assert by_kind[kind] == np.flatnonzero(new).tolist(), kind
    assert {kind: per_second(samples) for kind, samples in by_kind.items()} == {
        eq + "ahrs.MagneticFieldStrength2": [MAG_HZ] * SECONDS, eq + "air_data.StaticPressure": [BARO_HZ] * SECONDS,
        eq + "air_data.StaticTemperature": [BARO_HZ] * SECONDS, eq + "gnss.Fix2": [GNSS_HZ] * SECONDS}


@pytest.mark.parametrize("name, column, rate", [("mag2", "mag_new", MAG_HZ), ("static_pressure", "baro_new", BARO_HZ)])
def test_dronecan_formats_streamed_alone_follow_the_sensor(run, name, column, rate):
    out, ref = run
    samples = [round((stamp - START_NS / 1e9) * RATE) for stamp, _ in candump_transfers(out / f"{name}.log")]
    assert samples == np.flatnonzero(ref[column]).tolist() and per_second(samples) == [rate] * SECONDS
