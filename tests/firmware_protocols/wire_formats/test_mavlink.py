"""MAVLink 2 IMU encoders and decoder, checked against the spec's published vectors and against
pymavlink (an independent encoder/decoder). Expected wire values are computed here from the
MAVLink field definitions, not taken from the module under test."""
import io
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v10 import common as mavlink1
from pymavlink.dialects.v20 import common as mavlink2

from firmware_protocols import registry
from firmware_protocols.base import EncodeError, Samples
from firmware_protocols.crc import crc16_mcrf4xx_bytes
from firmware_protocols.wire_formats.mavlink import MavlinkDecoder, MavlinkEncoder, SigningLink

REPRO = settings(derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])

G = 9.80665
MG = G / 1000          # m/s^2 per mG
MILLI = 1e-3           # rad/s per mrad/s, gauss per mgauss
FLT_MAX = float(np.finfo(np.float32).max)
EPOCH_2015_NS = 1420070400 * 10**9
KEY = bytes(range(32))

# registry name -> (pymavlink message name, kind): "float" messages carry SI float32 values,
# "int" messages int16 mG / mrad/s / mgauss.
MESSAGES = {
    "mavlink-highres": ("highres_imu", "float"),
    "mavlink-hil-sensor": ("hil_sensor", "float"),
    "mavlink-scaled-imu": ("scaled_imu", "int"),
    "mavlink-scaled-imu2": ("scaled_imu2", "int"),
    "mavlink-scaled-imu3": ("scaled_imu3", "int"),
    "mavlink-raw-imu": ("raw_imu", "int"),
}
HAS_ID = {"mavlink-highres", "mavlink-hil-sensor", "mavlink-raw-imu"}
SPEC_SAMPLE = dict(time_ns=1_234_567_000, accel=(0.1, -0.2, -9.80665), gyro=(0.01, -0.02, 0.03),
                   mag=(0.21, 0.01, -0.42))


def i16(value: float, lsb: float) -> int:
    return min(max(round(value / lsb), -32768), 32767)


def cdeg(temperature):
    """MAVLink's int16 temperature: 0 means "not sent", so a reading of 0 goes out as 1."""
    if temperature is None:
        return 0
    return i16(temperature, 0.01) or 1


