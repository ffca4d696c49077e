"""Where samples go. A target spec names the link:

    pty                              new virtual serial port; prints the slave path (--link makes a symlink)
    serial:DEVICE[@BAUD]             serial port through pyserial (default 115200 baud)
    can:INTERFACE:CHANNEL[@BITRATE]  any python-can interface: socketcan:vcan0, virtual:ch0, slcan:/dev/ttyACM0,
                                     udp_multicast:239.74.163.2[:PORT] ([GROUP]:PORT for IPv6 groups; python-can's
                                     port 43113 by default); slcan:pty makes a virtual SLCAN adapter on a pty
    udp:HOST:PORT                    one datagram per sample (serial formats)
    file:PATH                        capture: raw bytes (serial formats) or a CAN log chosen by suffix

Each kind lives in its own module; this one parses specs and opens the right one.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

from imu_emulator.errors import TargetError
from imu_emulator.live.transport.base import LinkCapacity, TargetOptions, Transport

DEFAULT_SERIAL_BAUD = 115200
DEFAULT_CAN_BITRATE = 1_000_000

#: kind -> (syntax, what it is, the format kind it carries)
TARGET_KINDS = {
    "pty": ("pty", "virtual serial port; prints the slave path (--link PATH for a stable symlink, "
                   "--pace-baud BAUD to deliver no faster than a UART)", "serial"),
    "serial": ("serial:DEVICE[@BAUD]", f"serial port via pyserial (default {DEFAULT_SERIAL_BAUD} baud)", "serial"),
    "can": ("can:INTERFACE:CHANNEL[@BITRATE]", "CAN bus via python-can (socketcan, virtual, slcan, udp_multicast, ...); "
                                               "can:slcan:pty = virtual SLCAN adapter on a new pty", "can"),
    "udp": ("udp:HOST:PORT", "UDP datagrams, one per sample", "serial"),
    "file": ("file:PATH", "capture file: raw bytes, or for CAN formats a .log (candump) / .asc / .blf / .csv log", "any"),
}


@dataclass(frozen=True)
class TargetSpec:
    kind: str             # a key of TARGET_KINDS
    text: str             # as written, for messages
    path: str = ""        # device, CAN channel, host or file
    interface: str = ""   # python-can interface (can)
    port: int = 0         # udp; udp_multicast (0: python-can's default)
    rate: int | None = None   # baud (serial) or bit rate (can), when the spec names one


def _split_rate(text: str, body: str, what: str) -> tuple[str, int | None]:
    if "@" not in body:
        return body, None
    head, _, rate = body.rpartition("@")
    if not rate.isdigit() or int(rate) <= 0:
        raise TargetError(f"{text}: {what} after '@' must be a positive integer, got {rate!r}")
    return head, int(rate)


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


def parse_target(text: str) -> TargetSpec:
    """Parse a target spec; malformed specs raise TargetError naming the expected syntax."""
    if not isinstance(text, str) or not text:
        raise TargetError("target: empty spec (expected one of: "
                          + ", ".join(syntax for syntax, _, _ in TARGET_KINDS.values()) + ")")
    kind, _, rest = text.partition(":")
    if kind not in TARGET_KINDS:
        raise TargetError(f"{text}: unknown target kind {kind!r} (known: {', '.join(TARGET_KINDS)})")
    syntax = TARGET_KINDS[kind][0]
    if kind == "pty":
        if rest:
            raise TargetError(f"{text}: expected just 'pty' (use --link PATH for a stable path)")
        return TargetSpec("pty", text)
    if not rest:
        raise TargetError(f"{text}: expected {syntax}")
    if kind == "serial":
        device, baud = _split_rate(text, rest, "baud rate")
        if not device:
            raise TargetError(f"{text}: expected {syntax}")
        return TargetSpec("serial", text, path=device, rate=baud or DEFAULT_SERIAL_BAUD)
    if kind == "can":
        interface, sep, channel = rest.partition(":")
        channel, bitrate = _split_rate(text, channel, "bit rate")
        if not interface or not sep or not channel:
            raise TargetError(f"{text}: expected {syntax}")
        channel, port = _multicast_port(text, channel) if interface == "udp_multicast" else (channel, 0)
        return TargetSpec("can", text, path=channel, interface=interface, rate=bitrate, port=port)
    if kind == "udp":
        host, sep, port = rest.rpartition(":")
        host = host.strip("[]")   # [::1]:14550
        if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise TargetError(f"{text}: expected {syntax} with a port between 1 and 65535")
        return TargetSpec("udp", text, path=host, port=int(port))
    return TargetSpec("file", text, path=rest)


def check_carries(spec: TargetSpec, format_kind: str) -> None:
    """Refuse a format the target cannot carry (CAN frames to a pty, bytes to a CAN bus)."""
    carries = TARGET_KINDS[spec.kind][2]
    if carries not in ("any", format_kind):
        hint = " (use can:udp_multicast:GROUP for CAN over UDP)" if spec.kind == "udp" else ""
        raise TargetError(f"{spec.text}: a {spec.kind} target carries {carries} formats, "
                          f"not {format_kind} formats{hint}")


def link_capacity(spec: TargetSpec, format_kind: str, options: TargetOptions = TargetOptions()) -> LinkCapacity:
    """The capacity the link budget is checked against, known from the spec alone (so an impossible
    stream is refused before any device is opened). A pty or UDP has none unless --pace-baud asks;
    a CAN target is held to its bit rate even when virtual, as the real bus would be."""
    if spec.kind == "serial":
        return LinkCapacity(bytes_per_s=spec.rate / 10)
    if spec.kind == "pty":
        return LinkCapacity(bytes_per_s=options.pace_baud / 10 if options.pace_baud else None)
    if spec.kind == "can" and format_kind == "can":
        return LinkCapacity(bits_per_s=float(options.bitrate or spec.rate or DEFAULT_CAN_BITRATE),
                            data_bits_per_s=float(options.data_bitrate) if options.data_bitrate else None)
    return LinkCapacity()


def open_target(spec: TargetSpec, format_kind: str, options: TargetOptions = TargetOptions()) -> Transport:
    """Open a parsed target for a format of kind "serial" or "can"."""
    check_carries(spec, format_kind)
    if spec.kind == "pty":
        from imu_emulator.live.transport.pty import PtyTransport
        return PtyTransport(options)
    if spec.kind == "serial":
        from imu_emulator.live.transport.serialport import SerialTransport
        return SerialTransport(spec.path, spec.rate, options)
    if spec.kind == "udp":
        from imu_emulator.live.transport.udp import UdpTransport
        return UdpTransport(spec.path, spec.port, options)
    if spec.kind == "file":
        from imu_emulator.live.transport import capture
        return capture.CanLogTransport(spec.path) if format_kind == "can" else capture.RawFileTransport(spec.path)
    if spec.rate and not options.bitrate:
        options = replace(options, bitrate=spec.rate)
    if spec.interface == "slcan" and spec.path == "pty":
        from imu_emulator.live.transport.slcan_pty import SlcanPtyTransport
        return SlcanPtyTransport(options)
    from imu_emulator.live.transport.canbus import CanBusTransport
    return CanBusTransport(spec.interface, spec.path, options, port=spec.port)


__all__ = ["TARGET_KINDS", "LinkCapacity", "check_carries", "TargetOptions", "TargetSpec", "Transport", "link_capacity", "open_target",
           "parse_target"]
