"""MicroStrain MIP (descriptor set 0x80): the spec's published vector byte for byte, our packets read by a
decoder written here from the spec (struct, big-endian, Fletcher-16), and by MicroStrain's own library
(pymscl) through a pty."""
import os
import struct
import time
import tty
from datetime import datetime, timezone

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware_protocols import registry
from firmware_protocols.base import EncodeError, Samples
from firmware_protocols.wire_formats.microstrain import FIELDS, MipDecoder, MipEncoder
from tests.support.stream_fuzz import damaged_stream, feed_in_chunks
from tests.support.timing import scaled

SETTINGS = settings(derandomize=True, deadline=None, max_examples=60,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
F32_MAX = float(np.finfo(np.float32).max)
G = 9.80665
WEEK_NS = 604_800 * 10 ** 9
# GPS time - UTC Unix time, from the definitions rather than the module: the GPS epoch 1980-01-06T00:00:00Z and the
# 18 leap seconds GPS has gained on UTC since (IERS Bulletin C, from 2017-01-01).
GPS_MINUS_UNIX_NS = 18 * 10 ** 9 - round((datetime(1980, 1, 6, tzinfo=timezone.utc)
                                          - datetime(1970, 1, 1, tzinfo=timezone.utc)).total_seconds()) * 10 ** 9


def unix_of_gps(week: int, tow_ns: int) -> int:
    """Samples.time_ns (UTC Unix ns) of a GPS week and time of week."""
    return week * WEEK_NS + tow_ns - GPS_MINUS_UNIX_NS

# wire-formats.md, "MicroStrain MIP": accel in g from the common sample, gyro, mag, pressure 1013.25 mbar,
# quaternion (1, 0, 0, 0), GPS timestamp tow 123456.789 week 2300 flags 7.
SPEC_VECTOR = bytes.fromhex(
    "756580500e043c2711ffbca711ffbf8000000e053c23d70abca3d70a3cf5c28f0e063e570a3d3c23d70abed70a3d0617447d50"
    "00120a3f8000000000000000000000000000000e1240fe240c9fbe76c908fc000740f1")
SPEC_SAMPLE = Samples.single(unix_of_gps(2300, 123_456_789_000_000), [0.1, -0.2, -9.80665], [0.01, -0.02, 0.03],
                             mag=[0.21, 0.01, -0.42], pressure_pa=101_325.0, quat=[1.0, 0.0, 0.0, 0.0])


# --- an independent reader, from the spec ------------------------------------------------------

def spec_fletcher(data: bytes):
    a = b = 0
    for byte in data:
        a = (a + byte) % 256
        b = (b + a) % 256
    return a, b


def spec_fields(packet: bytes):
    """{descriptor: data} of one 0x80 packet; asserts the spec's framing and checksum."""
    assert packet[:2] == b"\x75\x65" and packet[2] == 0x80
    assert len(packet) == 4 + packet[3] + 2 <= 261
    assert spec_fletcher(packet[:-2]) == (packet[-2], packet[-1])
    fields, k, payload = {}, 0, packet[4:-2]
    while k < len(payload):
        size, descriptor = payload[k], payload[k + 1]
        fields[descriptor] = payload[k + 2:k + size]
        k += size
    assert k == len(payload)
    return fields


def f32(values):
    return [float(np.float32(v)) for v in values]


# --- published vector --------------------------------------------------------------------------

def test_spec_vector_byte_for_byte():
    encoder = registry._REGISTRY["microstrain-mip"].encoder(gps_flags=7)
    assert encoder.encode(SPEC_SAMPLE).data == SPEC_VECTOR
    assert encoder.bytes_per_sample == len(SPEC_VECTOR) == registry._REGISTRY["microstrain-mip"].bytes_per_sample


def test_spec_vector_read_by_spec_decoder_and_ours():
    fields = spec_fields(SPEC_VECTOR)
    assert list(fields) == [0x04, 0x05, 0x06, 0x17, 0x0A, 0x12]
    assert list(struct.unpack(">3f", fields[0x04])) == f32(np.array([0.1, -0.2, -9.80665]) / G)
    assert struct.unpack(">f", fields[0x17]) == (1013.25,)
    assert struct.unpack(">dHH", fields[0x12]) == (123456.789, 2300, 7)
    decoder = MipDecoder()
    (packet,) = decoder.feed(SPEC_VECTOR)
    f = packet.fields
    assert packet.kind == "mip-sensor" and f["descriptors"] == list(fields)
    assert f["accel"] == pytest.approx((0.1, -0.2, -9.80665), rel=1e-7)
    assert f["gyro"] == tuple(f32([0.01, -0.02, 0.03]))
    assert f["mag"] == tuple(f32([0.21, 0.01, -0.42]))
    assert f["pressure_pa"] == 101_325.0 and f["quat"] == (1.0, 0.0, 0.0, 0.0)
    assert f["time_ns"] == unix_of_gps(2300, 123_456_789_000_000) and f["gps_flags"] == 7


def test_every_field_read_by_spec_decoder():
    encoder = MipEncoder(fields=tuple(FIELDS))
    sample = Samples.single(unix_of_gps(2005, 1_500_000_001), [1.0, 2.0, 3.0], [0.1, 0.2, 0.3], mag=[0.2, 0.3, 0.4],
                            quat=[0.5, 0.5, 0.5, 0.5], euler=[0.1, 0.2, 0.3], pressure_pa=95_000.0,
                            delta_theta=[1e-4, 2e-4, 3e-4], delta_velocity=[0.01, 0.02, 0.03])
    fields = spec_fields(encoder.encode(sample).packet(0))
    assert list(fields) == [FIELDS[name].descriptor for name in FIELDS]
    assert list(struct.unpack(">3f", fields[0x04])) == f32(np.array([1.0, 2.0, 3.0]) / G)
    assert list(struct.unpack(">3f", fields[0x08])) == f32(np.array([0.01, 0.02, 0.03]) / G)  # g*s
    assert list(struct.unpack(">3f", fields[0x07])) == f32([1e-4, 2e-4, 3e-4])
    assert list(struct.unpack(">4f", fields[0x0A])) == [0.5] * 4
    assert list(struct.unpack(">3f", fields[0x0C])) == f32([0.1, 0.2, 0.3])
    assert struct.unpack(">f", fields[0x17]) == (950.0,)                         # mbar
    assert struct.unpack(">dHH", fields[0x12]) == (1.500000001, 2005, 0x1C)


# --- round trips over the full range -----------------------------------------------------------

any_double = st.floats(allow_nan=False, allow_infinity=False)


@SETTINGS
@given(st.lists(st.tuples(any_double, any_double, any_double), min_size=1, max_size=6), any_double)
def test_float_round_trip_and_saturation(vectors, pressure):
    accel = np.array(vectors)
    n = len(accel)
    encoder = MipEncoder(fields="accel,gyro,pressure")
    batch = encoder.encode(Samples(np.arange(n, dtype=np.int64), accel, accel * 0.5,
                                   pressure_pa=np.full(n, pressure)))
    packets = MipDecoder().feed(batch.data)
    assert len(packets) == n
    wire_accel = np.clip(accel / G, -F32_MAX, F32_MAX).astype(np.float32)
    wire_gyro = np.clip(accel * 0.5, -F32_MAX, F32_MAX).astype(np.float32)
    wire_pressure = np.float32(np.clip(pressure / 100.0, -F32_MAX, F32_MAX))
    for i, p in enumerate(packets):
        assert p.fields["accel"] == tuple(float(v) * G for v in wire_accel[i])
        assert p.fields["gyro"] == tuple(float(v) for v in wire_gyro[i])
        assert p.fields["pressure_pa"] == float(wire_pressure) * 100.0
    counts = encoder.saturated.counts
    assert counts.get("accel", 0) == np.count_nonzero(np.abs(accel / G) > F32_MAX)
    assert counts.get("gyro", 0) == np.count_nonzero(np.abs(accel * 0.5) > F32_MAX)
    assert counts.get("pressure", 0) == n * int(abs(pressure / 100.0) > F32_MAX)


@SETTINGS
@given(st.integers(-3 * WEEK_NS, 12_000 * WEEK_NS), st.integers(0, 0xFFFF))
def test_gps_timestamp_round_trip_and_week_saturation(time_ns, flags):
    # time_ns is UTC Unix ns; int64 nanoseconds reach only ~15 000 weeks, so only weeks before the GPS epoch
    # (1980-01-06) can saturate
    encoder = MipEncoder(fields=("gps_timestamp",), gps_flags=flags)
    packet = encoder.encode(Samples.single(time_ns, [0, 0, 0], [0, 0, 0])).packet(0)
    tow, week, got_flags = struct.unpack(">dHH", spec_fields(packet)[0x12])
    gps_ns = time_ns + GPS_MINUS_UNIX_NS
    true_week, tow_ns = divmod(gps_ns, WEEK_NS)
    assert tow == tow_ns / 1e9 and got_flags == flags
    assert week == min(max(true_week, 0), 0xFFFF)
    assert encoder.saturated.counts.get("gps_timestamp.week", 0) == int(week != true_week)
    (decoded,) = MipDecoder().feed(packet)
    if week == true_week:
        assert decoded.fields["time_ns"] == time_ns                  # exact to the nanosecond


def test_max_packet_size_is_enforced():
    assert MipEncoder(fields=tuple(FIELDS)).bytes_per_sample <= 261
    with pytest.raises(ValueError):
        MipEncoder(fields="accel,bogus")


@pytest.mark.parametrize("field, fields", [("accel", "accel"), ("gyro", "gyro"), ("mag", "mag"),
                                           ("quat", "quaternion"), ("pressure_pa", "pressure"),
                                           ("delta_velocity", "delta_velocity")])
def test_non_finite_input_names_the_field(field, fields):
    n = 3
    data = dict(accel=np.ones((n, 3)), gyro=np.ones((n, 3)), mag=np.ones((n, 3)), quat=np.ones((n, 4)),
                pressure_pa=np.ones(n), delta_velocity=np.ones((n, 3)))
    data[field] = data[field].copy()
    data[field].reshape(n, -1)[1, -1] = np.inf
    with pytest.raises(EncodeError, match=rf"'{field}'.*sample 1"):
        MipEncoder(fields=fields).encode(Samples(np.arange(n, dtype=np.int64), **data))


# --- the stream decoder ------------------------------------------------------------------------

def stream_of(n=15):
    rng = np.random.default_rng(5)
    samples = Samples(np.arange(n, dtype=np.int64) * 10_000_000, rng.normal(size=(n, 3)), rng.normal(size=(n, 3)),
                      mag=rng.normal(size=(n, 3)))
    return MipEncoder().encode(samples)


def test_byte_by_byte_and_other_descriptor_sets():
    batch = stream_of()
    reply = bytes([0x75, 0x65, 0x01, 0x04, 0x04, 0xF1, 0x01, 0x00])      # base command ACK (ping), set 0x01
    reply += bytes(spec_fletcher(reply))
    stream = batch.data + reply
    decoder = MipDecoder()
    packets = [p for b in stream for p in decoder.feed(bytes([b]))]
    assert [p.raw for p in packets[:-1]] == [batch.packet(i) for i in range(len(batch))]
    assert packets[-1].kind == "mip" and packets[-1].fields == {"descriptor_set": 0x01,
                                                                 "fields": [(0xF1, b"\x01\x00")]}
    assert decoder.stats.packets == len(batch) + 1 and decoder.stats.skipped_bytes == 0


def test_corrupted_packet_is_counted_and_the_rest_survive():
    batch = stream_of(4)
    data = bytearray(batch.data)
    data[int(batch.offsets[1]) + 20] ^= 0x80
    decoder = MipDecoder()
    packets = decoder.feed(bytes(data))
    assert [p.raw for p in packets] == [batch.packet(i) for i in (0, 2, 3)]
    assert decoder.stats.bad_checksum == 1 and decoder.stats.skipped_bytes == len(batch.packet(1))


@SETTINGS
@given(st.lists(st.binary(max_size=40).map(lambda b: b.replace(b"\x75", b"")), min_size=16, max_size=16),
       st.integers(1, 120))
def test_garbage_between_packets_is_skipped(garbage, cut):
    batch = stream_of()
    stream = b"".join(garbage[i] + batch.packet(i) for i in range(len(batch))) + garbage[-1]
    decoder = MipDecoder()
    packets = [p for k in range(0, len(stream), cut) for p in decoder.feed(stream[k:k + cut])]
    assert [p.raw for p in packets] == [batch.packet(i) for i in range(len(batch))]
    assert decoder.stats.skipped_bytes == sum(len(g) for g in garbage) and decoder.stats.bad_checksum == 0


@SETTINGS
@given(st.lists(st.one_of(st.binary(max_size=60), st.just(b"\x75\x65\x80"), st.integers(0, 14)), max_size=40),
       st.integers(0, 2 ** 32 - 1))
def test_fuzz_never_raises_never_yields_bad_checksum(parts, seed):
    stream = damaged_stream(stream_of(), parts, seed)
    decoder = MipDecoder()
    packets = feed_in_chunks(decoder, stream, 29)
    for p in packets:
        assert p.raw[:2] == b"\x75\x65" and spec_fletcher(p.raw[:-2]) == (p.raw[-2], p.raw[-1])
    assert decoder.stats.packets == len(packets)


# --- MicroStrain's own library reads our packets from a pty ------------------------------------

def mscl_packets(data: bytes, n: int) -> list:
    """Our bytes written to a pty that MicroStrain's MSCL reads as an InertialNode: the data packets it parsed."""
    try:
        import mscl
    except ImportError as exc:           # pymscl publishes wheels for some platforms only
        pytest.skip(f"pymscl (MicroStrain's MSCL) does not import here: {exc}")
    master, slave = os.openpty()
    tty.setraw(slave)
    connection = mscl.Connection.Serial(os.ttyname(slave), 921600)
    try:
        node = mscl.InertialNode(connection)
        os.write(master, data)
        received, deadline = [], time.monotonic() + scaled(5.0)
        while len(received) < n and time.monotonic() < deadline:
            received += list(node.getDataPackets(200))
    finally:
        connection.disconnect()
        for fd in (master, slave):
            try:
                os.close(fd)
            except OSError:
                pass
    assert len(received) == n
    return received


def test_pymscl_reads_our_packets_from_a_pty():
    n = 6
    rng = np.random.default_rng(11)
    accel, gyro, mag = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) * 0.1, rng.normal(size=(n, 3)) * 0.3
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    time_ns = unix_of_gps(2345, 100_000 * 10 ** 9) + np.arange(n, dtype=np.int64) * 5_000_000
    samples = Samples(time_ns, accel, gyro, mag=mag, quat=quat, pressure_pa=np.linspace(90_000, 101_000, n))
    data = MipEncoder().encode(samples).data
    received = mscl_packets(data, n)
    for i, packet in enumerate(received):
        assert packet.descriptorSet() == 0x80
        points = {p.channelName(): p for p in packet.data()}
        got = [points[f"scaledAccel{a}"].as_float() for a in "XYZ"]
        assert got == f32(accel[i] / G)
        assert [points[f"scaledGyro{a}"].as_float() for a in "XYZ"] == f32(gyro[i])
        assert [points[f"scaledMag{a}"].as_float() for a in "XYZ"] == f32(mag[i])
        assert points["scaledAmbientPressure"].as_float() == f32([samples.pressure_pa[i] / 100])[0]
        q = points["orientQuaternion"].as_Vector()
        assert [q.as_floatAt(k) for k in range(4)] == f32(quat[i])
        assert points["gpsCorrelTimestampWeekNum"].as_uint16() == 2345
        assert points["gpsCorrelTimestampTow"].as_double() == ((time_ns[i] + GPS_MINUS_UNIX_NS) % WEEK_NS) / 1e9
        assert points["gpsCorrelTimestampFlags"].as_uint16() == 0x1C


