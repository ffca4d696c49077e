"""file:PATH: a capture file: raw bytes (serial formats) or a CAN log chosen by suffix."""
from __future__ import annotations

from imu_emulator.live.transport.base import TargetOptions, Transport
from imu_emulator.live.transport.spec import TargetKind, TargetSpec


def _parse(text: str, rest: str) -> TargetSpec:
    return TargetSpec("file", text, path=rest)


def _open(spec: TargetSpec, format_kind: str, options: TargetOptions) -> Transport:
    from imu_emulator.live.transport.capture import CanLogTransport, RawFileTransport
    return CanLogTransport(spec.path) if format_kind == "can" else RawFileTransport(spec.path)


KIND = TargetKind(name="file", order=5, syntax="file:PATH",
                  help="capture file: raw bytes, or for CAN formats a .log (candump) / .asc / .blf / .csv log",
                  carries="any", parse=_parse, open=_open, talks_back=False)
