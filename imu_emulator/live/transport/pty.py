"""A virtual serial port: the emulator holds the master, firmware under test opens the slave path."""
from __future__ import annotations

import errno
import os
import select
import termios
import time
import tty
from collections import deque

from pathlib import Path

from imu_emulator.errors import TargetError
from imu_emulator.files import locks
from imu_emulator.files.create import part_name, refuse_foreign
from imu_emulator.live.transport.base import TargetOptions, Transport, output_queue
from imu_emulator.live.transport.fdwriter import FdPacketWriter, joins_writes_unless_paced, read_available

_OPEN_FLAGS = os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK


class PtyPair:
    """os.openpty with the slave in raw mode (the default line discipline echoes and rewrites binary
    data; the setting stays with the pty when our fd closes). We do not hold the slave open: the master then
    reports POLLHUP while no reader has it open, so nothing is written for nobody, and a reader that opens
    the path late gets current samples rather than a buffer of old ones. The master is non-blocking so a
    reader that stops cannot stop us."""

    def __init__(self, link: str | None = None):
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        os.close(slave)
        os.set_blocking(self.master, False)
        self._hangup = select.poll()
        self._hangup.register(self.master, 0)       # POLLHUP is always reported
        self.link, self._lock = link, None
        if link:
            try:
                self._lock = locks.hold(Path(link))     # taken now: a second stream on the link fails at once
            except OSError as exc:
                self.close()
                raise TargetError(f"pty: cannot create link {link}: {exc.strerror}") from None

    def publish(self) -> None:
        """Make the link: only once the stream can answer (publish() runs after the warm-up), so a driver that
        opens the link the moment it appears gets answers (issue 23, item 8: it appeared before a cold warm-up)."""
        if self.link and self._lock is not None:
            try:
                _replace_link(Path(self.link), self.path)
            except OSError as exc:
                raise TargetError(f"pty: cannot create link {self.link}: {exc.strerror}") from None

    def reader_present(self) -> bool:
        """True while some process has the slave open."""
        return not self._hangup.poll(0)

    def take_unread(self) -> int:
        """Read out what a reader that went away left unread (so the next reader starts with fresh packets), and
        say how many bytes that was: they were counted as sent, and now they are lost. Reading them ourselves
        rather than flushing (tcflush) is what gives the number: FIONREAD on the slave sees at most the line
        discipline's 4095 bytes, while up to about 20 kB wait in the pty (tools/bench_pty_loss.py, issue 23
        item 9: a slow reader that closed lost 166 packets nobody counted). The last writes reach the slave
        through a kernel work queue, so the slave must stay empty for _SETTLE_S before we believe it."""
        try:
            slave = os.open(self.path, _OPEN_FLAGS)
        except OSError:
            return 0
        taken = 0
        try:
            quiet_since = time.monotonic()
            while time.monotonic() - quiet_since < _SETTLE_S:
                data = read_available(slave)
                if data:
                    taken += len(data)
                    quiet_since = time.monotonic()
                else:
                    time.sleep(0.001)
            termios.tcflush(slave, termios.TCIFLUSH)
        except OSError:
            pass
        finally:
            os.close(slave)
        return taken

    def close(self) -> None:
        if self._lock is not None:
            if os.path.islink(self.link) and os.readlink(self.link) == self.path:
                os.unlink(self.link)
            self._lock.release()
            self._lock = None
        try:
            os.close(self.master)
        except OSError:
            pass


def _replace_link(link: Path, target: str) -> None:
    """A link (a stable name for the pty) made under a temporary name and renamed over `link`: an old link there
    is replaced, not followed; a file that is not a link is kept (it is not ours to replace); another user's link
    in a shared directory is refused (imu_emulator.files.create)."""
    refuse_foreign(link)
    if os.path.lexists(link) and not os.path.islink(link):
        raise FileExistsError(errno.EEXIST, "exists and is not a symbolic link: not replaced")
    temp = part_name(link)
    os.symlink(target, temp)
    try:
        os.replace(temp, link)
    except OSError:
        os.unlink(temp)
        raise


