"""Xsens MTData2: the recorded MTi-300 packet from the wire-formats spec, and our packets read back by a
decoder written here from the spec (struct, big-endian), independent of firmware_protocols.wire_formats.xsens."""
import itertools
import math
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware_protocols import registry
from firmware_protocols.base import EncodeError, Samples
from firmware_protocols.wire_formats.xsens import ITEMS, XsensDecoder, XsensEncoder
from tests.support.stream_fuzz import damaged_stream, feed_in_chunks

SETTINGS = settings(derandomize=True, deadline=None, max_examples=60,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
F32_MAX = float(np.finfo(np.float32).max)

# wire-formats.md, "Xsens MTi (MTData2)": a packet recorded by MT Manager from an MTi-300.
RECORDED_MTI300 = bytes.fromhex(
    "faff368b102002a6551060040057472e2010103f7f7dc4bc10107d3ba15770bd7ec65640200cbda21af8be2a8e96411d27a240"
    "100cb94fc800b9da24003cc9288040300c3c02c89c3c35f6c83cdb0c0080200cbbb17d81bb9632003c01e8418030103f8000"
    "00b6e33001b6c0400037264800c0200cbe999c243fb61b563f166aeb301004000186dee02004004000038b")
# Its items in wire order, read off the published bytes: PacketCounter, SampleTimeFine, Quaternion,
# Acceleration, DeltaV, FreeAcceleration, RateOfTurn, DeltaQ, MagneticField, BaroPressure, StatusWord.
RECORDED_XDIS = [0x1020, 0x1060, 0x2010, 0x4020, 0x4010, 0x4030, 0x8020, 0x8030, 0xC020, 0x3010, 0xE020]

COMMON = dict(time_ns=1_234_567_000, accel=[0.1, -0.2, -9.80665], gyro=[0.01, -0.02, 0.03], mag=[0.21, 0.01, -0.42])
ALL_ITEMS = tuple(ITEMS)
# Samples are forward-right-down; the MTi's sensor frame is x forward, y left, z up (MT0605P.E §4.2): on the
# wire a vector's y and z change sign (firmware_protocols.axes), and the attitude is that frame's.
FLU = np.array([1.0, -1.0, -1.0])


def common_sample(**extra):
    return Samples.single(COMMON["time_ns"], COMMON["accel"], COMMON["gyro"], mag=COMMON["mag"], **extra)


# --- an independent reader, from the spec ------------------------------------------------------

def spec_frame(packet: bytes):
    """(mid, payload) of one Xbus frame; asserts the framing and checksum rules of the spec."""
    assert packet[0] == 0xFA and packet[1] == 0xFF
    assert sum(packet[1:]) % 256 == 0, "byte sum FF..checksum must be 0 mod 256"
    if packet[3] == 0xFF:
        (length,) = struct.unpack(">H", packet[4:6])
        assert length > 254
        payload = packet[6:-1]
    else:
        length = packet[3]
        payload = packet[4:-1]
    assert len(payload) == length
    return packet[2], payload


def spec_items(payload: bytes):
    items, k = [], 0
    while k < len(payload):
        xdi, size = struct.unpack(">HB", payload[k:k + 3])
        items.append((xdi, payload[k + 3:k + 3 + size]))
        k += 3 + size
    assert k == len(payload)
    return items


def spec_reals(data: bytes, precision: int):
    if precision == 0:
        return list(struct.unpack(f">{len(data) // 4}f", data))
    if precision == 3:
        return list(struct.unpack(f">{len(data) // 8}d", data))
    if precision == 1:
        return [v / 2 ** 20 for v in struct.unpack(f">{len(data) // 4}i", data)]
    values = []
    for k in range(0, len(data), 6):      # 16.32: 4-byte fraction first, then the 2-byte integer part
        frac, whole = struct.unpack(">Ih", data[k:k + 6])
        values.append((whole * 2 ** 32 + frac) / 2 ** 32)
    return values


def as_wire(value, precision):
    """What the spec's representation keeps of an SI value (round to nearest)."""
    if precision == 0:
        return float(np.float32(value))
    if precision == 3:
        return float(value)
    lsb = 2.0 ** -20 if precision == 1 else 2.0 ** -32
    return round(value / lsb) * lsb


# --- the recorded MTi-300 packet ---------------------------------------------------------------

def test_recorded_packet_checksum_and_xdis():
    assert sum(RECORDED_MTI300[1:]) % 256 == 0
    mid, payload = spec_frame(RECORDED_MTI300)
    assert mid == 0x36
    assert [xdi for xdi, _ in spec_items(payload)] == RECORDED_XDIS
    decoder = XsensDecoder()
    (packet,) = decoder.feed(RECORDED_MTI300)
    assert packet.kind == "mtdata2"
    assert packet.fields["xdis"] == RECORDED_XDIS
    assert decoder.stats.packets == 1 and decoder.stats.bad_checksum == 0 and decoder.stats.skipped_bytes == 0


def test_recorded_packet_values_are_plausible():
    (packet,) = XsensDecoder().feed(RECORDED_MTI300)
    f = packet.fields
    assert 9.7 < np.linalg.norm(f["accel"]) < 9.9                     # a device at rest
    assert abs(np.linalg.norm(f["quat"]) - 1.0) < 1e-5
    assert abs(np.linalg.norm(f["delta_q"]) - 1.0) < 1e-5
    assert np.linalg.norm(f["gyro"]) < 0.05                            # rad/s: nearly still
    # DeltaV is acceleration integrated over one output period (400 Hz on an MTi-300).
    assert np.allclose(np.asarray(f["delta_velocity"]) * 400, f["accel"], atol=0.05)
    assert 80_000 < f["pressure_pa"] < 110_000
    assert f["sample_time_fine"] * 100_000 == f["time_ns"]
    assert 0 < np.linalg.norm(f["mag_au"]) < 3                         # normalised units, about 1
    assert f["frame"] == "ENU" and f["precision"]["acceleration"] == "float32"


# --- our packets, read by the spec reader ------------------------------------------------------

@pytest.mark.parametrize("precision, bits", [("float32", 0), ("fp1220", 1), ("fp1632", 2), ("float64", 3)])
def test_common_sample_read_by_spec_decoder(precision, bits):
    encoder = XsensEncoder(items=("packet_counter", "sample_time_fine", "acceleration", "rate_of_turn",
                                  "magnetic_field", "temperature", "baro_pressure", "status_word"),
                           precision=precision, mag_reference_gauss=0.5, status_word=0x00400003,
                           packet_counter_start=7)
    packet = encoder.encode(common_sample(temperature_c=21.5, pressure_pa=100_062.4)).packet(0)
    assert len(packet) == encoder.bytes_per_sample
    mid, payload = spec_frame(packet)
    assert mid == 0x36
    items = dict(spec_items(payload))
    assert list(items) == [0x1020, 0x1060, 0x4020 | bits, 0x8020 | bits, 0xC020 | bits, 0x0810 | bits, 0x3010, 0xE020]
    assert struct.unpack(">H", items[0x1020]) == (7,)
    assert struct.unpack(">I", items[0x1060]) == (COMMON["time_ns"] // 100_000,)    # 10 kHz ticks
    assert spec_reals(items[0x4020 | bits], bits) == [as_wire(v, bits) for v in COMMON["accel"] * FLU]
    assert spec_reals(items[0x8020 | bits], bits) == [as_wire(v, bits) for v in COMMON["gyro"] * FLU]
    assert spec_reals(items[0xC020 | bits], bits) == [as_wire(v / 0.5, bits) for v in COMMON["mag"] * FLU]
    assert spec_reals(items[0x0810 | bits], bits) == [as_wire(21.5, bits)]
    assert struct.unpack(">I", items[0x3010]) == (100_062,)
    assert struct.unpack(">I", items[0xE020]) == (0x00400003,)


# Coordinates in each declared frame of NED vectors: ENU swaps north and east and negates down; NWU negates
# east and down.
_FROM_NED = {"NED": np.eye(3), "ENU": np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]]),
             "NWU": np.diag([1, -1, -1])}


