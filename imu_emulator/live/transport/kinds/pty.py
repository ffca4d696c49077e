"""pty: a new virtual serial port; the slave path is printed (--link makes a stable symlink)."""
from __future__ import annotations

from imu_emulator.errors import TargetError
from imu_emulator.live.transport.base import LinkCapacity, TargetOptions, Transport
from imu_emulator.live.transport.spec import TargetKind, TargetSpec


def _parse(text: str, rest: str) -> TargetSpec:
    if rest:
        raise TargetError(f"{text}: expected just 'pty' (use --link PATH for a stable path)")
    return TargetSpec("pty", text)


def _capacity(spec: TargetSpec, format_kind: str, options: TargetOptions) -> LinkCapacity:
    """None unless --pace-baud asks for a UART's pace."""
    return LinkCapacity(bytes_per_s=options.pace_baud / 10 if options.pace_baud else None)


def _open(spec: TargetSpec, format_kind: str, options: TargetOptions) -> Transport:
    from imu_emulator.live.transport.pty import PtyTransport
    return PtyTransport(options)


KIND = TargetKind(name="pty", order=1, syntax="pty",
                  help="virtual serial port; prints the slave path (--link PATH for a stable symlink, "
                       "--pace-baud BAUD to deliver no faster than a UART)",
                  carries="serial", parse=_parse, open=_open, capacity=_capacity, takes_argument=False)
