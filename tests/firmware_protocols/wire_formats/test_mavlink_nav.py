"""The sensor head's GNSS, barometer and attitude over MAVLink (HIL_GPS, GPS_RAW_INT, SCALED_PRESSURE, ATTITUDE,
ATTITUDE_QUATERNION), decoded by pymavlink (common dialect) and compared with the Samples they came from.

What PX4 does with HIL_GPS, transcribed from PX4/PX4-Autopilot
src/modules/simulation/simulator_mavlink/SimulatorMavlink.cpp handle_message_hil_gps()
(commit f66bdc0f22d072fcb9b4a57c12e9beae302e16fc):
  latitude_deg = lat / 1e7; longitude_deg = lon / 1e7; altitude_msl_m = altitude_ellipsoid_m = alt / 1e3;
  eph = eph * 1e-2, epv = epv * 1e-2 ("cm -> m"); vel_m_s = vel / 100; vel_n/e/d = vn/ve/vd / 100;
  cog_rad = NaN if cog == 65535 else radians(cog * 1e-2); satellites_used = satellites_visible;
  fix_type = fix_type; one sensor_gps instance per HIL_GPS id.
"""
import io
import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2
from pymavlink.quaternion import Quaternion

from firmware_protocols import registry
from firmware_protocols.base import EncodeError, Samples
from firmware_protocols.gnss_time import GNSS_DEFAULTS
from firmware_protocols.wire_formats.mavlink import MavlinkEncoder, SigningLink
from firmware_protocols.wire_formats.mavlink_nav import MavlinkNavEncoder

KEY = bytes(range(32))
T0 = 1_700_000_000 * 10**9          # Unix-epoch sample time (2023-11-14)


def decode(data: bytes, key=None) -> list:
    mav = mavlink2.MAVLink(io.BytesIO())
    if key is not None:
        mav.signing.secret_key = key
    return mav.parse_buffer(data) or []


def px4_hil_gps(message) -> dict:
    """PX4's sensor_gps from one HIL_GPS (transcribed above)."""
    return {"latitude_deg": message.lat / 1e7, "longitude_deg": message.lon / 1e7, "altitude_m": message.alt / 1e3,
            "eph": message.eph * 1e-2, "epv": message.epv * 1e-2, "vel_m_s": message.vel / 100.0,
            "vel_ned": (message.vn / 100.0, message.ve / 100.0, message.vd / 100.0),
            "cog_rad": math.nan if message.cog == 65535 else math.radians(message.cog * 1e-2),
            "satellites_used": message.satellites_visible, "fix_type": message.fix_type}


def gnss_block(n=50, rate_hz=50.0, gnss_hz=5.0, seed=3):
    """A receiver at gnss_hz inside an IMU stream at rate_hz: its solution held between fixes, with a latency."""
    rng = np.random.default_rng(seed)
    t = T0 + (np.arange(n) * 1e9 / rate_hz).astype(np.int64)
    every = int(rate_hz / gnss_hz)
    new = (np.arange(n) % every == 0).astype(float)
    fix_at = np.repeat(np.arange(0, n, every), every)[:n]
    llh = np.column_stack([47.3 + rng.normal(0, 1e-4, n), 8.5 + rng.normal(0, 1e-4, n), 500 + rng.normal(0, 3, n)])
    vel = rng.normal(0, 8, (n, 3))
    return Samples(t, np.zeros((n, 3)), rng.normal(0, 0.2, (n, 3)),
                   gnss_llh=llh[fix_at], gnss_velocity_ned=vel[fix_at], gnss_fix=np.full(n, 3.0),
                   gnss_satellites=np.full(n, 17.0), gnss_hdop=np.full(n, 0.9), gnss_vdop=np.full(n, 1.3),
                   gnss_horizontal_accuracy_m=np.full(n, 1.7), gnss_vertical_accuracy_m=np.full(n, 2.9),
                   gnss_speed_accuracy_mps=np.full(n, 0.21), gnss_new=new,
                   gnss_age_s=0.08 + (np.arange(n) - fix_at) / rate_hz)


def test_hil_gps_as_px4_reads_it_equals_the_receiver_solution():
    block = gnss_block()
    batch = MavlinkNavEncoder("mavlink-hil-gps", id=2).encode(block)
    messages = decode(batch.data)
    new = np.flatnonzero(block.gnss_new)
    assert len(messages) == len(new) == 5
    # one frame exactly at each new solution, nothing between
    sizes = np.diff(batch.offsets)
    assert (sizes[new] > 0).all() and (np.delete(sizes, new) == 0).all()
    for i, message in zip(new, messages):
        px4 = px4_hil_gps(message)
        lat, lon, h = block.gnss_llh[i]
        assert abs(px4["latitude_deg"] - lat) <= 0.5e-7 and abs(px4["longitude_deg"] - lon) <= 0.5e-7
        assert abs(px4["altitude_m"] - h) <= 0.5e-3
        vn, ve, vd = block.gnss_velocity_ned[i]
        assert np.allclose(px4["vel_ned"], (vn, ve, vd), atol=0.005 + 1e-12)
        assert abs(px4["vel_m_s"] - math.hypot(vn, ve)) <= 0.005 + 1e-12
        assert abs(math.remainder(px4["cog_rad"] - math.atan2(ve, vn), 2 * math.pi)) <= math.radians(0.005) + 1e-12
        assert (px4["eph"], px4["epv"]) == (pytest.approx(1.7), pytest.approx(2.9))
        assert px4["satellites_used"] == 17 and px4["fix_type"] == 3 and message.id == 2
        # time of validity: the sample time less the solution's age (latency), in us
        assert message.time_usec == (block.time_ns[i] - round(block.gnss_age_s[i] * 1e9)) // 1000