def _gnss_and_filter_samples():
    """Three samples: a 3D fix, a 2D fix, no fix; the estimate tracking, aligning, not tracking."""
    rng = np.random.default_rng(5)
    n = 3
    return Samples(
        unix_of_gps(2300, 100_000 * 10 ** 9) + np.arange(n, dtype=np.int64) * 250_000_000, rng.normal(size=(n, 3)),
        rng.normal(size=(n, 3)),
        gnss_llh=np.column_stack((47 + rng.random(n), 8 + rng.random(n), 400 + 100 * rng.random(n))),
        gnss_velocity_ned=rng.normal(size=(n, 3)) * 5, gnss_fix=[3, 2, 0], gnss_satellites=[11, 6, 2],
        gnss_hdop=[0.8, 1.9, 9.0], gnss_vdop=[1.1, 2.5, 9.9], gnss_horizontal_accuracy_m=[0.7, 3.0, 50.0],
        gnss_vertical_accuracy_m=[1.1, 5.0, 80.0], gnss_speed_accuracy_mps=[0.05, 0.3, 9.0],
        position_llh=np.column_stack((47 + rng.random(n), 8 + rng.random(n), 400 + 100 * rng.random(n))),
        velocity_ned=rng.normal(size=(n, 3)) * 5, quat=_unit(rng.normal(size=(n, 4))),
        position_sigma_m=rng.random((n, 3)) * 3, velocity_sigma_mps=rng.random((n, 3)) * 0.2,
        attitude_sigma_rad=rng.random((n, 3)) * 0.05, ins_mode=[2, 1, 0], gnss_age_s=[0.12, 0.0, 1.5])


