"""Bosch MM7.10 TX1/TX2/TX3, checked with a decoder written here from the spec (wire-formats.md) and Bosch's
own ROS driver layout (off_highway_mm7p10 receiver.cpp), with a bit-by-bit CRC-8/SAE-J1850 (the CRC
algorithm itself is UNVERIFIED for this sensor, see firmware_protocols/wire_formats/bosch.py)."""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from firmware_protocols import registry
from firmware_protocols.base import EncodeError, Samples, can_bits_worst_case, frame_bytes
from firmware_protocols.wire_formats.bosch import BoschMM7Decoder, BoschMM7Encoder

SETTINGS = settings(derandomize=True, deadline=None, max_examples=60,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
G = 9.80665
FLU = np.array([1.0, -1.0, -1.0])      # Samples are FRD; the chip reports forward-left-up axes
LAYOUT = {  # id -> {signal: (start bit, length)}, little-endian
    0x174: {"rate": (0, 16), "stat": (20, 4), "temp": (24, 8), "acc": (32, 16), "cnt": (48, 4), "acc_stat": (52, 4),
            "crc": (56, 8)},
    0x178: {"rate": (0, 16), "stat": (20, 4), "acc": (32, 16), "cnt": (48, 4), "acc_stat": (52, 4), "crc": (56, 8)},
    0x17C: {"rate": (0, 16), "hw": (16, 4), "stat": (20, 4), "acc": (32, 16), "cnt": (48, 4), "acc_stat": (52, 4),
            "crc": (56, 8)},
}


def crc8_j1850_bitwise(data: bytes) -> int:
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def spec_decode(can_id: int, data: bytes) -> dict:
    word = int.from_bytes(data, "little")
    raw = {name: (word >> start) & ((1 << length) - 1) for name, (start, length) in LAYOUT[can_id].items()}
    out = dict(raw)
    out["rate"] = math.radians(raw["rate"] * 0.005 - 163.84)
    out["acc"] = (raw["acc"] * 0.000127465 - 4.1768) * G
    if "temp" in raw:
        out["temp"] = raw["temp"] - 50
    out["crc_ok"] = crc8_j1850_bitwise(data[:7]) == data[7]
    return out


def test_crc_check_value():
    assert crc8_j1850_bitwise(b"123456789") == 0x4B        # CRC-8/SAE-J1850 catalogue check value


def test_spec_layout_and_default_axes():
    # The chip's forward-left-up axes: yaw = +z, roll = -x (Bosch's driver), pitch = +y; AX/AY/AZ = +x/+y/+z.
    # Samples are forward-right-down: this one is (0.1, -0.2, 9.80665) and (0.01, -0.02, 0.03) in FLU, a part
    # at rest reading +1 g on AZ as the datasheet's upright part does.
    sample = Samples.single(0, [0.1, 0.2, -9.80665], [0.01, 0.02, -0.03], temperature_c=[31.4])
    frames = BoschMM7Encoder().encode(sample)
    assert [int(f["can_id"]) for f in frames] == [0x174, 0x178, 0x17C]
    assert not frames["extended"].any() and (frames["length"] == 8).all()
    tx1, tx2, tx3 = (spec_decode(int(f["can_id"]), frame_bytes(f)) for f in frames)
    assert all(t["crc_ok"] for t in (tx1, tx2, tx3))
    assert tx1["rate"] == pytest.approx(0.03, abs=math.radians(0.0025))
    assert tx2["rate"] == pytest.approx(-0.01, abs=math.radians(0.0025))
    assert tx3["rate"] == pytest.approx(-0.02, abs=math.radians(0.0025))
    assert (tx1["acc"], tx2["acc"], tx3["acc"]) == pytest.approx((-0.2, 0.1, 9.80665), abs=0.000064 * G)
    assert tx1["temp"] == 31 and tx3["hw"] == 0
    assert {t["stat"] for t in (tx1, tx2, tx3)} == {0} and {t["acc_stat"] for t in (tx1, tx2, tx3)} == {0}


def test_counter_shared_and_continues_across_calls():
    encoder = BoschMM7Encoder(counter=13)
    rng = np.random.default_rng(2)
    counters = []
    for n in (5, 1, 14):
        frames = encoder.encode(Samples(np.arange(n), rng.normal(0, 3, (n, 3)), rng.normal(0, 1, (n, 3))))
        decoded = [spec_decode(int(f["can_id"]), frame_bytes(f)) for f in frames]
        assert all(d["crc_ok"] for d in decoded)
        for k in range(n):
            trio = {d["cnt"] for d in decoded[3 * k:3 * k + 3]}
            assert len(trio) == 1
            counters.append(trio.pop())
        assert list(frames["sample"]) == list(np.repeat(np.arange(n), 3))
    assert counters == [(13 + i) % 16 for i in range(20)]


@SETTINGS
@given(gyro=st.lists(st.floats(-3.2, 3.2), min_size=3, max_size=3),
       accel=st.lists(st.floats(-4.5 * G, 4.5 * G), min_size=3, max_size=3), temp=st.floats(-80, 200))
def test_round_trip_with_saturation(gyro, accel, temp):
    encoder = BoschMM7Encoder()
    frames = encoder.encode(Samples.single(0, accel, gyro, temperature_c=[temp]))
    tx1, tx2, tx3 = (spec_decode(int(f["can_id"]), frame_bytes(f)) for f in frames)
    gyro, accel = np.asarray(gyro) * FLU + 0.0, np.asarray(accel) * FLU + 0.0     # the chip's axes
    wire_rates = (gyro[2], -gyro[0], gyro[1])
    wire_accels = (accel[1], accel[0], accel[2])
    rate_lo, rate_hi = math.radians(-163.84), math.radians(65534 * 0.005 - 163.84)
    acc_lo, acc_hi = -4.1768 * G, (65534 * 0.000127465 - 4.1768) * G
    for tx, rate, acc in zip((tx1, tx2, tx3), wire_rates, wire_accels):
        assert tx["rate"] == pytest.approx(min(max(rate, rate_lo), rate_hi), abs=math.radians(0.0025) + 1e-12)
        assert tx["acc"] == pytest.approx(min(max(acc, acc_lo), acc_hi), abs=0.0000638 * G)
        assert tx["crc_ok"]
    assert tx1["temp"] == min(max(round(temp), -50), 150)
    expected = (sum(not rate_lo - 1e-7 <= r <= rate_hi + 1e-7 for r in wire_rates)
                + sum(not acc_lo - 1e-5 <= a <= acc_hi + 1e-5 for a in wire_accels)
                + (not -50.5 <= temp <= 150.5))
    assert encoder.saturated.total == expected
    packet, = BoschMM7Decoder().feed_frames(frames)
    np.testing.assert_allclose(packet.fields["gyro"], [tx2["rate"] * -1, tx3["rate"], tx1["rate"]])


def test_saturation_edges_never_reach_ffff():
    encoder = BoschMM7Encoder()
    # FLU accel (1e6, -1e6, 0) and rate (1e6, -1e6, 1e6), given as FRD Samples
    frames = encoder.encode(Samples.single(0, [1e6, 1e6, 0.0], [1e6, 1e6, -1e6], temperature_c=[1000.0]))
    raw = [(int.from_bytes(frame_bytes(f)[0:2], "little"), int.from_bytes(frame_bytes(f)[4:6], "little"))
           for f in frames]
    assert raw == [(65534, 0), (0, 65534), (0, 32768)]   # yaw +z, roll -x, pitch +y; AY, AX, AZ
    assert frame_bytes(frames[0])[3] == 200
    assert encoder.saturated.counts == {"yaw_rate": 1, "roll_rate": 1, "pitch_rate": 1, "ax": 1, "ay": 1,
                                    "temperature": 1}


@pytest.mark.parametrize("field", ["gyro", "accel", "temperature_c"])
def test_nan_raises_naming_field(field):
    samples = Samples(np.arange(3), np.zeros((3, 3)), np.zeros((3, 3)), temperature_c=np.zeros(3))
    value = getattr(samples, field)
    value[(1, 2) if value.ndim == 2 else 1] = np.nan
    with pytest.raises(EncodeError, match=rf"'{field}' at sample 1"):
        BoschMM7Encoder().encode(samples)


def make_frames(n, seed=0):
    rng = np.random.default_rng(seed)
    samples = Samples(np.arange(n), rng.normal(0, 3, (n, 3)), rng.normal(0, 1, (n, 3)))
    return samples, BoschMM7Encoder().encode(samples)


def test_decoder_drops_incomplete_and_bad_sets():
    samples, frames = make_frames(10)
    rows = list(range(30))
    del rows[3 * 2 + 1]                                         # sample 2 loses TX2
    rows[3 * 4 - 1 + 1], rows[3 * 4 - 1 + 2] = rows[3 * 4 - 1 + 2], rows[3 * 4 - 1 + 1]  # sample 4: TX3 before TX2
    damaged = frames[rows].copy()
    damaged["data"][3 * 7 - 1, 4] ^= 0x01                       # sample 7 TX1 payload bit: CRC mismatch
    decoder = BoschMM7Decoder()
    packets = decoder.feed_frames(damaged)
    assert [p.fields["counter"] for p in packets] == [0, 1, 3, 5, 6, 8, 9]
    for p in packets:
        np.testing.assert_allclose(p.fields["gyro"], samples.gyro[p.fields["counter"]] * FLU,      # chip axes
                                   atol=math.radians(0.003))
    assert decoder.stats.bad_checksum == 1 and decoder.stats.ignored_frames > 0


def test_decoder_rejects_mixed_counters():
    _, a = make_frames(2, seed=1)
    mixed = a[[0, 4, 5]]                                        # TX1 of sample 0 with TX2/TX3 of sample 1
    decoder = BoschMM7Decoder()
    assert decoder.feed_frames(mixed) == [] and decoder.stats.ignored_frames == 3


@SETTINGS
@given(st.lists(st.tuples(st.sampled_from([0x174, 0x178, 0x17C, 0x100, 2**29]), st.binary(max_size=12),
                          st.booleans(), st.booleans()), max_size=60), st.integers(0, 2**16))
def test_decoder_fuzz_never_raises_never_corrupt(junk, seed):
    samples, frames = make_frames(8, seed=seed)
    good = {p.raw for p in BoschMM7Decoder().feed_frames(frames)}
    decoder = BoschMM7Decoder()
    got = []
    for i, f in enumerate(frames):
        got += decoder.feed_frame(int(f["can_id"]), frame_bytes(f), False)
        if i < len(junk):
            got += decoder.feed_frame(*junk[i])
    for p in got:
        # A packet is either an original sample or three frames whose CRCs and counters all check out.
        assert p.raw in good or all(spec_decode(i, p.raw[8 * k:8 * k + 8])["crc_ok"]
                                    for k, i in enumerate((0x174, 0x178, 0x17C)))


def test_registry_and_link_budget():
    info = registry._REGISTRY["bosch-mm7"]
    assert info.kind == "can" and info.frames_per_sample == ((8, False, False),) * 3
    assert sum(can_bits_worst_case(*f) for f in info.frames_per_sample) == 405     # spec: 405 kbit/s at 1 kHz
    samples, frames = make_frames(4)
    assert len(info.decoder().feed_frames(info.encoder().encode(samples))) == 4
