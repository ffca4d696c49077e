"""Device.output_many (a sender catching up asks for several samples at once) gives exactly what `output` gives
sample by sample: the oracle is a second, identical device asked one sample at a time, across heartbeats, rate
changes and one-off requests arriving between the ranges."""
import numpy as np
import pytest

import firmware_protocols
from firmware_protocols import Samples

mavlink2 = pytest.importorskip("pymavlink.dialects.v20.common")
from tests.support.devices import command_long  # noqa: E402

RATE = 100.0
N = 450             # 4.5 s: heartbeats at samples 0, 100, 200, 300 and 400
# range sizes, cycled: ones that end before a heartbeat, span one, or are too short to encode at once
SIZES = (1, 7, 50, 93, 2, 120, 33)


def _samples(n=N):
    """Values that change every sample, so a packet from the wrong sample shows."""
    k = np.arange(n)[:, None]
    angles = 0.01 * k + np.array([0.0, 1.0, 2.0])
    quat = np.hstack([np.cos(0.005 * k), np.sin(0.005 * k), np.zeros((n, 2))])
    return Samples((np.arange(n) * 1e7).astype(np.int64), 9.8 * np.sin(angles), 0.1 * np.cos(angles),
                   quat=quat, euler=np.zeros((n, 3)))


def _both(fmt, commands, **options):
    """(sample by sample, by ranges): each a list of what was sent per sample; commands {sample: bytes} reach both
    devices just before that sample (the ranges start there)."""
    samples = _samples()
    one = firmware_protocols.create_device(fmt, RATE, **options)
    one.ahead = 1           # one encoder call per sample (test_device_mavlink_ahead.py: `output` encoding ahead)
    many = firmware_protocols.create_device(fmt, RATE, **options)
    expected = []
    for m in range(N):
        if m in commands:
            one.receive(commands[m])
        expected.append(one.output(samples, m))
    got, m, sizes = [], 0, iter(SIZES * N)
    while m < N:
        if m in commands:
            many.receive(commands[m])
        k = min(m + next(sizes), N, *(c for c in commands if c > m))
        got += many.output_many(samples, m, k)
        m = k
    return expected, got


@pytest.mark.parametrize("fmt, options", [("mavlink-highres", {}), ("mavlink-hil-gps", {}),
                                          ("mavlink-highres", {"also": "mavlink-hil-gps"})])
def test_mavlink_ranges_are_the_samples_one_by_one(fmt, options):
    expected, got = _both(fmt, {}, **options)
    assert got == expected
    assert sum(map(len, got)) > 0


def test_mavlink_ranges_follow_rate_changes_and_one_off_requests():
    commands = {120: command_long(105, 20_000),           # HIGHRES_IMU every other sample
                230: command_long(105, 0, command=512),   # REQUEST_MESSAGE: one now, then the rate goes on
                260: command_long(105, 0),                # the default rate again
                380: command_long(105, -1)}               # off
    expected, got = _both("mavlink-highres", commands)
    assert got == expected
    assert got[400] and not got[401]         # the heartbeat goes on alone
