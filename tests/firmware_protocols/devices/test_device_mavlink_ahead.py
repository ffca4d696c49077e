"""The MAVLink device encodes ahead (issue 25): while only its main message is due, `output` encodes the next
`ahead` samples of a block in one call and hands their packets out one by one, taking the unsent ones back when
something may change what is due (a command, a sample asked for out of turn, a range). Oracles: pymavlink decoding
the wire (sequence numbers continuous across packets and replies; a rate change or one-off request acting from the
sample after the command, as common.xml has it), and a device encoding one sample per call (`ahead = 1`, the path
every packet took before)."""
import numpy as np
import pytest

import firmware_protocols
from firmware_protocols import EncodeError, Samples
from firmware_protocols.devices.base import view

mavlink2 = pytest.importorskip("pymavlink.dialects.v20.common")
from tests.support.devices import command_long, gcs  # noqa: E402

RATE = 100.0
N = 450                      # heartbeats at samples 0, 100, 200, 300 and 400
BLOCKS = (0, 7, 207, N)      # the sender's blocks: a range encoded ahead never runs past one
HIGHRES, HIL_GPS, HEARTBEAT = 105, 113, 0
REQUEST, GET_INTERVAL = 512, 510


def _samples(n=N, gnss_every=None):
    """Values that change every sample, so a packet from the wrong sample shows; with gnss_every, a GNSS fix new
    every that many samples (a GNSS message has packets at those samples alone)."""
    k = np.arange(n)[:, None]
    angles = 0.01 * k + np.array([0.0, 1.0, 2.0])
    gnss = {}
    if gnss_every:
        gnss = dict(gnss_llh=np.hstack([0.8 + 1e-7 * k, 0.1 + 1e-7 * k, 100 + 0.01 * k]),
                    gnss_velocity_ned=0.1 * np.cos(angles), gnss_fix=np.full(n, 3.0), gnss_satellites=np.full(n, 9.0),
                    gnss_hdop=np.full(n, 0.9), gnss_vdop=np.full(n, 1.2),
                    gnss_new=(np.arange(n) % gnss_every == 3).astype(float))
    return Samples((np.arange(n) * 1e7).astype(np.int64), 9.8 * np.sin(angles), 0.1 * np.cos(angles), **gnss)


def _commands(msgid):
    """Commands arriving between samples, none at a multiple of the range length."""
    return {37: command_long(msgid, 20_000),                 # every other sample
            90: command_long(msgid, 0),                      # the default rate again
            141: command_long(msgid, command=REQUEST),       # one now (it is due anyway)
            203: command_long(HEARTBEAT, command=REQUEST),   # a heartbeat now, between two of its own
            333: command_long(msgid, command=GET_INTERVAL)}  # a reply only


def _wire(device, samples, commands, prepare=False):
    """Per sample, the replies to the commands arriving before it, then what the device sends for it; the
    samples go to the device block by block, as the sender's blocks. `prepare`: the device is told to prepare
    each sample before the commands arrive, as the send loop does when it has slack."""
    out = []
    for a, b in zip(BLOCKS, BLOCKS[1:]):
        block = view(samples, a, b)
        for m in range(a, b):
            if prepare:
                device.prepare(block, m - a)
            replies = b"".join(device.receive(commands[m])) if m in commands else b""
            out.append((replies, device.output(block, m - a)))
    return out


def _pair(fmt, **options):
    ahead = firmware_protocols.create_device(fmt, RATE, **options)
    one = firmware_protocols.create_device(fmt, RATE, **options)
    one.ahead = 1
    assert ahead.ahead > 4
    return ahead, one


@pytest.mark.parametrize("fmt, msgid, gnss_every, options", [
    ("mavlink-highres", HIGHRES, None, {}),
    ("mavlink-hil-gps", HIL_GPS, 20, {}),          # packets at new fixes only: sequence numbers skip none
    ("mavlink-highres", HIGHRES, 20, {"also": "mavlink-hil-gps"})])