@pytest.mark.parametrize("frame, bits", [("ENU", 0x0), ("NED", 0x4), ("NWU", 0x8)])
def test_frame_bits_declared_on_orientation_and_attitude_expressed_in_that_frame(frame, bits):
    """Samples carry FRD -> NED attitude; the packet declares its frame and must carry the attitude of the MTi's
    forward-left-up sensor frame referenced to it: R_frame = C_frame<-NED R_ned C_FRD<-FLU, the last a half
    turn about x (scipy's Rotation as the oracle, Euler z-y-x from it)."""
    from scipy.spatial.transform import Rotation
    encoder = XsensEncoder(items="quaternion,euler_angles,acceleration", precision="float64", frame=frame)
    ned = Rotation.from_euler("ZYX", [3.0, -0.2, 0.1])
    x, y, z, w = ned.as_quat()
    packet = encoder.encode(Samples.single(0, [0, 0, 9.8], [0, 0, 0], quat=[w, x, y, z],
                                           euler=[0.1, -0.2, 3.0])).packet(0)
    items = dict(spec_items(spec_frame(packet)[1]))
    assert list(items) == [0x2013 | bits, 0x2033 | bits, 0x4023]
    want = Rotation.from_matrix(_FROM_NED[frame]) * ned * Rotation.from_rotvec([math.pi, 0.0, 0.0])
    qw, qx, qy, qz = spec_reals(items[0x2013 | bits], 3)                             # w first
    assert (want.inv() * Rotation.from_quat([qx, qy, qz, qw])).magnitude() < 1e-12
    yaw, pitch, roll = want.as_euler("ZYX")
    assert spec_reals(items[0x2033 | bits], 3) == pytest.approx([math.degrees(v) for v in (roll, pitch, yaw)])
    (decoded,) = XsensDecoder().feed(packet)
    assert decoded.fields["frame"] == frame
    assert decoded.fields["euler"] == pytest.approx((roll, pitch, yaw))


