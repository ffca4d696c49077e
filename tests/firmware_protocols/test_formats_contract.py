"""Every registered format keeps the contract the streaming layer and the CLI rely on."""
import numpy as np
import pytest

import firmware_protocols as fp
from firmware_protocols.base import FRAME_DTYPES, SaturationStats, can_bits_worst_case

NAMES = list(fp.formats())


def _samples(n=5, scale=1.0):
    rng = np.random.default_rng(3)
    return fp.Samples(time_ns=1_000_000_000 + np.arange(n, dtype=np.int64) * 1_000_000,
                      accel=rng.uniform(-9, 9, (n, 3)) * scale, gyro=rng.uniform(-2, 2, (n, 3)) * scale,
                      mag=rng.uniform(-0.5, 0.5, (n, 3)) * scale, quat=np.tile([1.0, 0, 0, 0], (n, 1)),
                      euler=np.zeros((n, 3)), temperature_c=np.full(n, 25.0), pressure_pa=np.full(n, 101325.0))


def test_registry_lists_the_issue_formats():
    for name in ("mavlink-highres", "vectornav-binary", "xsens-mtdata2", "microstrain-mip", "dronecan-rawimu",
                 "j1939", "bosch-mm7"):
        assert name in NAMES


@pytest.mark.parametrize("name", NAMES)
def test_encoder_contract(name):
    info = fp.get(name)
    encoder = fp.create_encoder(name)
    assert isinstance(encoder.saturated, SaturationStats)
    out = encoder.encode(_samples())
    if info.kind == "serial":
        assert isinstance(out, fp.SerialBatch) and len(out) == 5
        assert info.bytes_per_sample > 0 and encoder.bytes_per_sample > 0
        # declared size is the worst case per sample
        assert max(len(out.packet(i)) for i in range(5)) <= encoder.bytes_per_sample
    else:
        assert info.kind == "can" and out.dtype in FRAME_DTYPES
        per_sample = encoder.frames_per_sample
        if getattr(encoder, "frames_vary", False):    # messages at their own sensors' rates: the worst case
            assert 0 < len(out) <= 5 * len(per_sample)
        else:
            assert len(out) == 5 * len(per_sample)
        assert sorted(set(out["sample"].tolist())) == [0, 1, 2, 3, 4]
        assert all(can_bits_worst_case(length, ext, fd) > 0 for length, ext, fd in per_sample)
        assert out["length"].max() <= max(length for length, _, _ in per_sample)


@pytest.mark.parametrize("name", NAMES)
def test_decoder_reads_back_what_the_encoder_wrote(name):
    info = fp.get(name)
    out = fp.create_encoder(name).encode(_samples())
    decoder = fp.create_decoder(name)
    if info.kind == "serial":
        packets = decoder.feed(out.data)
    else:
        packets = decoder.feed_frames(out)
    # one packet per sample, or one per message where a sample is several messages (J1939: ARI + ACCS)
    assert len(packets) >= 5 and len(packets) % 5 == 0
    assert decoder.stats.bad_checksum == 0


@pytest.mark.parametrize("name", NAMES)
def test_saturation_is_counted_not_wrapped(name):
    encoder = fp.create_encoder(name)
    samples = _samples(scale=1e39)             # beyond float32 and every integer field
    # the sensor head's other readings too: formats carrying only pressure, temperature or a GNSS fix saturate there
    samples.pressure_pa, samples.temperature_c = samples.pressure_pa * 1e39, samples.temperature_c * 1e39
    samples.gnss_llh = samples.gnss_velocity_ned = np.full((len(samples), 3), 1e39)
    encoder.encode(samples)
    assert encoder.saturated.total > 0