@pytest.mark.parametrize("prepare", [False, True])
def test_ahead_sends_what_one_sample_at_a_time_sends(fmt, msgid, gnss_every, options, prepare):
    samples, commands = _samples(gnss_every=gnss_every), _commands(msgid)
    ahead, one = _pair(fmt, **options)
    got, expected = _wire(ahead, samples, commands, prepare), _wire(one, samples, commands)
    assert got == expected
    assert sum(len(packet) for _, packet in got) > 0


def test_the_wire_stays_numbered_and_commands_act_from_the_next_sample():
    ahead, _ = _pair("mavlink-highres")
    wire = _wire(ahead, _samples(), _commands(HIGHRES))
    messages = gcs().parse_buffer(b"".join(replies + packet for replies, packet in wire))
    kinds = [m.get_type() for m in messages]
    assert {kind: kinds.count(kind) for kind in set(kinds)} == {"HIGHRES_IMU": N - 26, "HEARTBEAT": 6,
                                                                 "COMMAND_ACK": 5, "MESSAGE_INTERVAL": 1}
    assert set(np.diff([m.get_seq() for m in messages]) % 256) == {1}
    # which samples carried HIGHRES_IMU (10 ms a sample): every one, every other from 37, every one from 90
    imu = [m.time_usec // 10_000 for m in messages if m.get_type() == "HIGHRES_IMU"]
    assert imu == [*range(37), *range(37, 90, 2), *range(90, N)]
    beats = [m for m in gcs().parse_buffer(b"".join(packet for _, packet in wire)) if m.get_type() == "HEARTBEAT"]
    heartbeat_at = [m for m, (_, packet) in enumerate(wire) if b"\xfd\x09" in packet[:2]]
    assert len(beats) == 6 and heartbeat_at == [0, 100, 200, 203, 300, 400]
    interval = [m for m in messages if m.get_type() == "MESSAGE_INTERVAL"]
    assert [(m.message_id, m.interval_us) for m in interval] == [(HIGHRES, 10_000)]


def test_saturation_is_counted_for_the_packets_sent_only():
    """SCALED_IMU carries mG in int16: 400 m/s^2 saturates. The counts after each sample are those of the samples
    sent so far, though a range encoded ahead holds later ones."""
    samples = _samples()
    samples.accel[[21, 22, 150], 0] = 400.0
    ahead, one = _pair("mavlink-scaled-imu")
    counts = []
    for device in (ahead, one):
        block = view(samples, 0, N)
        counts.append([(device.output(block, m), device.saturated) for m in range(N)])
    assert counts[0] == counts[1]
    assert [m for m in range(1, N) if counts[0][m][1] != counts[0][m - 1][1]] == [21, 22, 150]


def test_a_value_that_is_not_finite_stops_the_device_at_its_sample():
    samples = _samples()
    samples.accel[25, 1] = np.nan
    ahead, one = _pair("mavlink-highres")
    block = view(samples, 0, N)
    sent = [ahead.output(block, m) for m in range(25)]
    assert sent == [one.output(block, m) for m in range(25)]
    for device in (ahead, one):
        with pytest.raises(EncodeError, match="accel"):
            device.output(block, 25)


def test_a_range_asked_for_starts_with_what_was_encoded_ahead():
    """The sender catching up asks for a range while packets encoded ahead are unsent: the range starts with
    them, the rest numbered in turn."""
    samples = _samples()
    ahead, one = _pair("mavlink-highres")
    block = view(samples, 0, N)
    got = [ahead.output(block, m) for m in range(21)]       # the heartbeat's, then 16 to 31 encoded at once
    assert ahead._ahead is not None
    got += ahead.output_many(block, 21, 25)          # within those encoded ahead
    got += ahead.output_many(block, 25, 40) + [ahead.output(block, m) for m in range(40, 43)]    # past them
    assert got == [one.output(block, m) for m in range(43)]
    assert len(set(got)) == 43