def test_extended_length_when_payload_exceeds_254():
    encoder = XsensEncoder(items=ALL_ITEMS, precision="float64")
    samples = common_sample(quat=[1, 0, 0, 0], delta_theta=[1e-3, 2e-3, -3e-3], delta_velocity=[0.01, 0, 0.02])
    packet = encoder.encode(samples).packet(0)
    assert packet[3] == 0xFF
    mid, payload = spec_frame(packet)
    assert len(payload) > 254 and len(packet) == 6 + len(payload) + 1 == encoder.bytes_per_sample
    items = dict(spec_items(payload))
    theta = np.array([1e-3, 2e-3, -3e-3]) * FLU
    angle = np.linalg.norm(theta)
    expected_dq = [math.cos(angle / 2), *(np.sin(angle / 2) * theta / angle)]
    assert spec_reals(items[0x8033], 3) == pytest.approx(expected_dq, abs=1e-15)
    (decoded,) = XsensDecoder().feed(packet)
    assert decoded.fields["xdis"] == list(items)


def test_length_form_switches_between_254_and_255():
    item_bytes = {name: XsensEncoder(items=(name,), precision="float64").bytes_per_sample - 5 for name in ALL_ITEMS}
    found = {}
    for r in range(1, len(ALL_ITEMS) + 1):
        for combo in itertools.combinations(ALL_ITEMS, r):
            found.setdefault(sum(item_bytes[n] for n in combo), combo)
    assert {254, 255} <= set(found)
    short = XsensEncoder(items=found[254], precision="float64").encode(common_sample()).packet(0)
    assert short[3] == 254 and len(short) == 4 + 254 + 1
    long = XsensEncoder(items=found[255], precision="float64").encode(common_sample()).packet(0)
    assert long[3:6] == b"\xff\x00\xff" and len(long) == 6 + 255 + 1
    for packet in (short, long):
        spec_frame(packet)
        assert len(XsensDecoder().feed(packet)) == 1


