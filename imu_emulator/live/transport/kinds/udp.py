"""udp:HOST:PORT: one datagram per sample (serial formats)."""
from __future__ import annotations

from imu_emulator.errors import TargetError
from imu_emulator.live.transport.base import TargetOptions, Transport
from imu_emulator.live.transport.spec import TargetKind, TargetSpec


def _parse(text: str, rest: str) -> TargetSpec:
    host, sep, port = rest.rpartition(":")
    host = host.strip("[]")   # [::1]:14550
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise TargetError(f"{text}: expected {KIND.syntax} with a port between 1 and 65535")
    return TargetSpec("udp", text, path=host, port=int(port))


def _open(spec: TargetSpec, format_kind: str, options: TargetOptions) -> Transport:
    from imu_emulator.live.transport.udp import UdpTransport
    return UdpTransport(spec.path, spec.port, options)


KIND = TargetKind(name="udp", order=4, syntax="udp:HOST:PORT", help="UDP datagrams, one per sample",
                  carries="serial", parse=_parse, open=_open,
                  refusal_hint=" (use can:udp_multicast:GROUP for CAN over UDP)")
