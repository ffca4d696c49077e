"""Every device takes any input without raising, keeps streaming, and keeps its memory bounded: random bytes,
damaged copies of valid commands, truncated commands and floods, fed in random chunk sizes."""
import can
import numpy as np
from hypothesis import given, settings, strategies as st

import firmware_protocols
from firmware_protocols import Samples

def _mavlink_commands():
    from pymavlink.dialects.v20 import common as mavlink2
    mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    return [mav.command_long_encode(1, 1, 511, 0, 105, 20000, 0, 0, 0, 0, 0).pack(mav),
            mav.command_long_encode(1, 1, 512, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav)]


def _xsens_commands():
    from firmware_protocols.devices.xsens import xbus
    return [xbus(0x30), xbus(0xC0, bytes.fromhex("40200064")), xbus(0x10), xbus(0x00)]


def _mip_commands():
    from firmware_protocols.devices.microstrain import packet
    return [packet(0x01, [(0x01, b"")]), packet(0x0C, [(0x0F, bytes([1, 0x80, 1, 0x04, 0, 2]))]),
            packet(0x01, [(0x06, b"")])]


SERIAL = {
    "vectornav-binary": [b"$VNRRG,01*XX\r\n", b"$VNWRG,75,3,4,01,0721*XX\r\n", b"$VNASY,0*XX\r\n", b"$VNRST*XX\r\n"],
    "mavlink-highres": _mavlink_commands(),
    "xsens-mtdata2": _xsens_commands(),
    "microstrain-mip": _mip_commands(),
}
CAN = ("dronecan-rawimu", "j1939")


def _samples(n=8):
    t = (np.arange(n) * 1e7).astype(np.int64)
    return Samples(t, np.tile([0.1, -0.2, 9.8], (n, 1)), np.tile([0.01, 0.02, 0.03], (n, 1)),
                   quat=np.tile([1.0, 0, 0, 0], (n, 1)), euler=np.zeros((n, 3)))


def _damage(data: bytes, flips) -> bytes:
    out = bytearray(data)
    for position, value in flips:
        if out:
            out[position % len(out)] = value
    return bytes(out)


def test_the_valid_commands_here_are_answered():
    for name, commands in SERIAL.items():
        device = firmware_protocols.create_device(name, 100.0)
        for command in commands:
            assert device.receive(command), (name, command)
        assert device.stats.errors == 0, name


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(sorted(SERIAL)), noise=st.binary(max_size=600),
       pick=st.integers(0, 10), flips=st.lists(st.tuples(st.integers(0, 200), st.integers(0, 255)), max_size=3),
       cut=st.integers(0, 40), repeat=st.integers(1, 50), chunk=st.integers(1, 97))
def test_serial_devices_never_raise_and_keep_streaming(name, noise, pick, flips, cut, repeat, chunk):
    device = firmware_protocols.create_device(name, 100.0)
    commands = SERIAL[name]
    valid = commands[pick % len(commands)]
    stream = noise + _damage(valid, flips) + valid[:cut] + valid * repeat + noise[::-1]
    samples = _samples()
    for k in range(0, len(stream), chunk):
        for reply in device.receive(stream[k:k + chunk]):
            assert isinstance(reply, bytes) and reply
        device.output(samples, (k // chunk) % len(samples))
    assert len(getattr(device, "_buf", b"")) <= 8192     # nothing grows without bound
    stats = device.stats
    assert stats.commands + stats.errors + stats.ignored_bytes > 0


@settings(max_examples=40, deadline=None)
@given(name=st.sampled_from(CAN), frames=st.lists(st.tuples(st.integers(0, (1 << 29) - 1), st.binary(max_size=8),
                                                            st.booleans()), max_size=40))
def test_can_devices_never_raise(name, frames):
    device = firmware_protocols.create_device(name, 100.0)
    samples = _samples()
    messages = [can.Message(arbitration_id=i if extended else i & 0x7FF, data=d, is_extended_id=extended)
                for i, d, extended in frames]
    device.output(samples, 0)
    for reply in device.receive(messages):
        assert reply.dtype.names and len(reply) >= 1
    device.output(samples, 1)