def test_packet_counter_wraps_across_calls():
    encoder = XsensEncoder(items=("packet_counter",), packet_counter_start=65533)
    counters = []
    for n in (2, 3, 1):
        batch = encoder.encode(Samples(np.zeros(n, np.int64), np.zeros((n, 3)), np.zeros((n, 3))))
        counters += [struct.unpack(">H", spec_items(spec_frame(batch.packet(i))[1])[0][1])[0] for i in range(n)]
    assert counters == [65533, 65534, 65535, 0, 1, 2]


def test_registry_entry():
    info = registry._REGISTRY["xsens-mtdata2"]
    assert info.kind == "serial" and info.encoder is XsensEncoder and info.decoder is XsensDecoder
    assert info.bytes_per_sample == XsensEncoder().bytes_per_sample == 4 + 5 + 7 + 15 + 15 + 1
    assert {"items", "precision", "frame", "mag_reference_gauss"} <= set(info.options)


# --- round trips over each field's full range ------------------------------------------------

any_double = st.floats(allow_nan=False, allow_infinity=False)


@SETTINGS
@given(st.lists(st.tuples(any_double, any_double, any_double), min_size=1, max_size=8),
       st.sampled_from(["float32", "float64"]))
def test_float_round_trip_and_saturation(vectors, precision):
    accel = np.array(vectors)
    n = len(accel)
    gyro = accel[::-1].copy()
    encoder = XsensEncoder(items="acceleration,rate_of_turn", precision=precision)
    batch = encoder.encode(Samples(np.arange(n, dtype=np.int64), accel, gyro))
    limit = F32_MAX if precision == "float32" else np.finfo(np.float64).max
    expect_accel = np.clip(accel * FLU, -limit, limit).astype(np.float32 if precision == "float32" else np.float64)
    expect_gyro = np.clip(gyro * FLU, -limit, limit).astype(expect_accel.dtype)
    packets = XsensDecoder().feed(batch.data)
    assert len(packets) == n
    for i, p in enumerate(packets):
        assert p.fields["accel"] == tuple(float(v) for v in expect_accel[i])
        assert p.fields["gyro"] == tuple(float(v) for v in expect_gyro[i])
    over = int(np.count_nonzero(np.abs(accel) > limit))
    assert encoder.saturated.counts.get("acceleration", 0) == over
    assert encoder.saturated.counts.get("rate_of_turn", 0) == over


@SETTINGS
@given(st.lists(st.floats(-70_000, 70_000), min_size=3, max_size=3), st.sampled_from(["fp1220", "fp1632"]))
def test_fixed_point_round_trip_and_saturation(values, precision):
    bits, frac = (1, 20) if precision == "fp1220" else (2, 32)
    width = 32 if precision == "fp1220" else 48
    encoder = XsensEncoder(items=("acceleration",), precision=precision)
    packet = encoder.encode(Samples.single(0, values, [0, 0, 0])).packet(0)
    raw = [round(v * 2 ** frac) for v in values * FLU]
    lo, hi = -2 ** (width - 1), 2 ** (width - 1) - 1
    expected = [min(max(r, lo), hi) / 2 ** frac for r in raw]
    items = dict(spec_items(spec_frame(packet)[1]))
    assert spec_reals(items[0x4020 | bits], bits) == expected
    assert encoder.saturated.counts.get("acceleration", 0) == sum(not lo <= r <= hi for r in raw)
    (decoded,) = XsensDecoder().feed(packet)
    assert decoded.fields["accel"] == tuple(expected)


