"""VectorNav binary and ASCII output, checked against published packets (the wire-formats spec vector,
VectorNav's own library example, ArduPilot's fixed headers, a real VN-200 line) and against checksums
computed here independently of firmware_protocols.crc."""
import binascii
import struct
from functools import reduce

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware_protocols import registry
from firmware_protocols.base import EncodeError, Samples
from firmware_protocols.devices.vectornav import VectorNavDevice
from firmware_protocols.wire_formats.vectornav_ascii import AsciiDecoder, AsciiEncoder
from firmware_protocols.wire_formats.vectornav_binary import _BY_NAME, BinaryDecoder, BinaryEncoder, parse_fields

SETTINGS = settings(derandomize=True, deadline=None, max_examples=60,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
F32_MAX = float(np.finfo(np.float32).max)

# Spec common sample and vector (wire-formats.md, "VectorNav binary output").
SPEC_SAMPLE = Samples.single(1_234_567_000, [0.1, -0.2, -9.80665], [0.01, -0.02, 0.03], mag=[0.21, 0.01, -0.42])
SPEC_VECTOR = "fa060100000658ff954900000000cdcccc3dcdcc4cbe0ae81cc10ad7233c0ad7a3bc8fc2f53cac83"
# VectorNav programming library, examples/uart protocol (dawonn/vectornav): a Common TimeStartup|YawPitchRoll
# packet and an ASCII $VNYMR line the library's parser accepts.
VN_LIB_BINARY = bytes([0xFA, 0x01, 0x09, 0x00, 0x70, 0x05, 0x00, 0x03, 0x0A, 0x00, 0x00, 0x00, 0x48, 0x0E, 0x2C,
                       0x42, 0x08, 0x4C, 0x37, 0xC1, 0x10, 0x38, 0x8B, 0xC2, 0xD4, 0xCB])
VN_LIB_YMR = (b"$VNYMR,+100.949,-007.330,+000.715,-00.0049,-00.2449,+00.5397,-01.258,-00.100,-09.701,"
              b"-00.000018,+00.001122,-00.000551*69\r\n")
# A VN-200's $VNIMU line quoted in a university lab script (its XOR checksum is valid).
VN200_IMU = (b"$VNIMU,-00.0350,+00.4222,-00.6643,-00.015,+00.019,+09.948,+00.002066,-00.008442,-00.044656,"
             b"+20.7,+084.322*66\r\n")



def registered(name):
    """This module's own registry entry. registry.get() would import every sibling format module first,
    so one of them failing to import would fail these tests for reasons that are not theirs."""
    return registry._REGISTRY[name]


ENCODABLE = sorted((g, name) for g, fields in _BY_NAME.items() for name, f in fields.items() if f.quantities)
# The measurement fields (the navigation/status ones, f64/u16 or constants, have their own test).
_MEASURED_SOURCES = {"time_ns", "accel", "gyro", "mag", "quat", "euler", "temperature_c", "pressure_pa"}
MEASURED = [(g, name) for g, name in ENCODABLE
            if all(q.source in _MEASURED_SOURCES for q in _BY_NAME[g][name].quantities)]


def xor8(body: bytes) -> int:
    return reduce(lambda a, b: a ^ b, body, 0)


def split_line(line: bytes):
    assert line.startswith(b"$") and line.endswith(b"\r\n")
    body, _, cs = line[1:-2].partition(b"*")
    return body, cs


# --- binary: published packets --------------------------------------------------------------

def test_spec_vector_byte_for_byte():
    encoder = registered("vectornav-binary").encoder()
    batch = encoder.encode(SPEC_SAMPLE)
    assert batch.data.hex() == SPEC_VECTOR
    assert encoder.bytes_per_sample == len(batch.data) == registered("vectornav-binary").bytes_per_sample


def test_receiver_crc_check():
    packet = BinaryEncoder().encode(SPEC_SAMPLE).packet(0)
    assert binascii.crc_hqx(packet[1:], 0) == 0                       # groups .. crc
    assert packet[-2:] == binascii.crc_hqx(packet[1:-2], 0).to_bytes(2, "big")


def test_decodes_vectornav_library_example_and_reencodes_it():
    decoder = BinaryDecoder()
    [packet] = decoder.feed(VN_LIB_BINARY)
    time_ns, yaw, pitch, roll = struct.unpack_from("<Q3f", VN_LIB_BINARY, 4)
    assert packet.fields["common.timestartup"] == time_ns
    np.testing.assert_allclose(np.degrees(packet.fields["common.yawpitchroll"]), [roll, pitch, yaw], rtol=1e-12)
    again = BinaryEncoder("common:timestartup,yawpitchroll").encode(
        Samples.single(time_ns, [0, 0, 0], [0, 0, 0], euler=packet.fields["common.yawpitchroll"]))
    assert again.data == VN_LIB_BINARY


def test_ardupilot_vn100_layout_matches_its_header_and_length():
    # ArduPilot AP_ExternalAHRS_VectorNav.cpp: vn_ahrs_pkt1_header {0x14, 0x3E, 0x07, 0x04, 0x00},
    # VN_AHRS_PKT1_LENGTH 104.
    encoder = BinaryEncoder("imu:uncompmag,uncompaccel,uncompgyro,temp,pres,mag,accel,angularrate;"
                            "attitude:quaternion")
    packet = encoder.encode(SPEC_SAMPLE).packet(0)
    assert packet[1:6] == bytes([0x14, 0x3E, 0x07, 0x04, 0x00])
    assert len(packet) == encoder.bytes_per_sample == 104


def test_field_order_is_bit_order_whatever_the_spec_order():
    a = parse_fields("imu:angularrate,accel;time:timestartup")
    b = parse_fields({"time": ["TimeStartup"], "imu": 0x0600})
    assert a == b == parse_fields(None)
    assert [f.key for f in a.fields] == ["time.timestartup", "imu.accel", "imu.angularrate"]


@pytest.mark.parametrize("spec, words", [
    ("gnss:timestartup", ["unknown group", "gnss"]),
    ("imu:accel,gyro", ["unknown field", "gyro", "imu"]),
    ("imu accel", ["expected", "imu accel"]),
    ({"imu": 0x8000}, ["mask", "imu"]),
    ("attitude:dcm", ["no data", "attitude.dcm"]),
])
def test_bad_field_selection_names_the_culprit(spec, words):
    with pytest.raises(ValueError) as info:
        BinaryEncoder(spec)
    message = str(info.value)
    assert "\n" not in message and all(w in message for w in words)


# --- binary: round trips --------------------------------------------------------------------

def _expected_wire(value, scale):
    """float32 the encoder must send for one SI component: scaled, clipped at float32 max."""
    with np.errstate(over="ignore"):
        scaled = np.float64(value) * scale
    return np.float32(np.clip(scaled, -F32_MAX, F32_MAX)), bool(abs(scaled) > F32_MAX)


big = st.floats(allow_nan=False, allow_infinity=False)
vec3 = st.lists(st.one_of(big, st.floats(-100, 100), st.sampled_from([F32_MAX, -F32_MAX, 3.5e38, -1e39])),
                min_size=3, max_size=3)


@SETTINGS
@given(selection=st.sets(st.sampled_from(MEASURED), min_size=1, max_size=8),
       time_ns=st.integers(-2**63, 2**63 - 1), accel=vec3, gyro=vec3, mag=vec3, euler=vec3,
       quat=st.lists(big, min_size=4, max_size=4), temp=big, pres=big,
       chunk=st.integers(1, 64))
def test_binary_round_trip_any_layout(selection, time_ns, accel, gyro, mag, euler, quat, temp, pres, chunk):
    spec = {}
    for group, name in selection:
        spec.setdefault(group, []).append(name)
    encoder = BinaryEncoder(spec)
    samples = Samples.single(time_ns, accel, gyro, mag=mag, euler=euler, quat=quat, temperature_c=temp,
                             pressure_pa=pres)
    data = encoder.encode(samples).data
    assert len(data) == encoder.bytes_per_sample

    decoder = BinaryDecoder(spec)
    packets = [p for i in range(0, len(data), chunk) for p in decoder.feed(data[i:i + chunk])]
    assert len(packets) == 1 and packets[0].raw == data
    fields = packets[0].fields

    saturated = 0
    for field in encoder.layout.fields:
        for q in field.quantities:
            key = f"{field.key}.{q.label}" if q.label else field.key
            if q.source == "time_ns":
                # TimeStartup counts from the run's start (start_ns 0 here); GPS week and time of week split the
                # same clamped GPS time: time_ns is UTC Unix ns, GPS = UTC + 18 s - 315 964 800 s (1980-01-06)
                week_ns = 7 * 86400 * 10**9
                t = time_ns if q.time == "startup" else time_ns + (18 - 315_964_800) * 10**9
                expected = {"week": min(max(t, 0) // week_ns, 65535), "tow": max(t, 0) % week_ns}.get(q.time, max(t, 0))
                assert fields[key] == expected
                saturated += (t < 0) + (q.time == "week" and max(t, 0) // week_ns > 65535)
                continue
            source = np.atleast_1d(getattr(samples, q.source)[0])
            got = np.atleast_1d(fields[key])
            for slot, component in enumerate(q.order):
                wire, clipped = _expected_wire(source[component], q.scale)
                saturated += clipped
                assert got[component] == np.float64(wire) / q.scale
    assert encoder.saturated.total == saturated


def test_batch_equals_concatenated_single_encodes_and_defaults_apply():
    rng = np.random.default_rng(7)
    n = 500
    samples = Samples(np.arange(n) * 2_500_000, rng.normal(0, 5, (n, 3)), rng.normal(0, 1, (n, 3)))
    spec = "common:timestartup,yawpitchroll,quaternion,magpres;imu:temp,pres,accel"
    batch = BinaryEncoder(spec).encode(samples)
    single = BinaryEncoder(spec)
    assert batch.data == b"".join(single.encode(samples.slice(i, i + 1)).data for i in range(n))
    assert np.array_equal(batch.offsets, np.arange(n + 1) * single.bytes_per_sample)
    fields = BinaryDecoder().feed(batch.packet(3))[0].fields
    np.testing.assert_array_equal(fields["common.quaternion"], [1, 0, 0, 0])        # identity
    np.testing.assert_array_equal(fields["common.yawpitchroll"], [0, 0, 0])
    assert fields["imu.temp"] == 25.0
    assert fields["common.magpres.pressure_pa"] == pytest.approx(101325.0, rel=1e-7)


def test_quaternion_is_scalar_last_on_the_wire():
    samples = Samples.single(0, [0, 0, 0], [0, 0, 0], quat=[0.5, 0.1, 0.2, 0.3])
    packet = BinaryEncoder("attitude:quaternion").encode(samples).packet(0)
    assert struct.unpack_from("<4f", packet, 4) == tuple(np.float32([0.1, 0.2, 0.3, 0.5]))


@pytest.mark.parametrize("field, spec",
                         [("accel", None), ("mag", "common:magpres"), ("euler", "attitude:yawpitchroll")])
def test_nan_raises_encode_error_naming_field_and_sample(field, spec):
    n = 4
    values = {"accel": np.zeros((n, 3)), "mag": np.zeros((n, 3)), "euler": np.zeros((n, 3))}
    values[field][2, 1] = np.nan
    samples = Samples(np.arange(n), values["accel"], np.zeros((n, 3)), mag=values["mag"], euler=values["euler"])
    with pytest.raises(EncodeError, match=rf"'{field}'.*sample 2"):
        BinaryEncoder(spec).encode(samples)


# --- binary decoder robustness ----------------------------------------------------------------

def _stream(n=20):
    rng = np.random.default_rng(3)
    samples = Samples(np.arange(n) * 1000, rng.normal(0, 9, (n, 3)), rng.normal(0, 1, (n, 3)))
    a = BinaryEncoder().encode(samples)
    b = BinaryEncoder("common:timestartup,quaternion,magpres").encode(samples)
    return [a.packet(i) for i in range(n)] + [b.packet(i) for i in range(n)]


@SETTINGS
@given(garbage=st.lists(st.binary(max_size=40), min_size=40, max_size=40), cuts=st.lists(st.integers(1, 97)))
def test_decoder_recovers_every_packet_between_garbage(garbage, cuts):
    packets = _stream()
    stream = b"".join(g + p for g, p in zip(garbage, packets))
    decoder, got, pos = BinaryDecoder(), [], 0
    for cut in cuts + [len(stream)]:
        got += decoder.feed(stream[pos:pos + cut])
        pos += cut
    got += decoder.feed(stream[pos:])
    assert all(binascii.crc_hqx(p.raw[1:], 0) == 0 for p in got)
    # Garbage may by chance hold a valid packet of its own; every real one must come through, in order.
    raws = iter(p.raw for p in got)
    assert all(any(r == p for r in raws) for p in packets)
    assert decoder.stats.packets == len(got)
    assert decoder.stats.skipped_bytes + sum(len(p.raw) for p in got) + len(decoder._buf) == len(stream)


@SETTINGS
@given(data=st.data())
def test_decoder_fuzz_never_raises_never_yields_bad_crc(data):
    stream = bytearray(b"".join(_stream(5)))
    for _ in range(data.draw(st.integers(0, 12))):
        i = data.draw(st.integers(0, len(stream) - 1))
        stream[i] ^= 1 << data.draw(st.integers(0, 7))
    stream = bytes(stream[:data.draw(st.integers(0, len(stream)))]) + data.draw(st.binary(max_size=200))
    for decoder in (BinaryDecoder(), BinaryDecoder(fields="common:timestartup,quaternion,magpres"), AsciiDecoder()):
        got = decoder.feed(stream[:len(stream) // 2]) + decoder.feed(stream[len(stream) // 2:])
        assert all(binascii.crc_hqx(p.raw[1:], 0) == 0 for p in got if p.kind == "vectornav-binary")
        assert decoder.stats.packets == len(got)


def test_configured_decoder_skips_other_layouts_and_counts_bad_crc():
    good = _stream(2)
    decoder = BinaryDecoder(fields=None)
    damaged = bytearray(good[0])
    damaged[10] ^= 0x40
    got = decoder.feed(bytes(damaged) + good[1])
    assert [p.raw for p in got] == [good[1]] and decoder.stats.bad_checksum >= 1
    only_default = BinaryDecoder()
    assert [p.raw for p in only_default.feed(b"".join(good))] == good
    picky = BinaryDecoder(fields="common:timestartup,quaternion,magpres")
    assert [p.raw for p in picky.feed(b"".join(good))] == good[2:]


# --- ASCII ----------------------------------------------------------------------------------

@pytest.mark.parametrize("line, name", [(VN_LIB_YMR, "VNYMR"), (VN200_IMU, "VNIMU")])
def test_published_ascii_lines_decode_and_reencode_byte_for_byte(line, name):
    decoder = registered(f"vectornav-{name.lower()}").decoder()
    [packet] = decoder.feed(line)
    assert packet.kind == name and packet.raw == line
    samples = Samples.single(0, packet.fields["accel"], packet.fields["gyro"],
                             **{k: v for k, v in packet.fields.items() if k not in ("accel", "gyro")})
    assert registered(f"vectornav-{name.lower()}").encoder().encode(samples).data == line


@SETTINGS
@given(name=st.sampled_from(["VNYMR", "VNIMU"]), kind=st.sampled_from(["xor", "crc"]),
       vals=st.lists(st.floats(-50, 50), min_size=14, max_size=14))
def test_ascii_checksums_and_round_trip(name, kind, vals):
    samples = Samples.single(5, vals[0:3], [v / 10 for v in vals[3:6]], mag=[v / 50 for v in vals[6:9]],
                             euler=[v / 20 for v in vals[9:12]], temperature_c=vals[12],
                             pressure_pa=100_000 + 100 * vals[13])
    encoder = registered(f"vectornav-{name.lower()}").encoder(checksum=kind)
    line = encoder.encode(samples).data
    body, cs = split_line(line)
    expected = b"%02X" % xor8(body) if kind == "xor" else b"%04X" % binascii.crc_hqx(body, 0)
    assert cs == expected and body.startswith(name.encode() + b",")
    assert len(line) == encoder.bytes_per_sample     # values within the nominal widths
    [packet] = AsciiDecoder().feed(line)
    resolution = {"accel": 5e-4, "gyro": 5e-7, "mag": 5e-5, "euler": np.radians(5e-4),
                  "temperature_c": 0.05, "pressure_pa": 0.5}
    for key, value in packet.fields.items():
        np.testing.assert_allclose(value, getattr(samples, key)[0], rtol=1e-6, atol=resolution[key] * 1.01)


def test_ascii_saturates_and_rejects_nan():
    encoder = AsciiEncoder("VNIMU")
    samples = Samples.single(0, [1e39, 0, 0], [0, 0, 0])
    [packet] = AsciiDecoder().feed(encoder.encode(samples).data)
    assert packet.fields["accel"][0] == pytest.approx(F32_MAX, rel=1e-6)
    assert encoder.saturated.counts == {"vnimu.accel": 1}
    with pytest.raises(EncodeError, match="'gyro'.*sample 0"):
        encoder.encode(Samples.single(0, [0, 0, 0], [0, np.inf, 0]))


def test_ascii_decoder_handles_noise_splits_and_bad_checksums():
    lines = [AsciiEncoder("VNYMR").encode(SPEC_SAMPLE).data, AsciiEncoder("VNIMU", "crc").encode(SPEC_SAMPLE).data]
    bad = lines[0].replace(b"*", b"0*", 1)
    stream = b"\x00\xfa$VN" + lines[0] + b"noise" + bad + b"$VNWRG,07,2*6F\r\n" + lines[1] + b"$VNYMR,+1"
    decoder = AsciiDecoder()
    got = [p for i in range(len(stream)) for p in decoder.feed(stream[i:i + 1])]
    assert [p.raw for p in got] == lines
    assert decoder.stats.bad_checksum == 1 and decoder.stats.ignored_frames == 1


def test_bad_checksum_option_is_rejected():
    with pytest.raises(ValueError, match="checksum"):
        registered("vectornav-vnymr").encoder(checksum="sum")


# --- command replies ------------------------------------------------------------------------

@pytest.mark.parametrize("command, reply", [
    # VectorNav library example: model read on a VN-200 and an async-frequency write.
    (b"$VNRRG,01*XX\r\n", b"$VNRRG,01,VN-200T-CR*31\r\n"),
    (b"$VNWRG,07,2*XX\r\n", b"$VNWRG,07,2*6F\r\n"),
    (b"$VNWRG,35,1,0,1,1*71\r\n", b"$VNWRG,35,1,0,1,1*71\r\n"),
    # ArduPilot's comments: a CRC-checked binary output 1 write, and the VN-300 GNSS packet setup.
    (b"$VNWRG,75,3,16,01,0721*D415\r\n", b"$VNWRG,75,3,16,01,0721*D415\r\n"),
    (b"$VNWRG,76,3,80,4E,0002,0010,20B8,0018*63\r\n", b"$VNWRG,76,3,80,4E,0002,0010,20B8,0018*63\r\n"),
])
def test_device_answers_documented_commands(command, reply):
    assert VectorNavDevice(400.0, model="VN-200T-CR").receive(command) == [reply]


def test_device_defaults_and_errors():
    device = VectorNavDevice(400.0)
    (model_reply,) = device.receive(b"$VNRRG,1*XX\r\n")
    body, cs = split_line(model_reply)
    assert body.split(b",")[2].startswith(b"VN-") and cs == b"%02X" % xor8(body)
    assert split_line(device.receive(b"$VNASY,0*XX\r\n")[0])[0] == b"VNASY,0"
    assert split_line(device.receive(b"$VNWRG,07,2*00\r\n")[0])[0] == b"VNERR,03"
    assert split_line(device.receive(b"$VNRRG,99*XX\r\n")[0])[0] == b"VNERR,08"
    assert device.receive(b"garbage") == []


@pytest.mark.parametrize("name, option", [("vectornav-binary", "fields"), ("vectornav-vnymr", "checksum"),
                                          ("vectornav-vnimu", "checksum")])
def test_registered_formats(name, option):
    info = registered(name)
    assert info.kind == "serial" and option in info.options
    assert info.bytes_per_sample == info.encoder().bytes_per_sample > 0


def test_navigation_fields_round_trip_with_their_wire_types_and_documented_defaults():
    """INS group (f64 PosLla, u16 InsStatus) and attitude LinearAccelNed / YprU: the header is the one PX4's
    binary output 2 announces, and the values decode to what went in (float64 exactly, float32 rounded)."""
    spec = ("time:timestartup;imu:temp,pres,mag;attitude:quaternion,linearaccelned;"
            "ins:insstatus,poslla,velned,posu,velu")
    lla = [[47.3977421234567, 8.5455941234567, 488.123456789]]
    samples = Samples([1_000], [[0.1, 0.2, 9.8]], [[0.0, 0.0, 0.1]], position_llh=lla,
                      velocity_ned=[[1.25, -2.5, 0.125]], linear_accel_ned=[[0.5, 0.25, -0.125]])
    data = BinaryEncoder(spec).encode(samples).data
    # groups 0x36 = time, imu, attitude, ins; masks from vnproglib's TIMEGROUP/IMUGROUP/ATTITUDEGROUP/INSGROUP
    assert data[:10] == bytes([0xFA, 0x36]) + struct.pack("<4H", 0x0001, 0x0130, 0x0084, 0x0613)
    fields = BinaryDecoder().feed(data)[0].fields
    np.testing.assert_array_equal(fields["ins.poslla"], lla[0])
    assert struct.unpack_from("<H", data, 10 + 8 + 12 + 4 + 4 + 16 + 12)[0] == 0x0006
    np.testing.assert_array_equal(fields["ins.velned"], [1.25, -2.5, 0.125])
    np.testing.assert_array_equal(fields["attitude.linearaccelned"], [0.5, 0.25, -0.125])
    assert fields["ins.posu"] == 1.0 and fields["ins.velu"] == np.float32(0.05)