class UnreadLosses:
    """Packets the pty accepted (counted as sent) that no reader read: left in the pty when the reader closed,
    or when the run ended with the reader no longer reading. A byte count becomes packets by the sizes of the
    last packets written: every packet with a byte among the unread ones is lost (a packet partly read is of no
    use to a parser), and so is a packet whose tail never went out."""

    def __init__(self, remembered: int = 8192):
        # The pty holds about 20 kB; 8192 sizes cover it for packets of 3 bytes and more.
        self._sizes = deque(maxlen=remembered)
        self.packets = 0
        self.bytes = 0
        self.departures = 0          # readers that went away with packets unread

    def written(self, size: int) -> None:
        self._sizes.append(size)

    def forget_last(self) -> None:
        if self._sizes:
            self._sizes.pop()

    def lose(self, unread: int, unsent_tail: int) -> None:
        """`unread` bytes taken out of the pty unread, the last packet's `unsent_tail` bytes never written."""
        if not unread and not unsent_tail:
            return
        self.departures += 1
        self.bytes += unread + unsent_tail
        covered, lost = 0, 0
        # The newest packet's written part is its size less the tail still pending.
        while self._sizes and covered < unread + unsent_tail:
            covered += self._sizes.pop()
            lost += 1
        self.packets += max(lost, 1)
        self._sizes.clear()           # what came before was read: never counted twice

    def report(self) -> dict:
        if not self.packets:
            return {}
        return {"unread_lost": {"packets": self.packets, "bytes": self.bytes, "readers": self.departures}}


# Closing the master discards what the reader has not read yet: at the end of a run we wait for it, until it
# has taken nothing for this long (so a run with nobody reading ends at once, or nearly).
_DRAIN_IDLE_S = 0.2
_SETTLE_S = 0.02


class PtyTransport(Transport):
    """Packets go out only while a reader has the port open; the others are dropped and counted (with
    --speed 0, sending waits for a reader instead). What the reader writes (a driver's commands) comes back
    from `recv`; the streaming loop reads it whether or not a device answers, so the reader's writes never
    block."""

    _READER_WAIT_S = 0.01

    def __init__(self, options: TargetOptions):
        self.pty = PtyPair(options.link)
        self.writer = FdPacketWriter(self.pty.master, pace_baud=options.pace_baud, blocking=options.blocking)
        self._reader = False
        self.unread = UnreadLosses()

    def _reader_present(self) -> bool:
        present = self.pty.reader_present()
        while not present and self.writer.blocking:
            time.sleep(self._READER_WAIT_S)
            present = self.pty.reader_present()
        if present != self._reader:
            self._reader = present
            if not present:
                self._count_unread()
            # A packet half written when the reader left must not start the next reader's stream.
            self.writer.discard_pending()
        return present

    def _count_unread(self) -> None:
        """What the reader left unread is lost with it: taken out, counted (packets and bytes), never re-sent."""
        self.unread.lose(self.pty.take_unread(), self.writer.pending_bytes)
        self.writer.discard_pending()

    def publish(self) -> None:
        self.pty.publish()

    def send(self, payload: bytes) -> bool:
        if not self._reader_present():
            self.writer.refusals["no-reader"] += 1
            return False
        if not self.writer.send(payload):
            return False
        self.unread.written(len(payload))
        return True

    joins_writes = joins_writes_unless_paced

    def send_many(self, items: list) -> int:
        sent = super().send_many(items)
        if sent > 1 and self.joins_writes:  # counted as one packet: its packets' sizes, for the unread losses
            self.unread.forget_last()
            for item in items:
                self.unread.written(len(item))
        return sent

    def recv(self) -> bytes:
        return read_available(self.pty.master)

    def fileno(self) -> int:
        return self.pty.master

    def finish(self) -> None:
        """Wait for a reader to take what was sent. Only the slave side tells (FIONREAD: the line discipline's
        buffer, so at most 4095 however much more waits behind it; 0 when the reader took everything), so we
        open it for the while: during the run that would count as a reader."""
        if not self.pty.reader_present():
            if self._reader:        # it left after the last send, with what it had not read
                self._reader = False
                self._count_unread()
            return
        try:
            slave = os.open(self.pty.path, _OPEN_FLAGS)
        except OSError:
            return
        try:
            # The last writes reach the line discipline through a kernel work queue, so an empty reading right
            # after them proves nothing: empty must hold for _SETTLE_S.
            last, changed = output_queue(slave, termios.FIONREAD), time.monotonic()
            while True:
                time.sleep(0.002)
                now, queued = time.monotonic(), output_queue(slave, termios.FIONREAD)
                if queued != last:
                    last, changed = queued, now
                if now - changed >= (_DRAIN_IDLE_S if queued else _SETTLE_S):
                    break
        finally:
            os.close(slave)
        if last:
            # The reader stopped taking them: closing the master would discard them uncounted, so we take them.
            self._count_unread()

    def link_report(self) -> dict:
        report = super().link_report()
        report.update(self.unread.report())
        return report

    @property
    def send_errors(self):
        # Nothing is lost after a pty accepts bytes (a full buffer refuses the write instead): refusals
        # are the whole story.
        return self.writer.refusals

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