def _unit(q):
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_pymscl_reads_the_gnss_set_as_the_receivers_solution():
    """data_gnss.h fields by MSCL: position, velocity (speed, ground speed, heading derived), DOPs, fix type
    (MIP: 0 3D, 1 2D, 3 none), satellites, GPS time; valid flags cleared without a fix."""
    from firmware_protocols.wire_formats.microstrain import GNSS_FIELDS
    s = _gnss_and_filter_samples()
    data = MipEncoder(tuple(GNSS_FIELDS), descriptor_set=0x81).encode(s).data
    for i, packet in enumerate(mscl_packets(data, len(s))):
        assert packet.descriptorSet() == 0x81
        p = {d.channelName(): d for d in packet.data()}
        llh, v = s.gnss_llh[i], s.gnss_velocity_ned[i]
        assert [p[k].as_double() for k in ("latitude", "longitude", "heightAboveElipsoid", "heightAboveMSL")] == \
            [llh[0], llh[1], llh[2], llh[2]]
        assert [p[k].as_float() for k in ("horizontalAccuracy", "verticalAccuracy", "speedAccuracy")] == f32(
            [s.gnss_horizontal_accuracy_m[i], s.gnss_vertical_accuracy_m[i], s.gnss_speed_accuracy_mps[i]])
        assert [p[f"{a}Velocity"].as_float() for a in ("north", "east", "down")] == f32(v)
        assert p["speed"].as_float() == f32([np.linalg.norm(v)])[0]
        assert p["groundSpeed"].as_float() == f32([np.hypot(v[0], v[1])])[0]
        assert p["heading"].as_float() == f32([np.degrees(np.arctan2(v[1], v[0])) % 360.0])[0]
        assert [p[k].as_float() for k in ("horizontalDOP", "verticalDOP")] == f32([s.gnss_hdop[i], s.gnss_vdop[i]])
        assert p["positionDOP"].as_float() == f32([np.hypot(s.gnss_hdop[i], s.gnss_vdop[i])])[0]
        assert p["positionDOP"].valid() and not p["geometricDOP"].valid()     # only h, v (and p) are known
        assert p["gnssFixType"].as_uint8() == {3: 0, 2: 1, 0: 3}[int(s.gnss_fix[i])]
        assert p["gnssFixSvCount"].as_uint8() == s.gnss_satellites[i]
        fixed = s.gnss_fix[i] >= 2
        assert p["latitude"].valid() == p["northVelocity"].valid() == p["headingAccuracy"].valid() == fixed
        assert p["gpsTimeWeekNum"].as_uint16() == 2300
        # the solution's time of validity: the sample time less its age
        assert p["gpsTimeTow"].as_double() == \
            ((s.time_ns[i] - round(s.gnss_age_s[i] * 1e9) + GPS_MINUS_UNIX_NS) % WEEK_NS) / 1e9