def test_gps_raw_int_carries_dops_and_accuracies_in_common_xml_units():
    block = gnss_block()
    messages = decode(MavlinkNavEncoder("mavlink-gps-raw-int").encode(block).data)
    assert len(messages) == 5
    for message, i in zip(messages, np.flatnonzero(block.gnss_new)):
        assert (message.eph, message.epv) == (90, 130)                  # HDOP, VDOP x 100
        assert (message.h_acc, message.v_acc, message.vel_acc) == (1700, 2900, 210)   # mm, mm, mm/s
        assert message.alt == message.alt_ellipsoid == round(block.gnss_llh[i, 2] * 1000)
        assert message.lat == round(block.gnss_llh[i, 0] * 1e7)


@pytest.mark.parametrize("vn, ve, cog", [(5, 0, 0), (0, 5, 9000), (-5, 0, 18000), (0, -5, 27000),
                                         (5, -1e-9, 0), (1, 1, 4500)])
def test_course_over_ground_in_centidegrees_on_0_to_36000(vn, ve, cog):
    n = 1
    block = Samples([T0], np.zeros((n, 3)), np.zeros((n, 3)), gnss_llh=[[1.0, 2.0, 3.0]],
                    gnss_velocity_ned=[[vn, ve, 0.0]])
    (message,) = decode(MavlinkNavEncoder("mavlink-hil-gps").encode(block).data)
    assert message.cog == cog


def test_without_a_receiver_the_position_is_sent_with_default_quality_and_without_any_no_fix():
    block = Samples([T0, T0 + 10**7], np.zeros((2, 3)), np.zeros((2, 3)), position_llh=[[10, 20, 30]] * 2,
                    velocity_ned=[[1, 2, 3]] * 2)
    messages = decode(MavlinkNavEncoder("mavlink-gps-raw-int").encode(block).data)
    assert len(messages) == 2                        # gnss_new absent: every sample
    m = messages[0]
    assert (m.lat, m.lon, m.alt, m.fix_type, m.satellites_visible) == (10 * 10**7, 20 * 10**7, 30000, 3,
                                                                      GNSS_DEFAULTS["num_sats"])
    assert m.h_acc == GNSS_DEFAULTS["h_acc_m"] * 1000
    nothing = Samples([T0], np.zeros((1, 3)), np.zeros((1, 3)))
    (m,) = decode(MavlinkNavEncoder("mavlink-hil-gps").encode(nothing).data)
    assert (m.fix_type, m.lat, m.lon) == (1, 0, 0)  # GPS_FIX_TYPE_NO_FIX
    no_fix = gnss_block(n=10)
    no_fix.gnss_fix[:] = 0
    assert {m.fix_type for m in decode(MavlinkNavEncoder("mavlink-hil-gps").encode(no_fix).data)} == {1}


def test_out_of_range_velocity_saturates_and_is_counted():
    block = Samples([T0], np.zeros((1, 3)), np.zeros((1, 3)), gnss_llh=[[0, 0, 0]],
                    gnss_velocity_ned=[[400.0, 0, -500.0]])
    encoder = MavlinkNavEncoder("mavlink-hil-gps")
    (m,) = decode(encoder.encode(block).data)
    assert (m.vn, m.vd, m.vel) == (32767, -32768, 40000)
    assert encoder.saturated.counts == {"vn": 1, "vd": 1}