@SETTINGS
@given(st.integers(-2 ** 63, 2 ** 63 - 1), st.floats(-1e12, 1e12), st.floats(1e-3, 10.0))
def test_integer_items_and_time_round_trip(time_ns, pressure, mag_reference):
    encoder = XsensEncoder(items="sample_time_fine,sample_time_coarse,baro_pressure,magnetic_field",
                           precision="float64", mag_reference_gauss=mag_reference)
    packet = encoder.encode(Samples.single(time_ns, [0, 0, 0], [0, 0, 0], pressure_pa=pressure,
                                           mag=[0.2, -0.1, 0.45])).packet(0)
    items = dict(spec_items(spec_frame(packet)[1]))
    assert struct.unpack(">I", items[0x1060])[0] == (time_ns // 100_000) % 2 ** 32        # wraps like the device
    assert struct.unpack(">I", items[0x1070])[0] == (time_ns // 1_000_000_000) % 2 ** 32
    expected_pa = min(max(round(pressure), 0), 2 ** 32 - 1)
    assert struct.unpack(">I", items[0x3010])[0] == expected_pa
    assert encoder.saturated.counts.get("baro_pressure", 0) == int(expected_pa != round(pressure))
    (decoded,) = XsensDecoder(mag_reference_gauss=mag_reference).feed(packet)
    assert decoded.fields["mag"] == pytest.approx((0.2, 0.1, -0.45), rel=1e-15)
    assert decoded.fields["pressure_pa"] == expected_pa


# --- bad input ---------------------------------------------------------------------------------

@pytest.mark.parametrize("field, items", [("accel", "acceleration"), ("gyro", "rate_of_turn_hr"),
                                          ("mag", "magnetic_field"), ("quat", "quaternion"),
                                          ("delta_theta", "delta_q"), ("temperature_c", "temperature")])
def test_non_finite_input_names_the_field(field, items):
    n = 4
    data = dict(accel=np.ones((n, 3)), gyro=np.ones((n, 3)), mag=np.ones((n, 3)), quat=np.ones((n, 4)),
                delta_theta=np.ones((n, 3)), temperature_c=np.ones(n))
    data[field] = data[field].copy()
    data[field].reshape(n, -1)[2, 0] = np.nan
    encoder = XsensEncoder(items=items)
    with pytest.raises(EncodeError, match=rf"'{field}'.*sample 2"):
        encoder.encode(Samples(np.arange(n, dtype=np.int64), **data))
    assert encoder.packet_counter == 0          # nothing was sent, so the counter did not move


def test_bad_options_are_refused():
    for kwargs in ({"items": "acceleration,bogus"}, {"precision": "float16"}, {"frame": "XYZ"},
                   {"mag_reference_gauss": 0}, {"items": "acceleration,acceleration"}):
        with pytest.raises(ValueError):
            XsensEncoder(**kwargs)
    # options arrive as strings from a command line
    encoder = XsensEncoder(items="acceleration, status_word", status_word="0x400003", precision="float64",
                           mag_reference_gauss="0.45", frame="ned")
    assert (encoder.status_word, encoder.mag_reference_gauss, encoder.frame) == (0x400003, 0.45, "NED")


# --- the stream decoder ------------------------------------------------------------------------

def stream_of(n=20):
    encoder = XsensEncoder(items="packet_counter,sample_time_fine,quaternion,acceleration,rate_of_turn")
    rng = np.random.default_rng(3)
    samples = Samples(np.arange(n, dtype=np.int64) * 2_500_000, rng.normal(size=(n, 3)), rng.normal(size=(n, 3)))
    return encoder.encode(samples)


def test_byte_by_byte_equals_whole():
    batch = stream_of()
    whole = XsensDecoder().feed(batch.data)
    decoder = XsensDecoder()
    pieces = [p for b in batch.data for p in decoder.feed(bytes([b]))]
    assert [p.raw for p in pieces] == [p.raw for p in whole] == [batch.packet(i) for i in range(len(batch))]
    assert decoder.stats.skipped_bytes == 0


def test_corrupted_packet_is_counted_and_the_rest_survive():
    batch = stream_of(5)
    data = bytearray(batch.data)
    data[int(batch.offsets[2]) + 10] ^= 0x01
    decoder = XsensDecoder()
    packets = decoder.feed(bytes(data))
    assert [p.fields["packet_counter"] for p in packets] == [0, 1, 3, 4]
    assert decoder.stats.bad_checksum == 1
    assert decoder.stats.skipped_bytes == len(batch.packet(2))


def test_other_xbus_messages_pass_as_raw():
    ack = bytes([0xFA, 0xFF, 0x31, 0x00, 0xD0])       # GoToConfigAck, no data
    (packet,) = XsensDecoder().feed(ack)
    assert packet.kind == "xbus" and packet.fields == {"mid": 0x31, "data": b""}


@SETTINGS
@given(st.lists(st.binary(max_size=40).map(lambda b: b.replace(b"\xfa", b"")), min_size=21, max_size=21),
       st.lists(st.integers(1, 97), min_size=1, max_size=30))
def test_garbage_between_packets_is_skipped(garbage, cuts):
    batch = stream_of()
    stream = b"".join(garbage[i] + batch.packet(i) for i in range(len(batch))) + garbage[-1]
    decoder = XsensDecoder()
    packets, k = [], 0
    for cut in cuts * 50:
        packets += decoder.feed(stream[k:k + cut])
        k += cut
        if k >= len(stream):
            break
    packets += decoder.feed(stream[k:])
    assert [p.raw for p in packets] == [batch.packet(i) for i in range(len(batch))]
    assert decoder.stats.skipped_bytes == sum(len(g) for g in garbage)
    assert decoder.stats.bad_checksum == 0


@SETTINGS
@given(st.lists(st.one_of(st.binary(max_size=60), st.sampled_from([b"\xfa\xff", b"\xfa\xff\x36\xff",
                                                                   b"\xfa\xff\x36\xff\x01\x00"]),
                          st.integers(0, 19)), max_size=40),
       st.integers(0, 2 ** 32 - 1))
def test_fuzz_never_raises_never_yields_bad_checksum(parts, flip_seed):
    stream = damaged_stream(stream_of(), parts, flip_seed)
    decoder = XsensDecoder()
    packets = feed_in_chunks(decoder, stream, 37)
    for p in packets:
        assert p.raw[0] == 0xFA and sum(p.raw[1:]) % 256 == 0
    assert decoder.stats.packets == len(packets)


# --- MagneticField, BaroPressure and GnssPvtData as ArduPilot reads them -------------------------------------
# ArduPilot/ardupilot libraries/AP_ExternalAHRS/AP_ExternalAHRS_Xsens.cpp at 1056c40f8f57ad5fbb5620a7c293318f2b8471ab:
# parse_mtdata2 (XDI u16, size u8; MAGNETIC_FIELD 0xC020 three big-endian floats when size 12, BAROMETRIC_PRESSURE
# 0x3010 u32 when size 4), parse_gnss_pvt_data (size 94, the fields in this order) and convert_fix_type.
_AP_PVT = struct.Struct(">IHBBBBBBIiBBBBiiiiIIiiiiiIIiHHHHHHH")
_AP_PVT_NAMES = ("iTOW year month day hour min sec valid tAcc nano fixType flags numSv reserved lon lat height hMSL "
                 "hAcc vAcc velN velE velD gSpeed headMot sAcc headAcc headVeh gDop pDop tDop vDop hDop nDop eDop").split()
AP_FIX_NONE, AP_FIX_2D, AP_FIX_3D = 1, 2, 3       # AP_GPS_FixType


def ap_parse_mtdata2(frame: bytes) -> dict:
    assert frame[0] == 0xFA and frame[1] == 0xFF and frame[2] == 0x36 and sum(frame[1:]) & 0xFF == 0
    payload, index, data = frame[4:4 + frame[3]], 0, {}
    while index + 3 <= len(payload):
        xdi, size = struct.unpack_from(">HB", payload, index)
        index += 3
        if xdi == 0xC020 and size == 12:
            data["magneticField"] = struct.unpack_from(">3f", payload, index)
        elif xdi == 0x3010 and size == 4:
            data["barometricPressure"] = struct.unpack_from(">I", payload, index)[0]
        elif xdi == 0x7010 and size == 94:
            data["gnssPvtData"] = dict(zip(_AP_PVT_NAMES, _AP_PVT.unpack_from(payload, index)))
        index += size
    return data


def ap_convert_fix_type(fix_type: int, flags: int) -> int:
    if fix_type == 2:
        return AP_FIX_2D
    if fix_type in (3, 4):
        return AP_FIX_3D if fix_type == 4 or not flags & 0b11000010 else None   # (DGPS / RTK: not sent here)
    return AP_FIX_NONE


def test_mag_baro_and_gnss_pvt_read_as_ardupilot_does():
    """The samples' magnetic field (over mag_reference_gauss), static pressure and GNSS receiver solution, read back
    by ArduPilot's parser: a 3D fix, a 2D fix and none, each with its own accuracies, DOPs and satellites."""
    rng = np.random.default_rng(8)
    n = 3
    samples = Samples(
        1_700_000_000 * 10 ** 9 + np.arange(n, dtype=np.int64) * 250_000_000, rng.normal(size=(n, 3)),
        rng.normal(size=(n, 3)), mag=rng.normal(size=(n, 3)) * 0.3, pressure_pa=[101_325.4, 95_000.6, 89_874.2],
        gnss_llh=np.column_stack((47 + rng.random(n), 8 + rng.random(n), 400 + 100 * rng.random(n))),
        gnss_velocity_ned=rng.normal(size=(n, 3)) * 5, gnss_fix=[3, 2, 0], gnss_satellites=[14, 5, 1],
        gnss_hdop=[0.7, 2.2, 9.0], gnss_vdop=[1.2, 3.1, 9.9], gnss_horizontal_accuracy_m=[0.6, 4.0, 60.0],
        gnss_vertical_accuracy_m=[1.0, 6.0, 90.0], gnss_speed_accuracy_mps=[0.04, 0.5, 7.0],
        position_llh=[[10.0, 20.0, 30.0]] * n)          # the estimate: GnssPvtData must not take it
    reference = 0.49                                    # ArduPilot's comment: "1 a.u = 0.49Gauss"
    encoder = XsensEncoder(("magnetic_field", "baro_pressure", "gnss_pvt_data"), mag_reference_gauss=reference)
    batch = encoder.encode(samples)
    for i in range(n):
        data = ap_parse_mtdata2(batch.packet(i))
        # the MTi's sensor frame is forward-left-up (Samples are FRD): the encoder turns the field at its edge
        assert list(data["magneticField"]) == [float(np.float32(v / reference)) for v in samples.mag[i] * FLU]
        assert data["barometricPressure"] == round(samples.pressure_pa[i])
        pvt = data["gnssPvtData"]
        llh, v = samples.gnss_llh[i], samples.gnss_velocity_ned[i]
        assert (pvt["lat"], pvt["lon"]) == (round(llh[0] * 1e7), round(llh[1] * 1e7))
        assert pvt["height"] == pvt["hMSL"] == round(llh[2] * 1e3)
        assert (pvt["velN"], pvt["velE"], pvt["velD"]) == tuple(round(c * 1e3) for c in v)
        assert ap_convert_fix_type(pvt["fixType"], pvt["flags"]) == {3: AP_FIX_3D, 2: AP_FIX_2D, 0: AP_FIX_NONE}[
            int(samples.gnss_fix[i])]
        assert pvt["flags"] & 1 == (samples.gnss_fix[i] >= 2)              # gnssFixOK
        assert pvt["numSv"] == samples.gnss_satellites[i]
        assert pvt["hAcc"] == round(samples.gnss_horizontal_accuracy_m[i] * 1e3)
        assert pvt["vAcc"] == round(samples.gnss_vertical_accuracy_m[i] * 1e3)
        assert pvt["sAcc"] == round(samples.gnss_speed_accuracy_mps[i] * 1e3)
        assert (pvt["hDop"], pvt["vDop"]) == (round(samples.gnss_hdop[i] * 100), round(samples.gnss_vdop[i] * 100))
        # the seven DOPs stay consistent: h^2 = n^2 + e^2, p^2 = h^2 + v^2, g^2 = p^2 + t^2, each rounded to the
        # 0.01 wire step (so a side differs by at most 0.005 + 0.005 * sqrt 2 < 0.013)
        d = {k: pvt[k] / 100 for k in ("gDop", "pDop", "tDop", "vDop", "hDop", "nDop", "eDop")}
        assert d["hDop"] == pytest.approx(math.hypot(d["nDop"], d["eDop"]), abs=0.013)
        assert d["pDop"] == pytest.approx(math.hypot(d["hDop"], d["vDop"]), abs=0.013)
        assert d["gDop"] == pytest.approx(math.hypot(d["pDop"], d["tDop"]), abs=0.013)
