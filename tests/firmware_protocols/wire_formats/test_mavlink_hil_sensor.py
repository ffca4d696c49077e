"""HIL_SENSOR as PX4's HITL simulator interface reads it: the sensor head's magnetometer, static and differential
pressure and temperature, each flagged in fields_updated only when that sensor has a new reading.

What PX4 does with the message, transcribed from PX4/PX4-Autopilot
src/modules/simulation/simulator_mavlink/SimulatorMavlink.hpp (commit ad4197644707b638783ab1745635b8a731b6a5e4)
and SimulatorMavlink.cpp update_sensors() (commit f66bdc0f22d072fcb9b4a57c12e9beae302e16fc):
  enum SensorSource { ACCEL = 0b111, GYRO = 0b111000, MAG = 0b111000000, BARO = 0b1101000000000,
                      DIFF_PRESS = 0b10000000000 }
  a sensor is published only when (fields_updated & SOURCE) == SOURCE (all of its bits);
  baro: pressure = abs_pressure * 100 (hPa -> Pa), temperature = temperature (degC);
  differential pressure: diff_pressure * 100 (hPa -> Pa); mag: xmag/ymag/zmag in gauss as they come.
The oracle for the bytes is pymavlink (common dialect)."""
import io

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from firmware_protocols.base import EncodeError, Samples
from firmware_protocols.wire_formats.mavlink import MavlinkEncoder

# PX4's SensorSource, as transcribed above
ACCEL, GYRO, MAG, BARO, DIFF_PRESS = 0b111, 0b111000, 0b111000000, 0b1101000000000, 0b10000000000


def px4_reads(message) -> dict:
    """What PX4's update_sensors() publishes from one HIL_SENSOR, in its own units (Pa, degC, gauss)."""
    out = {}
    bits = message.fields_updated
    if bits & MAG == MAG:
        out["mag"] = (message.xmag, message.ymag, message.zmag)
    if bits & BARO == BARO:
        out["pressure_pa"] = message.abs_pressure * 100.0
        out["temperature_c"] = message.temperature
    if bits & DIFF_PRESS == DIFF_PRESS:
        out["differential_pressure_pa"] = message.diff_pressure * 100.0
    return out


def decode(data: bytes) -> list:
    return mavlink2.MAVLink(io.BytesIO()).parse_buffer(data) or []


def sensor_head_block(n=400, rate_hz=200.0, seed=7, t0_ns=5_000_000):
    rng = np.random.default_rng(seed)
    t = (np.arange(n) * (1e9 / rate_hz)).astype(np.int64) + t0_ns
    return Samples(t, rng.normal(0, 1, (n, 3)), rng.normal(0, 0.1, (n, 3)), mag=rng.normal(0, 0.4, (n, 3)),
                   pressure_pa=rng.normal(97000, 50, n), temperature_c=rng.normal(21, 1, n),
                   differential_pressure_pa=rng.uniform(0, 600, n))


def test_px4_reads_every_sensor_head_field_equal_to_the_samples():
    block = sensor_head_block(n=20)
    messages = decode(MavlinkEncoder("mavlink-hil-sensor").encode(block).data)
    assert len(messages) == 20
    for i, message in enumerate(messages):
        read = px4_reads(message)
        f32 = lambda v: float(np.float32(v))       # noqa: E731 - the wire's float32
        assert message.fields_updated & (ACCEL | GYRO) == ACCEL | GYRO
        assert read["mag"] == tuple(f32(v) for v in block.mag[i])
        assert read["pressure_pa"] == pytest.approx(block.pressure_pa[i], rel=2**-23)
        assert read["temperature_c"] == f32(block.temperature_c[i])
        assert read["differential_pressure_pa"] == pytest.approx(block.differential_pressure_pa[i], rel=2**-23,
                                                                 abs=1e-9)
        # ISA pressure altitude, closed form: 44330.77 m (1 - (p / 101325)^0.190263)
        isa = 44330.77 * (1 - (block.pressure_pa[i] / 101325.0) ** 0.190263)
        assert message.pressure_alt == pytest.approx(isa, abs=1e-3)


