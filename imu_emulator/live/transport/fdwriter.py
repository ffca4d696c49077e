"""Whole packets onto a non-blocking byte stream (pty master, serial port)."""
from __future__ import annotations

import errno
import os
import select
import time
from collections import Counter


def read_available(fd: int, limit: int = 65536) -> bytes:
    """What a non-blocking fd holds now (at most `limit` bytes; the rest waits for the next call), b"" when
    nothing. EIO (a pty with no reader) and EAGAIN read as nothing: the stream goes on."""
    try:
        return os.read(fd, limit)
    except (BlockingIOError, InterruptedError):
        return b""
    except OSError as exc:
        if exc.errno != errno.EIO:
            raise
        return b""


# `Transport.joins_writes` of a link writing through an FdPacketWriter (`self.writer`): a modelled UART takes or
# drops packet by packet what its FIFO can hold, which a joined write would turn into one packet.
joins_writes_unless_paced = property(lambda self: not self.writer.paced)


class FdPacketWriter:
    """Write packets to a non-blocking fd without ever leaving half a packet on the line.

    When the kernel buffer is full (a reader that stopped reading, a slow UART) the packet is dropped
    whole. When the kernel takes only part of a packet, the rest is kept (at most one packet) and
    finished before anything else is written; until then new packets are dropped. Memory never grows.

    pace_baud models a UART: the line is busy for 10 bits per byte; a packet that finds more than
    `fifo_bytes` still waiting on the line is dropped, as a real transmit FIFO would overflow.
    blocking (--speed 0): wait for room instead of dropping, so the link sets the pace.
    """

    def __init__(self, fd: int, pace_baud: int | None = None, fifo_bytes: int = 4096, blocking: bool = False):
        self.fd = fd
        self.blocking = blocking
        self._tail = b""
        self._ns_per_byte = 10e9 / pace_baud if pace_baud else 0.0
        self._fifo_ns = fifo_bytes * self._ns_per_byte
        self._line_free_ns = 0
        self._poll = select.poll()
        self._poll.register(fd, select.POLLOUT)
        self.refusals = Counter()      # why send returned False: EAGAIN (kernel buffer full), EIO, uart-fifo-full
        self._cause = ""

    @property
    def paced(self) -> bool:
        return bool(self._ns_per_byte)

    def set_pace_baud(self, pace_baud: int) -> None:
        fifo_bytes = self._fifo_ns / self._ns_per_byte if self._ns_per_byte else 4096
        self._ns_per_byte = 10e9 / pace_baud
        self._fifo_ns = fifo_bytes * self._ns_per_byte

    def send(self, packet: bytes) -> bool:
        if self._tail and not self._write_tail():
            self.refusals[self._cause] += 1
            return False
        if self._ns_per_byte and not self._line_takes(len(packet)):
            self.refusals["uart-fifo-full"] += 1
            return False
        self._tail = packet
        self._write_tail()
        return True

    @property
    def pending_bytes(self) -> int:
        """Bytes of the last packet not yet written (its head is on the line)."""
        return len(self._tail)

    def discard_pending(self) -> None:
        """Forget the unfinished packet and the modelled line's backlog (the reader they were for is gone)."""
        self._tail = b""
        self._line_free_ns = 0

    def _line_takes(self, size: int) -> bool:
        now = time.monotonic_ns()
        start = max(now, self._line_free_ns)
        if start - now > self._fifo_ns:
            if not self.blocking:
                return False
            time.sleep((start - now - self._fifo_ns) / 1e9)
        self._line_free_ns = start + int(size * self._ns_per_byte)
        return True

    def _write_tail(self) -> bool:
        """Push the unfinished packet; True when nothing is left of it."""
        while self._tail:
            try:
                n = os.write(self.fd, self._tail)
            except BlockingIOError:
                n = 0
                self._cause = "EAGAIN"
            except OSError as exc:
                # EIO: pty slave side closed by everyone. The stream goes on, as with a cable pulled.
                if exc.errno != errno.EIO:
                    raise
                n = 0
                self._cause = "EIO"
            self._tail = self._tail[n:]
            if self._tail:
                if not self.blocking:
                    return False
                self._poll.poll(100)
        return True
