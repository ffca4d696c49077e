"""can:INTERFACE:CHANNEL[@BITRATE]: any python-can interface: socketcan:vcan0, virtual:ch0, slcan:/dev/ttyACM0,
udp_multicast:239.74.163.2[:PORT] ([GROUP]:PORT for IPv6 groups; python-can's port 43113 by default);
slcan:pty makes a virtual SLCAN adapter on a pty."""
from __future__ import annotations

from dataclasses import replace

from imu_emulator.errors import TargetError
from imu_emulator.live.transport.base import LinkCapacity, TargetOptions, Transport
from imu_emulator.live.transport.spec import TargetKind, TargetSpec, split_rate

DEFAULT_CAN_BITRATE = 1_000_000


def _multicast_port(text: str, channel: str) -> tuple[str, int]:
    """GROUP[:PORT] of python-can's udp_multicast: an IPv4 group may take a port after its last ':', an IPv6
    group only in brackets ([ff15::1]:43200), since its own colons would be read as one. Two benches (or test
    runs) on one host need different ports: a socket bound to the port hears every group joined on it."""
    if channel.startswith("["):
        group, sep, port = channel[1:].partition("]")
        port = port[1:] if port.startswith(":") else port
    elif channel.count(":") == 1:
        group, sep, port = channel.partition(":")
    else:
        return channel, 0
    if not group or not sep or not port.isdigit() or not 0 < int(port) < 65536:
        raise TargetError(f"{text}: expected can:udp_multicast:GROUP[:PORT] ([GROUP]:PORT for IPv6) "
                          "with a port between 1 and 65535")
    return group, int(port)


def _parse(text: str, rest: str) -> TargetSpec:
    interface, sep, channel = rest.partition(":")
    channel, bitrate = split_rate(text, channel, "bit rate")
    if not interface or not sep or not channel:
        raise TargetError(f"{text}: expected {KIND.syntax}")
    channel, port = _multicast_port(text, channel) if interface == "udp_multicast" else (channel, 0)
    return TargetSpec("can", text, path=channel, interface=interface, rate=bitrate, port=port)


def _capacity(spec: TargetSpec, format_kind: str, options: TargetOptions) -> LinkCapacity:
    """Held to its bit rate even when virtual, as the real bus would be."""
    if format_kind == "can":
        return LinkCapacity(bits_per_s=float(options.bitrate or spec.rate or DEFAULT_CAN_BITRATE),
                            data_bits_per_s=float(options.data_bitrate) if options.data_bitrate else None)
    return LinkCapacity()


def _open(spec: TargetSpec, format_kind: str, options: TargetOptions) -> Transport:
    if spec.rate and not options.bitrate:
        options = replace(options, bitrate=spec.rate)
    if spec.interface == "slcan" and spec.path == "pty":
        from imu_emulator.live.transport.slcan_pty import SlcanPtyTransport
        return SlcanPtyTransport(options)
    from imu_emulator.live.transport.canbus import CanBusTransport
    return CanBusTransport(spec.interface, spec.path, options, port=spec.port)


KIND = TargetKind(name="can", order=3, syntax="can:INTERFACE:CHANNEL[@BITRATE]",
                  help="CAN bus via python-can (socketcan, virtual, slcan, udp_multicast, ...); "
                       "can:slcan:pty = virtual SLCAN adapter on a new pty",
                  carries="can", parse=_parse, open=_open, capacity=_capacity)
