"""DroneCAN ahrs.RawIMU / Solution / MagneticFieldStrength2, checked against the spec's published vector and
against the `dronecan` library (pydronecan) as an independent encoder and decoder."""
import struct

import dronecan
import numpy as np
import pytest
from dronecan.dsdl.common import crc16_from_bytes
from dronecan.transport import Frame, Transfer
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware_protocols import registry
from firmware_protocols.base import EncodeError, Samples, can_bits_worst_case, frame_bytes
from firmware_protocols.wire_formats.dronecan import (DroneCanDecoder, MagneticFieldStrength2Encoder, RawImuEncoder,
                                                      SolutionEncoder, _f16_from_f32_bits)

SETTINGS = settings(derandomize=True, deadline=None, max_examples=40,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
AHRS = dronecan.uavcan.equipment.ahrs

# wire-formats.md, "DroneCAN (UAVCAN v0)": RawIMU from node 42, transfer id 5, priority 31.
SPEC_ID = 0x1F03EB2A
SPEC_FRAMES = ("eec087d612000085 00000ad7233b1f25 211fa5ae2717b705 d13717b751b85225 499d38662e66b205 "
               "e7c86f1283396f25 1203ba09d7c8bc45").split()
SPEC_ACCEL = np.array([0.1, -0.2, -9.80665])
SPEC_GYRO = np.array([0.01, -0.02, 0.03])


def registered(name):
    return registry._REGISTRY[name]


def frames_hex(frames):
    return [frame_bytes(f).hex() for f in frames]


def to_pydronecan_frames(frames):
    return [Frame(int(f["can_id"]), bytearray(frame_bytes(f)), canfd=bool(f["fd"])) for f in frames]


def oracle_frames(message, node_id, transfer_id, priority, fd):
    transfer = Transfer(payload=message, source_node_id=node_id, transfer_id=transfer_id,
                        transfer_priority=priority, canfd=fd)
    return transfer.message_id, [bytes(f.bytes).hex() for f in transfer.to_frames()]


def decode_with_pydronecan(frames):
    transfer = Transfer()
    transfer.from_frames(to_pydronecan_frames(frames))
    return transfer


# --- published vector ---------------------------------------------------------------------------

def test_spec_vector_byte_for_byte():
    # The spec says "integrals = latest x 0.0025", but its vector carries float32(-9.80664 * 0.0025) as the
    # z accelerometer integral (every other integral is latest x 0.0025). Passing the integrals explicitly
    # as delta_velocity reproduces the published bytes; the frames' CRC and layout are unaffected.
    integrals = np.array([0.1, -0.2, -9.80664]) * 0.0025
    sample = Samples.single(1_234_567_000, SPEC_ACCEL, SPEC_GYRO, delta_theta=SPEC_GYRO * 0.0025,
                            delta_velocity=integrals)
    frames = RawImuEncoder(node_id=42, priority=31, transfer_id=5, sample_period_s=0.0025).encode(sample)
    assert list(frames["can_id"]) == [SPEC_ID] * 7
    assert frames_hex(frames) == SPEC_FRAMES
    assert frames["extended"].all() and not frames["fd"].any() and (frames["sample"] == 0).all()


def test_spec_vector_decodes_with_both_decoders():
    raw = [(SPEC_ID, bytes.fromhex(h)) for h in SPEC_FRAMES]
    transfer = Transfer()
    transfer.from_frames([Frame(i, bytearray(d)) for i, d in raw])
    decoder = DroneCanDecoder()
    packets = [p for i, d in raw for p in decoder.feed_frame(i, d, True)]
    assert len(packets) == 1
    fields = packets[0].fields
    assert fields["time_ns"] == transfer.payload.timestamp.usec * 1000 == 1_234_567_000
    assert fields["source_node_id"] == 42 and fields["transfer_id"] == 5 and fields["priority"] == 31
    np.testing.assert_array_equal(fields["gyro"], list(transfer.payload.rate_gyro_latest))
    np.testing.assert_array_equal(fields["accel"], list(transfer.payload.accelerometer_latest))
    np.testing.assert_array_equal(fields["delta_velocity"], list(transfer.payload.accelerometer_integral))
    np.testing.assert_allclose(fields["accel"], SPEC_ACCEL, atol=0.005)


def test_defaults_integrate_latest_times_period():
    """Without delta_theta/delta_velocity the integrals are latest x period, as the spec describes."""
    sample = Samples.single(1_234_567_000, SPEC_ACCEL, SPEC_GYRO)
    frames = RawImuEncoder(node_id=42, priority=31, transfer_id=5, sample_period_s=0.0025).encode(sample)
    message = raw_imu_message(1_234_567, 0.0025, SPEC_GYRO, SPEC_GYRO * 0.0025, SPEC_ACCEL, SPEC_ACCEL * 0.0025)
    assert oracle_frames(message, 42, 5, 31, False) == (SPEC_ID, frames_hex(frames))


# --- pydronecan as oracle -----------------------------------------------------------------------

def raw_imu_message(usec, interval, gyro, gyro_int, accel, accel_int):
    message = AHRS.RawIMU(integration_interval=float(interval), rate_gyro_latest=[float(v) for v in gyro],
                          rate_gyro_integral=[float(v) for v in gyro_int],
                          accelerometer_latest=[float(v) for v in accel],
                          accelerometer_integral=[float(v) for v in accel_int])
    message.timestamp.usec = int(usec)
    return message


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
moderate = st.floats(min_value=-1e5, max_value=1e5, allow_nan=False)
vector = st.lists(finite, min_size=3, max_size=3)
moderate_vector = st.lists(moderate, min_size=3, max_size=3)


@SETTINGS
@given(accel=moderate_vector, gyro=moderate_vector, time_us=st.integers(0, (2**63 - 1) // 1000 - 1),
       transfer_id=st.integers(0, 31), node_id=st.integers(1, 127), priority=st.integers(0, 31),
       period=st.floats(1e-5, 1.0), fd=st.booleans())
def test_raw_imu_matches_pydronecan(accel, gyro, time_us, transfer_id, node_id, priority, period, fd):
    accel, gyro = np.array(accel), np.array(gyro)
    sample = Samples.single(time_us * 1000 + 999, accel, gyro)
    encoder = RawImuEncoder(node_id=node_id, priority=priority, transfer_id=transfer_id, sample_period_s=period, fd=fd)
    frames = encoder.encode(sample)
    message = raw_imu_message(time_us, period, gyro, gyro * period, accel, accel * period)
    can_id, expected = oracle_frames(message, node_id, transfer_id, priority, fd)
    assert frames_hex(frames) == expected
    assert set(frames["can_id"]) == {can_id}
    assert encoder.frames_per_sample == tuple((len(bytes.fromhex(h)), True, fd) for h in expected)
    decoded = decode_with_pydronecan(frames)
    assert decoded.payload.timestamp.usec == time_us and decoded.transfer_id == transfer_id


@SETTINGS
@given(accel=moderate_vector, gyro=moderate_vector, quat=st.lists(st.floats(-1, 1), min_size=4, max_size=4),
       transfer_id=st.integers(0, 31), fd=st.booleans())
def test_solution_matches_pydronecan(accel, gyro, quat, transfer_id, fd):
    sample = Samples.single(7_000_123_456, accel, gyro, quat=quat)
    frames = SolutionEncoder(node_id=11, priority=5, transfer_id=transfer_id, fd=fd).encode(sample)
    message = AHRS.Solution(orientation_xyzw=[float(quat[1]), float(quat[2]), float(quat[3]), float(quat[0])],
                            angular_velocity=[float(v) for v in gyro], linear_acceleration=[float(v) for v in accel])
    message.timestamp.usec = 7_000_123
    assert frames_hex(frames) == oracle_frames(message, 11, transfer_id, 5, fd)[1]
    decoded = decode_with_pydronecan(frames).payload
    packet, = DroneCanDecoder().feed_frames(frames)
    np.testing.assert_array_equal(packet.fields["quat"], [decoded.orientation_xyzw[i] for i in (3, 0, 1, 2)])
    np.testing.assert_array_equal(packet.fields["gyro"], list(decoded.angular_velocity))


@SETTINGS
@given(mag=moderate_vector, sensor_id=st.integers(0, 255), transfer_id=st.integers(0, 31), fd=st.booleans())
def test_mag2_matches_pydronecan(mag, sensor_id, transfer_id, fd):
    sample = Samples.single(0, [0, 0, 0], [0, 0, 0], mag=mag)
    frames = MagneticFieldStrength2Encoder(sensor_id=sensor_id, node_id=100, priority=20, transfer_id=transfer_id,
                                           fd=fd).encode(sample)
    message = AHRS.MagneticFieldStrength2(sensor_id=sensor_id, magnetic_field_ga=[float(v) for v in mag])
    assert frames_hex(frames) == oracle_frames(message, 100, transfer_id, 20, fd)[1]
    packet, = DroneCanDecoder().feed_frames(frames)
    assert packet.fields["sensor_id"] == sensor_id
    np.testing.assert_array_equal(packet.fields["mag"], list(decode_with_pydronecan(frames).payload.magnetic_field_ga))


def test_float16_conversion_equals_libuavcan_rounding():
    """Every half value, every midpoint between neighbours (the ties), subnormals and random floats give the
    bits of pydronecan's f16_from_f32 (libuavcan's algorithm)."""
    from dronecan.transport import f16_from_f32
    halves = np.arange(0, 0x7C00, dtype=np.uint16).view(np.float16).astype(np.float64)
    midpoints = (halves[:-1] + halves[1:]) / 2
    rng = np.random.default_rng(7)
    randoms = np.concatenate([rng.normal(0, 10, 3000), 10.0 ** rng.uniform(-9, 4.8, 3000)])
    values = np.concatenate([halves[::7], midpoints[::7], midpoints[:1200], randoms])
    values = np.concatenate([values, -values])
    bits32 = values.astype(np.float32).view(np.uint32).astype(np.int64)
    ours = [int(_f16_from_f32_bits(int(b))) for b in bits32]
    theirs = [f16_from_f32(float(v)) for v in values]
    assert ours == theirs


# --- multi-sample blocks and state --------------------------------------------------------------

def random_samples(n, seed=3, t0=0, scale=1.0):
    rng = np.random.default_rng(seed)
    return Samples(t0 + np.arange(n, dtype=np.int64) * 2_500_000, rng.normal(0, 5, (n, 3)) * scale,
                   rng.normal(0, 1, (n, 3)) * scale, mag=rng.normal(0, 0.5, (n, 3)),
                   quat=rng.normal(0, 1, (n, 4)))


def test_block_equals_per_sample_encoding_and_transfer_ids_continue():
    samples = random_samples(40)
    block = RawImuEncoder(transfer_id=30)
    single = RawImuEncoder(transfer_id=30)
    frames = np.concatenate([block.encode(samples.slice(0, 25)), block.encode(samples.slice(25, 40))])
    one_by_one = [single.encode(samples.slice(i, i + 1)) for i in range(40)]
    assert frames_hex(frames) == [h for f in one_by_one for h in frames_hex(f)]
    tails = frames["data"][np.arange(len(frames)), frames["length"] - 1]
    assert list(tails[::7] & 0x1F) == [(30 + i) % 32 for i in range(40)]
    assert list(tails[:7] & 0xE0) == [0x80, 0x20, 0x00, 0x20, 0x00, 0x20, 0x40]
    assert block.transfer_id == single.transfer_id == (30 + 40) % 32
    assert list(frames["sample"][:14]) == [0] * 7 + [1] * 7


def test_integration_interval_from_timestamps_across_calls():
    samples = random_samples(6)
    encoder = RawImuEncoder()
    transfers = ([decode_with_pydronecan(f) for f in np.split(encoder.encode(samples.slice(0, 3)), 3)]
                 + [decode_with_pydronecan(f) for f in np.split(encoder.encode(samples.slice(3, 6)), 3)])
    intervals = [t.payload.integration_interval for t in transfers]
    assert intervals[0] == 0.0                      # no previous sample: "integrals not available"
    np.testing.assert_allclose(intervals[1:], 0.0025, rtol=1e-7)
    np.testing.assert_allclose(list(transfers[4].payload.rate_gyro_integral), samples.gyro[4] * 0.0025, rtol=1e-3,
                               atol=1e-6)


def test_delta_fields_are_sent_as_integrals():
    samples = random_samples(3)
    samples.delta_theta = np.full((3, 3), 0.125)
    samples.delta_velocity = np.full((3, 3), -0.5)
    packets = DroneCanDecoder().feed_frames(RawImuEncoder(sample_period_s=0.001).encode(samples))
    assert [list(p.fields["delta_theta"]) for p in packets] == [[0.125] * 3] * 3
    assert [list(p.fields["delta_velocity"]) for p in packets] == [[-0.5] * 3] * 3


# --- saturation and errors ----------------------------------------------------------------------

@SETTINGS
@given(accel=vector, gyro=vector)
def test_saturation_never_inf_and_counted(accel, gyro):
    encoder = RawImuEncoder(sample_period_s=1.0)
    packet, = DroneCanDecoder().feed_frames(encoder.encode(Samples.single(5_000, accel, gyro)))
    for name, sent, field in (("accel", accel, "accelerometer_latest"), ("gyro", gyro, "rate_gyro_latest")):
        decoded = packet.fields[name]
        assert np.isfinite(decoded).all()
        over = int(np.sum(np.abs(sent) > 65504.0))
        assert encoder.saturated.counts.get(field, 0) == over
        big = np.abs(sent) > 65504.0
        np.testing.assert_array_equal(decoded[big], np.sign(np.array(sent))[big] * 65504.0)
    assert np.isfinite(packet.fields["delta_velocity"]).all()


def test_saturation_edges_and_timestamp_clamp():
    encoder = RawImuEncoder(sample_period_s=1.0)
    edge = [65504.0, -65504.0, 65519.99]
    samples = Samples(np.array([-5_000, 2**63 - 1]), [edge, [1e300, -1e300, 0.0]], [[0, 0, 0], [0, 0, 0]])
    packets = DroneCanDecoder().feed_frames(encoder.encode(samples))
    assert packets[0].fields["time_ns"] == 0 and packets[1].fields["time_ns"] == (2**63 - 1) // 1000 * 1000
    np.testing.assert_array_equal(packets[0].fields["accel"], [65504.0, -65504.0, 65504.0])
    assert packets[1].fields["delta_velocity"][0] == np.finfo(np.float32).max
    assert encoder.saturated.counts == {"timestamp": 1, "accelerometer_latest": 3, "accelerometer_integral": 2}


@pytest.mark.parametrize("field, index, name", [("accel", (0, 1), "accel"), ("gyro", (1, 2), "gyro"),
                                                ("delta_theta", (1, 0), "delta_theta")])
def test_nan_raises_naming_field(field, index, name):
    samples = random_samples(3)
    samples.delta_theta = np.zeros((3, 3))
    samples.delta_velocity = np.zeros((3, 3))
    getattr(samples, field)[index] = np.nan
    encoder = RawImuEncoder(sample_period_s=0.01, transfer_id=4)
    with pytest.raises(EncodeError, match=rf"'{name}' at sample {index[0]}, component {index[1]}"):
        encoder.encode(samples)
    assert encoder.transfer_id == 4 and encoder.saturated.total == 0


def test_nan_in_quat_and_mag():
    samples = random_samples(2)
    samples.quat[1, 0] = np.inf
    samples.mag[0, 2] = np.nan
    with pytest.raises(EncodeError, match="'quat' at sample 1, component 0"):
        SolutionEncoder().encode(samples)
    with pytest.raises(EncodeError, match="'mag' at sample 0, component 2"):
        MagneticFieldStrength2Encoder().encode(samples)


def test_bad_options():
    for kwargs in ({"node_id": 0}, {"node_id": 128}, {"priority": 32}, {"sample_period_s": -1.0}):
        with pytest.raises(ValueError):
            RawImuEncoder(**kwargs)


# --- decoder robustness -------------------------------------------------------------------------

def expected_packets(frames):
    return {(p.fields["transfer_id"], p.raw) for p in DroneCanDecoder().feed_frames(frames)}


def test_decoder_drops_broken_transfers():
    samples = random_samples(20)
    frames = RawImuEncoder(sample_period_s=0.0025).encode(samples)
    good = expected_packets(frames)
    assert len(good) == 20
    rows = list(range(len(frames)))
    del rows[7 * 3 + 2]                                  # lose a frame of transfer 3
    rows[7 * 5 + 1], rows[7 * 5 + 2] = rows[7 * 5 + 2], rows[7 * 5 + 1]   # swap two of transfer 5
    damaged = frames[rows].copy()
    damaged["data"][7 * 8 - 1 + 3, 2] ^= 0x10            # flip a payload bit in transfer 8 (one row removed)
    decoder = DroneCanDecoder()
    packets = decoder.feed_frames(damaged)
    got = {(p.fields["transfer_id"], p.raw) for p in packets}
    assert got <= good and len(got) == 17
    assert decoder.stats.bad_checksum == 1 and decoder.stats.ignored_frames > 0


def test_decoder_interleaved_sources_and_messages():
    a = RawImuEncoder(node_id=5).encode(random_samples(4, seed=1))
    b = RawImuEncoder(node_id=6).encode(random_samples(4, seed=2))
    m = MagneticFieldStrength2Encoder(node_id=5).encode(random_samples(4, seed=3))
    mixed = np.empty(len(a) + len(b) + len(m), dtype=a.dtype)
    mixed[0:56:2], mixed[1:56:2], mixed[56:] = a, b, m
    packets = DroneCanDecoder().feed_frames(mixed)
    assert sorted((p.kind.rsplit(".", 1)[1], p.fields["source_node_id"]) for p in packets) == sorted(
        [("RawIMU", 5)] * 4 + [("RawIMU", 6)] * 4 + [("MagneticFieldStrength2", 5)] * 4)
    assert DroneCanDecoder((1002,)).feed_frames(mixed).__len__() == 4


@SETTINGS
@given(st.lists(st.tuples(st.integers(0, 2**32 - 1), st.binary(min_size=0, max_size=70), st.booleans(),
                          st.booleans()), max_size=60),
       st.lists(st.integers(0, 139), max_size=30), st.integers(0, 2**16 - 1))
def test_decoder_fuzz_never_raises_never_corrupt(junk, drop, crc_flip):
    samples = random_samples(20, seed=crc_flip)
    frames = RawImuEncoder(node_id=9).encode(samples)
    good = expected_packets(frames)
    keep = [i for i in range(len(frames)) if i not in set(drop)]
    decoder = DroneCanDecoder()
    got = []
    for n, i in enumerate(keep):
        f = frames[i]
        data = bytearray(frame_bytes(f))
        if n == crc_flip % max(len(keep), 1):
            data[0] ^= 1 << (crc_flip % 8)
        got += decoder.feed_frame(int(f["can_id"]), bytes(data), True)
        if n < len(junk):
            can_id, payload, extended, fd = junk[n]
            got += decoder.feed_frame(can_id, payload, extended, fd)
    # Junk may legitimately form single-frame transfers of its own ids; from our id only originals come out.
    ours = [p for p in got if p.fields["source_node_id"] == 9 and p.fields["priority"] == 31
            and p.kind.endswith("RawIMU")]
    assert all((p.fields["transfer_id"], p.raw) in good for p in ours)


# --- registry and link budget ------------------------------------------------------------------

def test_registered_and_link_budget():
    raw = registered("dronecan-rawimu")
    assert raw.kind == "can" and raw.frames_per_sample == ((8, True, False),) * 7
    assert sum(can_bits_worst_case(*f) for f in raw.frames_per_sample) == 1120   # spec: 1.12 Mbit/s at 1 kHz
    assert registered("dronecan-solution").frames_per_sample == ((8, True, False),) * 4 + ((4, True, False),)
    assert registered("dronecan-mag2").frames_per_sample == ((8, True, False),)
    assert RawImuEncoder(fd=True).frames_per_sample == ((64, True, True),)
    assert SolutionEncoder(fd=True).frames_per_sample == ((32, True, True),)
    assert MagneticFieldStrength2Encoder(fd=True).frames_per_sample == ((12, True, True),)
    encoder = raw.encoder(node_id=3)
    frames = encoder.encode(random_samples(2))
    assert [(int(f["length"]), bool(f["extended"]), bool(f["fd"])) for f in frames[:7]] == list(raw.frames_per_sample)
    assert len(raw.decoder().feed_frames(frames)) == 2


def test_transfer_crc_is_ccitt_false_over_signature_then_payload():
    """The first two bytes of a multi-frame transfer, computed here with pydronecan's own CRC routine."""
    frames = RawImuEncoder().encode(random_samples(1))
    stream = b"".join(frame_bytes(f)[:-1] for f in frames)
    signature = struct.pack("<Q", AHRS.RawIMU.get_data_type_signature())
    assert stream[0] | stream[1] << 8 == crc16_from_bytes(signature + stream[2:])


def test_encode_into_reused_buffer_matches_encode():
    samples = random_samples(6)
    buffer = SolutionEncoder(fd=True).encode(random_samples(50, seed=9))     # stale FD rows to overwrite
    written = RawImuEncoder(transfer_id=7).encode_into(samples, buffer)
    fresh = RawImuEncoder(transfer_id=7).encode(samples)
    assert written == len(fresh) == 42
    assert frames_hex(buffer[:written]) == frames_hex(fresh)
    assert not buffer["fd"][:written].any() and list(buffer["sample"][:written]) == list(fresh["sample"])
    with pytest.raises(ValueError):
        RawImuEncoder().encode_into(samples, buffer[:41])
