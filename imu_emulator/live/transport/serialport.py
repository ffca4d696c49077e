"""A real serial port through pyserial (USB adapters, UARTs, or any tty path)."""
from __future__ import annotations

import os

import serial

from imu_emulator.errors import TargetError
from imu_emulator.live.transport.base import TargetOptions, Transport, output_queue
from imu_emulator.live.transport.fdwriter import FdPacketWriter, joins_writes_unless_paced, read_available


class SerialTransport(Transport):

    def __init__(self, device: str, baud: int, options: TargetOptions):
        try:
            # pyserial's POSIX backend opens with O_NONBLOCK and leaves it so: our writer needs exactly that.
            self.port = serial.Serial(device, baudrate=baud, timeout=0, write_timeout=0)
        except (serial.SerialException, ValueError, OSError) as exc:
            code = getattr(exc, "errno", None)
            reason = os.strerror(code) if isinstance(code, int) else str(exc).splitlines()[0]
            raise TargetError(f"serial:{device}: cannot open: {reason}") from None
        self.device, self.baud = device, baud
        self.writer = FdPacketWriter(self.port.fileno(), pace_baud=options.pace_baud, blocking=options.blocking)

    def send(self, payload: bytes) -> bool:
        return self.writer.send(payload)

    joins_writes = joins_writes_unless_paced

    def recv(self) -> bytes:
        return read_available(self.port.fileno())

    def fileno(self) -> int:
        return self.port.fileno()

    @property
    def send_errors(self):
        return self.writer.refusals

    def queued(self) -> int | None:
        """TIOCOUTQ: bytes the UART has not transmitted yet."""
        return output_queue(self.port.fileno())

    def set_baud(self, baud: int) -> bool:
        """Follow a baud-rate change the device echoed: the echo leaves at the old rate first."""
        self.port.flush()
        self.port.baudrate = baud
        self.baud = baud
        if self.writer.paced:
            self.writer.set_pace_baud(baud)
        return True

    def describe(self) -> str:
        return f"{self.device} @ {self.baud} baud"

    def close(self) -> None:
        self.port.close()