@pytest.mark.parametrize("family, states", [("gq7", (4, 1, 1)), ("gx5", (2, 1, 0))])
def test_pymscl_reads_the_filter_set_as_the_estimate(family, states):
    """data_filter.h fields by MSCL: the estimate, its 1-sigma uncertainties, and the filter state each family
    reports for tracking / aligning / not tracking (GQ7 4 full navigation, 1 initialising; GX5 2 running with a
    valid solution, 1 initialization, 0 startup); a solution is flagged valid only while tracking."""
    from firmware_protocols.wire_formats.microstrain import FILTER_FIELDS
    s = _gnss_and_filter_samples()
    data = MipEncoder(tuple(FILTER_FIELDS), descriptor_set=0x82, filter_family=family).encode(s).data
    for i, packet in enumerate(mscl_packets(data, len(s))):
        assert packet.descriptorSet() == 0x82
        p = {d.channelName(): d for d in packet.data()}
        assert [p[k].as_double() for k in ("estLatitude", "estLongitude", "estHeightAboveElipsoid")] == \
            list(s.position_llh[i])
        assert [p[f"est{a}Velocity"].as_float() for a in ("North", "East", "Down")] == f32(s.velocity_ned[i])
        q = p["estOrientQuaternion"].as_Vector()
        assert [q.as_floatAt(k) for k in range(4)] == f32(s.quat[i])
        assert [p[f"est{a}PositionUncert"].as_float() for a in ("North", "East", "Down")] == f32(s.position_sigma_m[i])
        assert [p[f"est{a}VelocityUncert"].as_float() for a in ("North", "East", "Down")] == \
            f32(s.velocity_sigma_mps[i])
        assert [p[f"est{a}Uncert"].as_float() for a in ("Roll", "Pitch", "Yaw")] == f32(s.attitude_sigma_rad[i])
        assert p["estFilterState"].as_uint16() == states[i]
        assert p["estLatitude"].valid() == p["estRollUncert"].valid() == (s.ins_mode[i] == 2)