def expected_args(name, t_ns, accel, gyro, mag=None, pressure=None, temperature=None, id=0,
                  pressure_alt=None, diff_pressure=None):
    """Arguments of pymavlink's <message>_encode for one sample, from the MAVLink definitions."""
    _, kind = MESSAGES[name]
    mag3 = (0.0, 0.0, 0.0) if mag is None else mag
    if kind == "float":
        provided = [True] * 6 + [mag is not None] * 3 + [pressure is not None, diff_pressure is not None,
                                                        pressure_alt is not None, temperature is not None]
        return dict(time_usec=t_ns // 1000, xacc=accel[0], yacc=accel[1], zacc=accel[2],
                    xgyro=gyro[0], ygyro=gyro[1], zgyro=gyro[2], xmag=mag3[0], ymag=mag3[1], zmag=mag3[2],
                    abs_pressure=0.0 if pressure is None else pressure / 100,
                    diff_pressure=diff_pressure / 100 if diff_pressure is not None else 0.0,
                    pressure_alt=pressure_alt or 0.0, temperature=temperature or 0.0,
                    fields_updated=sum(1 << bit for bit, p in enumerate(provided) if p), id=id)
    args = dict(xacc=i16(accel[0], MG), yacc=i16(accel[1], MG), zacc=i16(accel[2], MG),
                xgyro=i16(gyro[0], MILLI), ygyro=i16(gyro[1], MILLI), zgyro=i16(gyro[2], MILLI),
                xmag=i16(mag3[0], MILLI), ymag=i16(mag3[1], MILLI), zmag=i16(mag3[2], MILLI),
                temperature=cdeg(temperature))
    if name == "mavlink-raw-imu":
        return dict(time_usec=t_ns // 1000, id=id, **args)
    return dict(time_boot_ms=(t_ns // 10**6) % 2**32, **args)


def pymavlink_link(seq=0, sysid=1, compid=1):
    mav = mavlink2.MAVLink(io.BytesIO(), srcSystem=sysid, srcComponent=compid)
    mav.seq = seq
    return mav


def random_block(rng, n, t0=10**15, mag=True, pressure=True, temperature=True):
    return Samples(t0 + np.cumsum(rng.integers(1, 3_000_000, n)), rng.normal(0, 20, (n, 3)),
                   rng.normal(0, 3, (n, 3)), mag=rng.normal(0, 0.5, (n, 3)) if mag else None,
                   pressure_pa=rng.normal(95000, 3000, n) if pressure else None,
                   temperature_c=rng.normal(20, 15, n) if temperature else None)


def sample_args(samples, i, name, **extra):
    def row(field):
        value = getattr(samples, field)
        return None if value is None else (tuple(value[i]) if value.ndim == 2 else float(value[i]))
    kind = MESSAGES[name][1]
    return expected_args(name, int(samples.time_ns[i]), row("accel"), row("gyro"), mag=row("mag"),
                         pressure=row("pressure_pa") if kind == "float" else None,
                         temperature=row("temperature_c"), **extra)


# --- the spec's published vectors -------------------------------------------------------------

@pytest.mark.parametrize("name, options, optional, expected", [
    ("mavlink-highres", dict(seq=0, diff_pressure_pa=0.0, pressure_alt_m=12.5),
     dict(pressure_pa=101325.0, temperature_c=25.0),
     "fd3e000000010169000087d6120000000000cdcccc3dcdcc4cbe0ae81cc10ad7233c0ad7a3bc8fc2f53c3d0a573e0ad7233c"
     "3d0ad7be00507d4400000000000048410000c841ff1f7263"),
    ("mavlink-scaled-imu", dict(seq=2), dict(temperature_c=25.0),
     "fd1800000201011a0000d20400000a00ecff18fc0a00ecff1e00d2000a005cfec4094cc6"),
    ("mavlink-raw-imu", dict(seq=3), dict(temperature_c=25.0),
     "fd1d00000301011b000087d61200000000000a00ecff18fc0a00ecff1e00d2000a005cfe00c4096557"),
])
def test_spec_vectors(name, options, optional, expected):
    encoder = registry.create_encoder(name, sysid=1, compid=1, **options)
    batch = encoder.encode(Samples.single(SPEC_SAMPLE["time_ns"], SPEC_SAMPLE["accel"], SPEC_SAMPLE["gyro"],
                                          mag=SPEC_SAMPLE["mag"], **optional))
    assert batch.data.hex() == expected
    assert list(batch.offsets) == [0, len(expected) // 2]


# --- byte for byte against pymavlink ------------------------------------------------------------

@pytest.mark.parametrize("name", MESSAGES)
@pytest.mark.parametrize("signed", [False, True])
def test_bytes_match_pymavlink(name, signed):
    rng = np.random.default_rng(7)
    block = random_block(rng, 300, t0=EPOCH_2015_NS + 10**15)
    # several samples inside one 10 us tick make the signing timestamp step past the sample time
    block.time_ns[50:60] = block.time_ns[50]
    id_option = {"id": 3} if name in HAS_ID else {}
    extra = dict(id_option)
    options = dict(sysid=42, compid=200, seq=250, **id_option)
    if MESSAGES[name][1] == "float":
        options.update(diff_pressure_pa=123.0, pressure_alt_m=321.5)
        extra.update(diff_pressure=123.0, pressure_alt=321.5)
    if signed:
        options.update(signing_key=KEY, link_id=9, sign_time="sample")
    encoder = MavlinkEncoder(name, **options)
    # two calls: the sequence number (and signing clock) must continue, wrapping at 256
    data = encoder.encode(block.slice(0, 123)).data + encoder.encode(block.slice(123, 300)).data

    mav = pymavlink_link(seq=250, sysid=42, compid=200)
    if signed:
        mav.signing.secret_key, mav.signing.link_id, mav.signing.sign_outgoing = KEY, 9, True
    last = 0
    for i in range(len(block)):
        if signed:
            last = max((int(block.time_ns[i]) - EPOCH_2015_NS) // 10_000, last + 1)
            mav.signing.timestamp = last
        mav.send(getattr(mav, MESSAGES[name][0] + "_encode")(**sample_args(block, i, name, **extra)))
    assert data == mav.file.getvalue()
    assert encoder.seq == (250 + 300) % 256


@pytest.mark.parametrize("name", MESSAGES)
def test_missing_optional_fields_match_pymavlink(name):
    block = random_block(np.random.default_rng(3), 20, mag=False, pressure=False, temperature=False)
    data = MavlinkEncoder(name).encode(block).data
    mav = pymavlink_link()
    for i in range(len(block)):
        mav.send(getattr(mav, MESSAGES[name][0] + "_encode")(**sample_args(block, i, name)))
    assert data == mav.file.getvalue()


@pytest.mark.parametrize("name", MESSAGES)
def test_pymavlink_decodes_batch(name):
    block = random_block(np.random.default_rng(11), 2000)
    batch = MavlinkEncoder(name).encode(block)
    assert len(batch) == len(block) and batch.offsets[-1] == len(batch.data)
    messages = pymavlink_link().parse_buffer(batch.data)
    assert len(messages) == len(block)
    float_kind = MESSAGES[name][1] == "float"
    for i, msg in enumerate(messages):
        assert msg.get_type() == MESSAGES[name][0].upper() and msg.get_seq() == i % 256
        expected = sample_args(block, i, name)
        if float_kind:
            # the encoder derives pressure_alt from pressure (checked against the ISA table below)
            assert msg.fields_updated == expected.pop("fields_updated") | 1 << 11
            del expected["pressure_alt"]
        for field, value in expected.items():
            got = getattr(msg, field)
            if float_kind and isinstance(value, float):
                assert got == pytest.approx(value, rel=2**-23, abs=1e-30), field
            else:
                assert got == value, field
        if float_kind:
            assert msg.xacc == pytest.approx(block.accel[i, 0], rel=2**-23)
        else:
            assert abs(msg.xacc * MG - block.accel[i, 0]) <= MG / 2 + 1e-12
            assert abs(msg.zmag * MILLI - block.mag[i, 2]) <= MILLI / 2 + 1e-12


def test_pressure_altitude_follows_the_standard_atmosphere():
    # ICAO standard atmosphere (Doc 7488): geopotential altitude (m) -> static pressure (hPa)
    table = {0: 1013.25, 1000: 898.75, 2000: 794.95, 5000: 540.20, 10000: 264.36}
    n = len(table)
    block = Samples(np.arange(n), np.zeros((n, 3)), np.zeros((n, 3)),
                    pressure_pa=np.array(list(table.values())) * 100)
    packets = MavlinkDecoder().feed(MavlinkEncoder("mavlink-highres").encode(block).data)
    for packet, altitude in zip(packets, table):
        assert packet.fields["pressure_alt_m"] == pytest.approx(altitude, abs=0.5)
        # accel, gyro, abs_pressure, pressure_alt; no mag, diff_pressure or temperature
        assert packet.fields["fields_updated"] == 0b111111 | 1 << 9 | 1 << 11


# --- round trips through our decoder, saturation included --------------------------------------

INT_LIMITS = {"accel": 32767 * MG, "gyro": 32767 * MILLI, "mag": 32767 * MILLI, "temperature_c": 327.67}


def edge_floats(limit, lsb):
    """Anything within twice the range, plus the values where rounding tips into saturation."""
    edges = [limit, -limit, (32767.5 - 1e-9) * lsb, 32767.5 * lsb, -32768.5 * lsb, -(32768.5 - 1e-9) * lsb,
             32768 * lsb, -32769 * lsb, 0.0, 0.4 * lsb, -0.4 * lsb, 1e30, -1e30]
    return st.one_of(st.floats(-2 * limit, 2 * limit), st.sampled_from(edges))


def huge_floats():
    return st.one_of(st.floats(-1e40, 1e40), st.sampled_from([FLT_MAX, -FLT_MAX, 3.5e38, -3.5e38, 0.0, 1e-45]))


@st.composite
def sample_blocks(draw, name):
    n = draw(st.integers(1, 6))
    float_kind = MESSAGES[name][1] == "float"
    vector = (lambda field: huge_floats()) if float_kind else (lambda field: edge_floats(INT_LIMITS[field], 1e-3 if field != "accel" else MG))
    times = draw(st.lists(st.integers(-2**63, 2**63 - 1), min_size=n, max_size=n))
    block = dict(time_ns=np.array(times, dtype=np.int64),
                 accel=[[draw(vector("accel")) for _ in range(3)] for _ in range(n)],
                 gyro=[[draw(vector("gyro")) for _ in range(3)] for _ in range(n)])
    if draw(st.booleans()):
        block["mag"] = [[draw(vector("mag")) for _ in range(3)] for _ in range(n)]
    if draw(st.booleans()):
        temperature = huge_floats() if float_kind else edge_floats(INT_LIMITS["temperature_c"], 0.01)
        block["temperature_c"] = [draw(temperature) for _ in range(n)]
    if float_kind and draw(st.booleans()):
        block["pressure_pa"] = [draw(st.one_of(st.floats(0, 1e42), st.sampled_from([100 * FLT_MAX, 3.5e40])))
                                for _ in range(n)]
    return Samples(**block)


def check_round_trip(name, block):
    encoder = MavlinkEncoder(name, pressure_alt_m=1.0) if MESSAGES[name][1] == "float" else MavlinkEncoder(name)
    packets = MavlinkDecoder().feed(encoder.encode(block).data)
    assert len(packets) == len(block)
    saturated = {}

    def count(field, hit):
        saturated[field] = saturated.get(field, 0) + int(hit)

    for i, packet in enumerate(packets):
        got = packet.fields
        assert packet.kind == name
        t = int(block.time_ns[i])
        if name.startswith("mavlink-scaled-imu"):
            assert got["time_boot_ms"] == (t // 10**6) % 2**32
        else:
            assert got["time_usec"] == max(t // 1000, 0)
            count("time_usec", t < 0)
        for field, wire_names in (("accel", "xyz"), ("gyro", "xyz"), ("mag", "xyz")):
            values = getattr(block, field)
            if values is None:
                assert got[field] is None if MESSAGES[name][1] == "float" else got[field] == (0.0, 0.0, 0.0)
                continue
            for axis in range(3):
                wire = f"{wire_names[axis]}{'acc' if field == 'accel' else field}"
                x = values[i, axis]
                if MESSAGES[name][1] == "float":
                    clipped = min(max(x, -FLT_MAX), FLT_MAX)
                    assert got[field][axis] == float(np.float32(clipped))
                    count(wire, clipped != x)
                else:
                    lsb = MG if field == "accel" else MILLI
                    raw = round(x / lsb)
                    assert got[field][axis] == pytest.approx(min(max(raw, -32768), 32767) * lsb, rel=1e-12)
                    count(wire, not -32768 <= raw <= 32767)
        if block.temperature_c is None:
            assert got["temperature_c"] is None
        elif MESSAGES[name][1] == "float":
            x = block.temperature_c[i]
            assert got["temperature_c"] == float(np.float32(min(max(x, -FLT_MAX), FLT_MAX)))
            count("temperature", abs(x) > FLT_MAX)
        else:
            raw = round(block.temperature_c[i] / 0.01)
            assert got["temperature_c"] == pytest.approx(0.01 * (min(max(raw, -32768), 32767) or 1))
            count("temperature", not -32768 <= raw <= 32767)
        if MESSAGES[name][1] == "float":
            if block.pressure_pa is None:
                assert got["pressure_pa"] is None
            else:
                hpa = block.pressure_pa[i] / 100
                assert got["pressure_pa"] == float(np.float32(min(hpa, FLT_MAX))) * 100
                count("abs_pressure", hpa > FLT_MAX)
    assert encoder.saturated.counts == {k: v for k, v in saturated.items() if v}


@pytest.mark.parametrize("name", MESSAGES)
def test_round_trip_full_range(name):
    @settings(REPRO, max_examples=60)
    @given(sample_blocks(name))
    def run(block):
        check_round_trip(name, block)
    run()


def test_temperature_zero_is_sent_as_one_and_absent_as_zero():
    encoder = MavlinkEncoder("mavlink-scaled-imu2")
    block = Samples(np.arange(3), np.zeros((3, 3)), np.zeros((3, 3)), temperature_c=[0.0, -0.004, 0.006])
    messages = pymavlink_link().parse_buffer(encoder.encode(block).data)
    assert [m.temperature for m in messages] == [1, 1, 1]
    no_temperature = Samples(np.arange(1), np.zeros((1, 3)), np.zeros((1, 3)))
    (message,) = pymavlink_link().parse_buffer(encoder.encode(no_temperature).data)
    assert message.temperature == 0


def test_time_boot_ms_wraps_like_the_autopilot_counter():
    t = np.array([2**32 * 10**6 - 1, 2**32 * 10**6, 2**32 * 10**6 + 5 * 10**9], dtype=np.int64)
    block = Samples(t, np.zeros((3, 3)), np.zeros((3, 3)))
    messages = pymavlink_link().parse_buffer(MavlinkEncoder("mavlink-scaled-imu").encode(block).data)
    assert [m.time_boot_ms for m in messages] == [2**32 - 1, 0, 5000]


def test_untruncated_packets_and_registry_sizes():
    block = Samples(np.zeros(2, dtype=np.int64), np.zeros((2, 3)), np.zeros((2, 3)))
    for name, (pymav_name, _) in MESSAGES.items():
        info = registry.get(name)
        assert info.kind == "serial" and info.options
        full = MavlinkEncoder(name, truncate=False)
        batch = full.encode(block)
        assert len(batch.packet(0)) == info.bytes_per_sample == full.bytes_per_sample
        payload_len = getattr(mavlink2, f"MAVLink_{pymav_name}_message").unpacker.size
        assert info.bytes_per_sample == 12 + payload_len
        assert MavlinkEncoder(name, signing_key=KEY).bytes_per_sample == info.bytes_per_sample + 13
        assert len(pymavlink_link().parse_buffer(batch.data)) == 2
    # an all-zero payload: truncation keeps exactly one byte
    (message,) = pymavlink_link().parse_buffer(MavlinkEncoder("mavlink-scaled-imu").encode(block.slice(0, 1)).data)
    assert len(message.get_msgbuf()) == 13 and message.xacc == 0 and message.temperature == 0


# --- bad input ------------------------------------------------------------------------------------

@pytest.mark.parametrize("field", ["accel", "gyro", "mag", "temperature_c", "pressure_pa"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_names_field_and_sample(field, bad):
    block = random_block(np.random.default_rng(5), 10_000)
    values = getattr(block, field)
    values[9_000 if values.ndim == 1 else (9_000, 1)] = bad   # in a later chunk than the first
    encoder = MavlinkEncoder("mavlink-highres", signing_key=KEY, seq=7)
    with pytest.raises(EncodeError, match=rf"'{field}'.*sample 9000"):
        encoder.encode(block)
    # the refused block left no trace: sequence and signing clock are where they were
    assert encoder.seq == 7 and encoder.signing_link.last_timestamp == 0 and encoder.saturated.total == 0


def test_fields_a_message_does_not_carry_are_not_checked():
    block = random_block(np.random.default_rng(5), 4)
    block.pressure_pa[2] = np.nan
    assert len(MavlinkEncoder("mavlink-scaled-imu").encode(block)) == 4


def test_bad_options_are_refused():
    with pytest.raises(ValueError, match="id"):
        MavlinkEncoder("mavlink-scaled-imu", id=1)
    with pytest.raises(ValueError, match="sysid"):
        MavlinkEncoder("mavlink-highres", sysid=256)
    with pytest.raises(ValueError, match="signing_key"):
        MavlinkEncoder("mavlink-highres", signing_key=b"short")
    with pytest.raises(ValueError, match="pressure_alt_m"):
        MavlinkEncoder("mavlink-raw-imu", pressure_alt_m=3.0)


# --- signing ------------------------------------------------------------------------------------

def test_shared_signing_link_keeps_timestamps_increasing_and_decoder_checks_them():
    link = SigningLink(KEY.hex(), link_id=4)
    highres = MavlinkEncoder("mavlink-highres", signing_link=link)
    scaled = MavlinkEncoder("mavlink-scaled-imu", signing_link=link)
    block = random_block(np.random.default_rng(2), 50)
    before = (time.time_ns() - EPOCH_2015_NS) // 10_000
    stream = b"".join(encoder.encode(block.slice(i, i + 1)).data
                      for i in range(len(block)) for encoder in (highres, scaled))
    decoder = MavlinkDecoder(signing_key=KEY)
    packets = decoder.feed(stream)
    assert len(packets) == 100 and decoder.bad_signature == 0
    stamps = [p.fields["signing_timestamp"] for p in packets]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert before <= stamps[0] <= before + 200_000   # wall clock, within 2 s
    assert {p.fields["link_id"] for p in packets} == {4}

    # pymavlink with the same key accepts every packet
    oracle = pymavlink_link()
    oracle.signing.secret_key = KEY
    assert len(oracle.parse_buffer(stream)) == 100

    # a replay, a wrong key, and unsigned packets are refused
    assert decoder.feed(stream[:len(packets[0].raw)]) == [] and decoder.bad_signature == 1
    assert MavlinkDecoder(signing_key=bytes(32)).feed(stream) == []
    unsigned = MavlinkEncoder("mavlink-highres").encode(block).data
    assert MavlinkDecoder(signing_key=KEY).feed(unsigned) == []
    assert len(MavlinkDecoder(signing_key=KEY, allow_unsigned=True).feed(unsigned)) == 50
    assert len(MavlinkDecoder().feed(stream)) == 100   # without a key: CRC only


# --- the stream decoder against hostile input ----------------------------------------------------

def reference_stream(rng):
    """Packets of every message type, some signed, from our encoders."""
    packets = []
    block = random_block(rng, 40)
    for k, name in enumerate(MESSAGES):
        signing = dict(signing_key=KEY, sign_time="sample") if k % 2 else {}
        batch = MavlinkEncoder(name, **signing).encode(block.slice(k * 6, k * 6 + 6))
        packets += [batch.packet(i) for i in range(len(batch))]
    order = rng.permutation(len(packets))
    return [packets[i] for i in order]


def crc_valid(frame: bytes) -> bool:
    """Independent check via pymavlink: the frame parses to exactly one message."""
    return len(pymavlink_link().parse_buffer(frame) or []) == 1


# Frame starts that make the decoder wait for, or check, a candidate frame.
LOOKALIKES = [bytes.fromhex(h) for h in (
    "fd1800000201011a0000", "fd3e000000010169000087d6", "fd4101000001016b0000", "fd1d0000030101",
    "fe16000101", "fe1600010174", "fd0000000001011a0000", "fdff02000001011a0000")]


@settings(REPRO, max_examples=200)
@given(st.lists(st.one_of(st.binary(max_size=300), st.sampled_from(LOOKALIKES)), max_size=30),
       st.lists(st.integers(1, 500), max_size=20), st.booleans())
def test_decoder_survives_garbage(pieces, cuts, with_key):
    garbage = b"".join(pieces)
    decoder = MavlinkDecoder(signing_key=KEY if with_key else None)
    pos = 0
    for size in cuts + [len(garbage)]:
        for packet in decoder.feed(garbage[pos:pos + size]):
            assert crc_valid(packet.raw)
        pos += size
    assert decoder.stats.skipped_bytes <= len(garbage)


@settings(REPRO, max_examples=150)
@given(st.data())
def test_decoder_recovers_every_intact_packet(data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**16), label="seed"))
    packets = reference_stream(rng)
    stream, intact = b"", []
    for packet in packets:
        stream += data.draw(st.binary(max_size=40), label="garbage")
        damage = data.draw(st.sampled_from(["none", "none", "flip", "truncate"]), label="damage")
        # Without a key nothing can tell a damaged signature from a good one, so damage stays
        # inside the CRC-covered part of the frame.
        covered = len(packet) - (13 if packet[2] & 1 else 0)
        if damage == "flip":
            bit = data.draw(st.integers(0, 8 * covered - 1))
            packet = bytearray(packet)
            packet[bit // 8] ^= 1 << (bit % 8)
            packet = bytes(packet)
        elif damage == "truncate":
            packet = packet[:data.draw(st.integers(1, covered - 1))]
        else:
            intact.append(packet)
        stream += packet
    stream += bytes(300)   # lets any half-seen candidate frame resolve
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=60), label="cuts"))
    decoder = MavlinkDecoder()
    got = []
    for start, stop in zip([0] + cuts, cuts + [len(stream)]):
        got += decoder.feed(stream[start:stop])
    assert [p.raw for p in got] == intact
    assert all(crc_valid(p.raw) for p in got)
    assert decoder.stats.packets == len(intact)
    assert decoder.stats.skipped_bytes == len(stream) - sum(len(p) for p in intact)


def test_decoder_counts_bad_checksums_and_skips_mavlink1():
    block = random_block(np.random.default_rng(4), 3)
    good = MavlinkEncoder("mavlink-scaled-imu").encode(block)
    corrupt = bytearray(good.packet(1))
    corrupt[12] ^= 0x40
    v1 = mavlink1.MAVLink(io.BytesIO(), srcSystem=1, srcComponent=1)
    v1_scaled = v1.scaled_imu_encode(5, 1, 2, 3, 4, 5, 6, 7, 8, 9).pack(v1)
    v1_heartbeat = v1.heartbeat_encode(2, 3, 0, 0, 4).pack(v1)
    assert v1_scaled[0] == 0xFE and crc_valid(good.packet(0))
    decoder = MavlinkDecoder()
    packets = decoder.feed(v1_scaled + good.packet(0) + bytes(corrupt) + v1_heartbeat + good.packet(2))
    assert [p.raw for p in packets] == [good.packet(0), good.packet(2)]
    assert decoder.stats.bad_checksum == 1 and decoder.stats.ignored_frames == 1
    # a frame of a message this decoder does not know cannot be checked: its bytes are skipped
    assert decoder.stats.skipped_bytes == len(corrupt) + len(v1_heartbeat)
    fields = packets[1].fields
    assert fields["seq"] == 2 and fields["accel"] == pytest.approx(tuple(block.accel[2]), abs=MG / 2)
    assert fields["time_ns"] == block.time_ns[2] // 10**6 * 10**6


def test_crc_extra_is_part_of_the_checksum():
    frame = MavlinkEncoder("mavlink-scaled-imu2").encode(random_block(np.random.default_rng(1), 1)).data
    body = frame[1:-2]
    assert crc16_mcrf4xx_bytes(body + bytes([76])) == int.from_bytes(frame[-2:], "little")
    # the same bytes relabelled as SCALED_IMU3 (CRC_EXTRA 46) must be refused
    relabelled = frame[:7] + (129).to_bytes(3, "little") + frame[10:]
    decoder = MavlinkDecoder()
    assert decoder.feed(relabelled) == [] and decoder.stats.bad_checksum == 1