def test_scaled_pressure_at_the_barometer_rate():
    n = 100
    rng = np.random.default_rng(5)
    t = (np.arange(n) * 5_000_000).astype(np.int64)              # 200 Hz
    block = Samples(t, np.zeros((n, 3)), np.zeros((n, 3)), pressure_pa=rng.normal(95000, 100, n),
                    temperature_c=np.r_[0.0, rng.normal(15, 5, n - 1)], differential_pressure_pa=rng.uniform(0, 900, n))
    # a 25 Hz barometer's readings from t = 0 (closed form): new where floor(t / 40 ms) changes
    picked = np.flatnonzero(np.r_[True, np.diff(t // 40_000_000) != 0])
    block.baro_new = np.isin(np.arange(n), picked).astype(float)
    encoder = MavlinkNavEncoder("mavlink-scaled-pressure")
    messages = decode(encoder.encode(block.slice(0, 33)).data + encoder.encode(block.slice(33, n)).data)
    assert len(messages) == 13                        # 0.5 s at 25 Hz from t = 0 (t = 0 .. 0.495 s)
    for message, i in zip(messages, picked):
        assert message.press_abs == pytest.approx(block.pressure_pa[i] / 100, rel=2**-23)
        assert message.press_diff == pytest.approx(block.differential_pressure_pa[i] / 100, rel=2**-23, abs=1e-9)
        assert message.temperature == round(block.temperature_c[i] * 100)
        # 0 means "not available" for the differential sensor's temperature: a reading of 0 goes out as 1
        assert message.temperature_press_diff == (round(block.temperature_c[i] * 100) or 1)
    assert messages[0].temperature == 0 and messages[0].temperature_press_diff == 1


def test_attitude_matches_pymavlinks_own_quaternion_to_euler():
    rng = np.random.default_rng(11)
    n = 30
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    gyro = rng.normal(0, 1, (n, 3))
    block = Samples(T0 + np.arange(n) * 10**6, np.zeros((n, 3)), gyro, quat=q)
    attitudes = decode(MavlinkNavEncoder("mavlink-attitude").encode(block).data)
    quaternions = decode(MavlinkNavEncoder("mavlink-attitude-quaternion").encode(block).data)
    assert len(attitudes) == len(quaternions) == n
    for i, (a, aq) in enumerate(zip(attitudes, quaternions)):
        roll, pitch, yaw = Quaternion(list(q[i])).euler         # pymavlink's own z-y-x conversion, the oracle
        assert (a.roll, a.pitch, a.yaw) == (pytest.approx(roll, abs=1e-6), pytest.approx(pitch, abs=1e-6),
                                            pytest.approx(yaw, abs=1e-6))
        assert [aq.q1, aq.q2, aq.q3, aq.q4] == pytest.approx(list(q[i]), rel=2**-23)
        assert (a.rollspeed, a.pitchspeed, a.yawspeed) == pytest.approx(tuple(gyro[i]), rel=2**-23)
        assert (aq.rollspeed, aq.pitchspeed, aq.yawspeed) == (a.rollspeed, a.pitchspeed, a.yawspeed)
        assert aq.time_boot_ms == a.time_boot_ms == (block.time_ns[i] // 10**6) % 2**32
    # no attitude at all: identity, level
    bare = Samples([T0], np.zeros((1, 3)), np.zeros((1, 3)))
    (a,) = decode(MavlinkNavEncoder("mavlink-attitude").encode(bare).data)
    assert (a.roll, a.pitch, a.yaw) == (0.0, 0.0, 0.0)


def test_signed_frames_share_the_link_and_pass_pymavlinks_check():
    link = SigningLink(KEY, link_id=3)
    imu = MavlinkEncoder("mavlink-hil-sensor", signing_link=link, sign_time="sample")
    gps = MavlinkNavEncoder("mavlink-hil-gps", signing_link=link, sign_time="sample", seq=200)
    block = gnss_block(n=20)
    stream = b"".join(imu.encode(block.slice(i, i + 1)).data + gps.encode(block.slice(i, i + 1)).data
                      for i in range(20))
    messages = decode(stream, key=KEY)
    assert [m.get_type() for m in messages].count("HIL_GPS") == 2 and len(messages) == 22   # fixes at 5 Hz
    stamps = [m._signed and int.from_bytes(m.get_msgbuf()[-12:-6], "little") for m in messages]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert [m.get_seq() for m in messages if m.get_type() == "HIL_GPS"] == [200, 201]


def test_bad_input_and_options_are_one_line_errors():
    block = gnss_block(n=25)                          # new solutions at samples 0, 10, 20
    block.gnss_llh[3, 1] = np.inf                     # not sent: not checked
    assert len(decode(MavlinkNavEncoder("mavlink-hil-gps").encode(block).data)) == 3
    block.gnss_llh[20, 1] = np.inf
    with pytest.raises(EncodeError, match="'gnss_llh' at sample 20, component 1"):
        MavlinkNavEncoder("mavlink-hil-gps").encode(block)
    for options, needle in ((dict(message="mavlink-attitude", id=1), "id: ATTITUDE has no id field"),
                            (dict(message="mavlink-scaled-pressure", baro_rate_hz=5), r"baro_rate_hz: retired; .*\[imu.barometer\]"),
                            (dict(message="mavlink-nope"), "message: unknown 'mavlink-nope'"),
                            (dict(message="mavlink-hil-gps", sysid=300), "sysid: must be 0..255")):
        with pytest.raises(ValueError, match=needle):
            MavlinkNavEncoder(**options)


def test_registered_with_a_decoder_that_reads_them_back():
    block = gnss_block(n=10)
    for name in ("mavlink-hil-gps", "mavlink-gps-raw-int", "mavlink-scaled-pressure", "mavlink-attitude",
                 "mavlink-attitude-quaternion"):
        info = registry.get(name)
        data = info.encoder().encode(block).data
        packets = info.decoder().feed(data)
        assert [p.kind for p in packets] == [name] * len(decode(data)) and packets
        assert info.bytes_per_sample >= max(len(p.raw) for p in packets)     # the budget is an upper bound
