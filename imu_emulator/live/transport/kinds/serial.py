"""serial:DEVICE[@BAUD]: a serial port through pyserial (default 115200 baud)."""
from __future__ import annotations

from imu_emulator.errors import TargetError
from imu_emulator.live.transport.base import LinkCapacity, TargetOptions, Transport
from imu_emulator.live.transport.spec import TargetKind, TargetSpec, split_rate

DEFAULT_SERIAL_BAUD = 115200


def _parse(text: str, rest: str) -> TargetSpec:
    device, baud = split_rate(text, rest, "baud rate")
    if not device:
        raise TargetError(f"{text}: expected {KIND.syntax}")
    return TargetSpec("serial", text, path=device, rate=baud or DEFAULT_SERIAL_BAUD)


def _capacity(spec: TargetSpec, format_kind: str, options: TargetOptions) -> LinkCapacity:
    return LinkCapacity(bytes_per_s=spec.rate / 10)


def _open(spec: TargetSpec, format_kind: str, options: TargetOptions) -> Transport:
    from imu_emulator.live.transport.serialport import SerialTransport
    return SerialTransport(spec.path, spec.rate, options)


KIND = TargetKind(name="serial", order=2, syntax="serial:DEVICE[@BAUD]",
                  help=f"serial port via pyserial (default {DEFAULT_SERIAL_BAUD} baud)",
                  carries="serial", parse=_parse, open=_open, capacity=_capacity)