def test_mag_and_baro_flagged_only_where_the_samples_say_new():
    rate, mag_hz, baro_hz = 200.0, 50.0, 20.0
    block = sensor_head_block(n=400, rate_hz=rate, t0_ns=0)
    t = block.time_ns
    # a reading every 1/rate from t = 0 (closed form, floor arithmetic): new where floor(t * rate) changes
    mag_new = np.r_[True, np.diff(t // round(1e9 / mag_hz)) != 0]
    baro_new = np.r_[True, np.diff(t // round(1e9 / baro_hz)) != 0]
    block.mag_new, block.baro_new = mag_new.astype(float), baro_new.astype(float)
    encoder = MavlinkEncoder("mavlink-hil-sensor")
    # cut into uneven blocks: each sample's flags travel with it
    data = b"".join(encoder.encode(block.slice(a, b)).data for a, b in ((0, 7), (7, 133), (133, 400)))
    messages = decode(data)
    assert len(messages) == 400
    seen_mag = np.array([m.fields_updated & MAG == MAG for m in messages])
    seen_baro = np.array([m.fields_updated & BARO == BARO for m in messages])
    seen_diff = np.array([m.fields_updated & DIFF_PRESS == DIFF_PRESS for m in messages])
    assert (seen_mag == mag_new).all() and (seen_baro == baro_new).all() and (seen_diff == baro_new).all()
    # 2 s of samples from t = 0: 100 magnetometer and 40 barometer readings, exactly
    assert seen_mag.sum() == 100 and seen_baro.sum() == 40
    # bits cleared never clear the IMU's own
    assert all(m.fields_updated & (ACCEL | GYRO) == ACCEL | GYRO for m in messages)
    # a partly flagged sensor would be one PX4 drops silently: bits go all-or-nothing per sensor
    for m in messages:
        assert m.fields_updated & MAG in (0, MAG)
        assert m.fields_updated & BARO in (0, BARO)


def test_a_non_finite_flag_is_named_in_a_block_and_alone():
    from firmware_protocols.devices.base import single
    block = sensor_head_block(n=4)
    block.mag_new, block.baro_new = np.ones(4), np.array([1.0, 0.0, np.nan, 1.0])
    with pytest.raises(EncodeError, match="'baro_new' at sample 2"):
        MavlinkEncoder("mavlink-hil-sensor").encode(block)
    with pytest.raises(EncodeError, match="'baro_new' at sample 0"):       # a device's block of one
        MavlinkEncoder("mavlink-hil-sensor").encode(single(block, 2))
    (alone,) = decode(MavlinkEncoder("mavlink-hil-sensor").encode(single(block, 1)).data)
    assert alone.fields_updated & (MAG | BARO) == MAG                     # the one sample's flags, not the block's


def test_without_flags_every_sample_carries_the_readings():
    """Samples without mag_new / baro_new (no scene companion): every provided field flagged, as before."""
    block = sensor_head_block(n=5)
    messages = decode(MavlinkEncoder("mavlink-hil-sensor").encode(block).data)
    assert all(m.fields_updated & (MAG | BARO) == MAG | BARO for m in messages)


def test_absent_fields_keep_their_bits_clear():
    block = sensor_head_block(n=3)
    bare = Samples(block.time_ns, block.accel, block.gyro)
    (first, *_rest) = decode(MavlinkEncoder("mavlink-hil-sensor").encode(bare).data)
    assert first.fields_updated == ACCEL | GYRO
    assert px4_reads(first) == {}
    assert (first.xmag, first.abs_pressure, first.diff_pressure, first.temperature) == (0.0, 0.0, 0.0, 0.0)


def test_constant_diff_pressure_option_wins_over_the_samples():
    block = sensor_head_block(n=2)
    (message, _) = decode(MavlinkEncoder("mavlink-hil-sensor", diff_pressure_pa=250.0).encode(block).data)
    assert message.diff_pressure == pytest.approx(2.5)


@pytest.mark.parametrize("options, needle", [
    (dict(message="mavlink-scaled-imu", mag_rate_hz=50.0), r"mag_rate_hz: retired; .*\[imu.magnetometer\] rate_hz"),
    (dict(baro_rate_hz=20.0), r"baro_rate_hz: retired; .*\[imu.barometer\] rate_hz"),
])
def test_retired_rate_options_name_the_scene_key(options, needle):
    options.setdefault("message", "mavlink-hil-sensor")
    with pytest.raises(ValueError, match=needle) as error:
        MavlinkEncoder(**options)
    assert "\n" not in str(error.value)


def test_non_finite_differential_pressure_is_named():
    block = sensor_head_block(n=4)
    block.differential_pressure_pa[2] = np.nan
    with pytest.raises(ValueError, match="differential_pressure_pa' at sample 2"):
        MavlinkEncoder("mavlink-hil-sensor").encode(block)
