"""Capture files: raw bytes for serial formats; for CAN formats a log in the format python-can's writers
pick by suffix (.log candump, .asc Vector ASC, .blf Vector BLF, .csv, .trc, ...).

The file is claimed before it is written: locked for this stream (a second stream on the same path is refused,
imu_emulator.files.locks) and created anew beside the path and renamed over it, so a link at the path is replaced,
never followed, and another user's link in a shared directory is refused (imu_emulator.files.create)."""
from __future__ import annotations

import os
from pathlib import Path

from imu_emulator.errors import TargetError
from imu_emulator.files import locks
from imu_emulator.files.create import is_direct, open_replacing
from imu_emulator.live.transport.base import Transport


def _open_error(path: str, exc: Exception, doing: str = "cannot open") -> TargetError:
    return TargetError(f"file:{path}: {doing}: {getattr(exc, 'strerror', None) or exc}")


def _write_error(path: str, exc: OSError) -> TargetError:
    # A full disk or a device that refuses data ends the run with one line; what was sent is still reported.
    return _open_error(path, exc, "cannot write")


def _claim(path: str):
    """Lock the path for this stream, then an fd to a new empty file there; a device or FIFO is opened as it is
    (and not locked: a lock file would land in /dev)."""
    lock = None
    try:
        if not is_direct(Path(path)):
            lock = locks.hold(Path(path))
        return lock, open_replacing(Path(path))
    except OSError as exc:
        if lock is not None:
            lock.release()
        raise _open_error(path, exc) from None


class _CaptureFile(Transport):
    """What both capture writers share: one line naming the file for any OS error while writing or closing;
    the path's lock held until the file is closed."""

    path: str
    lock = None

    def _write(self, payload) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def _finish(self) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def send(self, payload) -> bool:
        try:
            self._write(payload)
        except OSError as exc:
            raise _write_error(self.path, exc) from None
        return True

    def describe(self) -> str:
        return f"file {self.path}"

    def close(self) -> None:
        try:
            self._finish()
        except OSError as exc:
            raise _write_error(self.path, exc) from None
        finally:
            if self.lock is not None:
                self.lock.release()


class RawFileTransport(_CaptureFile):

    joins_writes = True

    def __init__(self, path: str):
        self.lock, fd = _claim(path)
        self.file = open(fd, "wb")
        self.path = path

    def _write(self, payload: bytes) -> None:
        self.file.write(payload)

    def _finish(self) -> None:
        self.file.close()


class CanLogTransport(_CaptureFile):

    def __init__(self, path: str):
        # here, not at import: python-can costs ~0.2 s of start-up that raw captures do not need
        import can

        from imu_emulator.live.transport.frames import to_messages
        self._to_messages = to_messages
        suffix = Path(path).suffix.lower()
        known = sorted(can.io.MESSAGE_WRITERS)
        if suffix not in known:
            raise TargetError(f"file:{path}: no CAN log writer for suffix {suffix or '(none)'!r} "
                              f"(known: {', '.join(known)})")
        self.lock, fd = _claim(path)
        os.close(fd)        # python-can opens it by name: the file there is now ours, new and empty
        try:
            self.writer = can.Logger(path)
        except (OSError, ValueError, ImportError) as exc:
            if self.lock is not None:
                self.lock.release()
            raise _open_error(path, exc) from None
        self.path = path

    def prepare(self, payload, time_ns: int):
        # The log's time stamps are the samples' times on the declared time base, not wall clock.
        return self._to_messages(payload, timestamp=time_ns / 1e9)

    def _write(self, messages) -> None:
        for message in messages:
            self.writer.on_message_received(message)

    def _finish(self) -> None:
        self.writer.stop()
