"""A virtual serial port: the emulator holds the master, firmware under test opens the slave path."""
from __future__ import annotations

import os
import tty

from imu_emulator.errors import TargetError
from imu_emulator.transport.base import TargetOptions, Transport
from imu_emulator.transport.fdwriter import FdPacketWriter, read_available


class PtyPair:
    """os.openpty with the slave in raw mode (the default line discipline echoes and rewrites binary
    data). Our own slave fd stays open so a reader may open, close and reopen the path without the
    master seeing EIO; the master is non-blocking so a reader that stops cannot stop us."""

    def __init__(self, link: str | None = None):
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self._slave)
        self.link = link
        if link:
            try:
                if os.path.islink(link):
                    os.unlink(link)
                os.symlink(self.path, link)
            except OSError as exc:
                self.close()
                raise TargetError(f"pty: cannot create link {link}: {exc.strerror}") from None

    def close(self) -> None:
        if self.link and os.path.islink(self.link) and os.readlink(self.link) == self.path:
            os.unlink(self.link)
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


class PtyTransport(Transport):
    """What the reader writes (a driver's commands) comes back from `recv`; the streaming loop reads it
    whether or not a device answers, so the reader's writes never block."""

    def __init__(self, options: TargetOptions):
        self.pty = PtyPair(options.link)
        self.writer = FdPacketWriter(self.pty.master, pace_baud=options.pace_baud, blocking=options.blocking)

    def send(self, payload: bytes) -> bool:
        return self.writer.send(payload)

    def recv(self) -> bytes:
        return read_available(self.pty.master)

    def fileno(self) -> int:
        return self.pty.master

    def set_baud(self, baud: int) -> bool:
        """A pty has no baud rate; with --pace-baud the pacing follows the new rate, as the UART would."""
        if not self.writer.paced:
            return False
        self.writer.set_pace_baud(baud)
        return True

    def describe(self) -> str:
        return self.pty.path + (f" (link {self.pty.link})" if self.pty.link else "")

    def close(self) -> None:
        self.pty.close()