def test_our_decoder_reads_the_gnss_and_filter_sets_back():
    """The decoder's "values" of the GNSS and filter sets equal what the encoder was given (float32 on the wire)."""
    from firmware_protocols.wire_formats.microstrain import FILTER_FIELDS, GNSS_FIELDS
    s = _gnss_and_filter_samples()
    data = (MipEncoder(tuple(GNSS_FIELDS), descriptor_set=0x91).encode(s).data
            + MipEncoder(tuple(FILTER_FIELDS), descriptor_set=0x82).encode(s).data)
    packets = MipDecoder().feed(data)
    assert [p.fields["descriptor_set"] for p in packets] == [0x91] * 3 + [0x82] * 3
    for i, p in enumerate(packets[:3]):
        v = p.fields["values"]
        assert v["position_llh"][:4] == (*s.gnss_llh[i], s.gnss_llh[i][2])
        assert list(v["velocity_ned"][:3]) == f32(s.gnss_velocity_ned[i])
        assert v["fix_info"][:2] == ({3: 0, 2: 1, 0: 3}[int(s.gnss_fix[i])], s.gnss_satellites[i])
    for i, p in enumerate(packets[3:]):
        v = p.fields["values"]
        assert v["position_llh"] == (*s.position_llh[i], int(s.ins_mode[i] == 2))
        assert list(v["position_uncertainty"][:3]) == f32(s.position_sigma_m[i])
        assert v["status"] == ((4, 1, 1)[i], 1, 0)


def test_gps_week_offset_is_retired_with_one_line_naming_start_time():
    for make in (lambda: MipEncoder(gps_week_offset=2300), lambda: MipDecoder(gps_week_offset=2300)):
        with pytest.raises(ValueError, match="--start-time") as err:
            make()
        assert "\n" not in str(err.value)
