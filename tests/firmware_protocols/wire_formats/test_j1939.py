"""SAE J1939 ARI + ACCS, checked against the spec's vectors and with cantools reading a DBC written from the
spec (tests/data/j1939_imu.dbc) as the independent decoder and encoder."""
import math

import cantools
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware_protocols import registry
from firmware_protocols.base import EncodeError, Samples, can_bits_worst_case, frame_bytes
from firmware_protocols.wire_formats.j1939 import AxisMap, J1939Decoder, J1939Encoder
from tests.support.paths import DATA

SETTINGS = settings(derandomize=True, deadline=None, max_examples=60,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
DB = cantools.database.load_file(DATA / "j1939_imu.dbc")
ARI = DB.get_message_by_name("ARI")
ACCS = DB.get_message_by_name("ACCS")

# wire-formats.md, "SAE J1939 IMU messages": source address 0x90, ARI priority 3, ACCS priority 2.
SPEC_SAMPLE = Samples.single(1_234_567_000, [0.1, -0.2, -9.80665], [0.01, -0.02, 0.03])
SPEC_ARI = (0x0CF02A90, "6d7c497ddc7dc005")
SPEC_ACCS = (0x08F02D90, "ec7c0a7dd58000ff")


def registered(name):
    return registry._REGISTRY[name]


def test_spec_vectors():
    frames = J1939Encoder(source_address=0x90, ari_priority=3, accs_priority=2, latency_s=0.0025).encode(SPEC_SAMPLE)
    assert [(int(f["can_id"]), frame_bytes(f).hex()) for f in frames] == [SPEC_ARI, SPEC_ACCS]
    assert frames["extended"].all() and list(frames["sample"]) == [0, 0]


def test_spec_vectors_read_by_cantools():
    ari = ARI.decode(bytes.fromhex(SPEC_ARI[1]), decode_choices=False)
    accs = ACCS.decode(bytes.fromhex(SPEC_ACCS[1]), decode_choices=False)
    assert ARI.frame_id == SPEC_ARI[0] and ACCS.frame_id == SPEC_ACCS[0]
    assert ari["PitchRate"] == pytest.approx(math.degrees(-0.02), abs=1 / 256)
    assert ari["RollRate"] == pytest.approx(math.degrees(0.01), abs=1 / 256)
    assert ari["YawRate"] == pytest.approx(math.degrees(0.03), abs=1 / 256)
    assert ari["AngularRateMeasurementLatency"] == 2.5
    assert (accs["VerticalAcceleration"], accs["LateralAcceleration"], accs["LongitudinalAcceleration"]) == \
        pytest.approx((9.81, -0.2, 0.1), abs=1e-9)


rates = st.floats(-4.5, 4.5)               # rad/s, beyond the ±250 deg/s (4.36 rad/s) the message holds
accels = st.floats(-340.0, 340.0)          # m/s², beyond -320..322.55
vec = lambda s: st.lists(s, min_size=3, max_size=3)  # noqa: E731


@SETTINGS
@given(gyro=vec(rates), accel=vec(accels), sa=st.integers(0, 253), pri=st.integers(0, 7),
       fom=st.lists(st.integers(0, 3), min_size=6, max_size=6), latency=st.floats(0, 0.2))
def test_cantools_decodes_and_reencodes_identically(gyro, accel, sa, pri, fom, latency):
    encoder = J1939Encoder(source_address=sa, ari_priority=pri, accs_priority=7 - pri, rate_fom=fom[:3],
                           accel_fom=fom[3:], latency_s=latency)
    ari_frame, accs_frame = encoder.encode(Samples.single(0, accel, gyro))
    assert int(ari_frame["can_id"]) == (pri << 26) | (0xF02A << 8) | sa
    assert int(accs_frame["can_id"]) == ((7 - pri) << 26) | (0xF02D << 8) | sa
    ari = ARI.decode(frame_bytes(ari_frame), decode_choices=False)
    accs = ACCS.decode(frame_bytes(accs_frame), decode_choices=False)
    # Values: rounded to the nearest step or saturated to the valid range, never wrapped.
    for name, value in (("PitchRate", gyro[1]), ("RollRate", gyro[0]), ("YawRate", gyro[2])):
        expected = min(max(math.degrees(value), -250.0), 251.9921875)
        assert ari[name] == pytest.approx(expected, abs=1 / 256 + 1e-9)
    for name, value in (("LateralAcceleration", accel[1]), ("LongitudinalAcceleration", accel[0]),
                        ("VerticalAcceleration", -accel[2])):
        assert accs[name] == pytest.approx(min(max(value, -320.0), 322.55), abs=0.005 + 1e-9)
    assert [ari[n] for n in ("PitchRateFigureOfMerit", "RollRateFigureOfMerit", "YawRateFigureOfMerit")] == fom[:3]
    assert ari["AngularRateMeasurementLatency"] == pytest.approx(min(latency * 1000, 125), abs=0.25 + 1e-9)
    # cantools encoding the values it read gives our bytes back.
    assert ARI.encode(ari, scaling=True, strict=False) == frame_bytes(ari_frame)
    assert ACCS.encode(accs, scaling=True, strict=False) == frame_bytes(accs_frame)


@SETTINGS
@given(gyro=vec(st.floats(-1e6, 1e6)), accel=vec(st.floats(-1e6, 1e6)))
def test_saturation_counts_and_never_reaches_reserved_codes(gyro, accel):
    encoder = J1939Encoder()
    frames = encoder.encode(Samples.single(0, accel, gyro))
    for f in frames:
        data = frame_bytes(f)
        for byte in (0, 2, 4):
            assert data[byte] | data[byte + 1] << 8 <= 0xFAFF
    over_rate = sum(not -250.0 - 1 / 256 <= math.degrees(g) <= 0xFAFF / 128 - 250 + 1 / 256 for g in gyro)
    over_accel = sum(not -320.005 <= a <= 322.555 for a in (accel[0], accel[1], -accel[2]))
    rate_counts = sum(encoder.saturated.counts.get(n, 0) for n in ("pitch_rate", "roll_rate", "yaw_rate"))
    accel_counts = sum(encoder.saturated.counts.get(n, 0) for n in
                       ("lateral_acceleration", "longitudinal_acceleration", "vertical_acceleration"))
    assert (rate_counts, accel_counts) == (over_rate, over_accel)


def test_saturation_edges():
    encoder = J1939Encoder(latency_s=1.0)
    top = math.radians(0xFAFF / 128 - 250)
    samples = Samples(np.arange(3), [[322.55, -320.0, 0.0], [322.56, -320.01, 0.0], [1e9, -1e9, 0]],
                      [[top, math.radians(-250.0), 0.0], [top + 1e-3, math.radians(-250.1), 0], [1e9, -1e9, 0]])
    frames = encoder.encode(samples)
    raw = lambda f, b: frame_bytes(f)[b] | frame_bytes(f)[b + 1] << 8  # noqa: E731
    assert [raw(frames[i], 2) for i in (0, 2, 4)] == [0xFAFF] * 3      # roll rate = +gyro x
    assert [raw(frames[i], 0) for i in (0, 2, 4)] == [0] * 3           # pitch rate = +gyro y
    assert [raw(frames[i], 2) for i in (1, 3, 5)] == [0xFAFF] * 3      # longitudinal = +accel x
    assert [raw(frames[i], 0) for i in (1, 3, 5)] == [0] * 3           # lateral = +accel y
    assert frame_bytes(frames[0])[7] == 0xFA                            # 1 s latency -> 125 ms
    assert encoder.saturated.counts == {"latency": 1, "roll_rate": 2, "pitch_rate": 2,
                                    "longitudinal_acceleration": 2, "lateral_acceleration": 2}


def test_custom_axis_map():
    # A vendor convention: pitch = -y, roll = +x, yaw = -z; lateral = -y, longitudinal = +x, vertical = +z.
    encoder = J1939Encoder(rate_axes=((1, 0, 2), (-1, 1, -1)), accel_axes=AxisMap((1, 0, 2), (-1, 1, 1)))
    decoder = J1939Decoder(rate_axes=((1, 0, 2), (-1, 1, -1)), accel_axes=AxisMap((1, 0, 2), (-1, 1, 1)))
    ari, accs = decoder.feed_frames(encoder.encode(SPEC_SAMPLE))
    assert ari.fields["pitch_rate"] == pytest.approx(0.02, abs=1e-4)
    assert ari.fields["yaw_rate"] == pytest.approx(-0.03, abs=1e-4)
    assert accs.fields["vertical_acceleration"] == pytest.approx(-9.81, abs=0.006)
    np.testing.assert_allclose(ari.fields["gyro"], SPEC_SAMPLE.gyro[0], atol=1e-4)
    np.testing.assert_allclose(accs.fields["accel"], SPEC_SAMPLE.accel[0], atol=0.006)
    with pytest.raises(ValueError):
        J1939Encoder(rate_axes=((0, 0, 2), (1, 1, 1)))
    with pytest.raises(ValueError):
        J1939Encoder(accel_axes=((0, 1, 2), (1, 2, 1)))


@SETTINGS
@given(gyro=vec(st.floats(-4.3, 4.3)), accel=vec(st.floats(-300, 300)))
def test_round_trip_own_decoder(gyro, accel):
    packets = J1939Decoder().feed_frames(J1939Encoder().encode(Samples.single(0, accel, gyro)))
    assert [p.kind for p in packets] == ["ARI", "ACCS"]
    np.testing.assert_allclose(packets[0].fields["gyro"], gyro, atol=math.radians(1 / 256) + 1e-12)
    np.testing.assert_allclose(packets[1].fields["accel"], accel, atol=0.005 + 1e-9)


@pytest.mark.parametrize("field", ["gyro", "accel"])
def test_nan_raises_naming_field(field):
    samples = Samples(np.arange(4), np.zeros((4, 3)), np.zeros((4, 3)))
    getattr(samples, field)[2, 1] = np.nan
    with pytest.raises(EncodeError, match=rf"'{field}' at sample 2, component 1"):
        J1939Encoder().encode(samples)


def test_decoder_not_available_and_foreign_frames():
    decoder = J1939Decoder()
    ari, = decoder.feed_frame(0x0CF02A90, bytes.fromhex("ffff00fe497dc0ff"), True)
    assert math.isnan(ari.fields["pitch_rate"]) and math.isnan(ari.fields["roll_rate"])
    assert math.isnan(ari.fields["latency_s"])
    for frame in ((0x0CF02A90, b"\x00" * 7, True), (0x0CF02A90, b"\x00" * 8, False), (0x18FEF100, b"\x00" * 8, True)):
        assert decoder.feed_frame(*frame) == []
    assert decoder.stats.ignored_frames == 3 and decoder.stats.packets == 1


@SETTINGS
@given(st.lists(st.tuples(st.integers(-5, 2**32), st.binary(max_size=70), st.booleans(), st.booleans()),
                max_size=50))
def test_decoder_fuzz_never_raises(frames):
    decoder = J1939Decoder()
    for can_id, data, extended, fd in frames:
        for packet in decoder.feed_frame(can_id, data, extended, fd):
            assert packet.kind in ("ARI", "ACCS") and len(packet.raw) == 8
    assert decoder.stats.packets + decoder.stats.ignored_frames == len(frames)


def test_block_and_registry():
    info = registered("j1939")
    assert info.kind == "can" and info.frames_per_sample == ((8, True, False), (8, True, False))
    assert sum(can_bits_worst_case(*f) for f in info.frames_per_sample) == 320      # spec: 320 kbit/s at 1 kHz
    rng = np.random.default_rng(5)
    samples = Samples(np.arange(50), rng.normal(0, 5, (50, 3)), rng.normal(0, 1, (50, 3)))
    frames = info.encoder().encode(samples)
    assert list(frames["sample"]) == list(np.repeat(np.arange(50), 2))
    packets = info.decoder().feed_frames(frames)
    assert len(packets) == 100
    np.testing.assert_allclose([p.fields["gyro"] for p in packets[::2]], samples.gyro, atol=1e-4)
