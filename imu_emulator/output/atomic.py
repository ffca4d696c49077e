"""Output files that appear whole or not at all.

The file is created at once under a temporary name in its directory (so a path that cannot be written fails
before any work is done), written, then renamed over the target on `close` or removed on `discard`: a run
that fails half-way leaves neither a half-written file nor a stale temporary one. Every OSError becomes
one OutputError line naming the path.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

from imu_emulator.errors import ImuEmulatorError


class OutputError(ImuEmulatorError):
    """An output file cannot be created or written."""


def output_error(path, exc: OSError, doing: str = "cannot write") -> OutputError:
    return OutputError(f"{path}: {doing}: {exc.strerror or exc}")


class FinishOnExit:
    """As a context manager: close() when the block succeeds, discard() when it raises."""

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb) -> None:
        if kind is None:
            self.close()
        else:
            self.discard()


class AtomicOutput(FinishOnExit):
    """`file` is the open temporary file ("w": text, "wb": binary). close() puts it at its path;
    discard() removes it, and does nothing after close()."""

    def __init__(self, path, mode: str = "w"):
        self.path = Path(path)
        # A device, FIFO or pipe (/dev/stdout) cannot be replaced by a rename: it is written directly.
        self.direct = self.path.exists() and not self.path.is_file()
        # Write through a symlink to where it points, as a plain open() would.
        self.target = self.path if self.direct else Path(os.path.realpath(self.path))
        self.temp = None if self.direct else self.target.with_name(
            f".{self.target.name}.{os.urandom(4).hex()}.part")     # as secrets.token_hex(4), without its imports
        try:
            if self.direct:
                fd = os.open(self.path, os.O_WRONLY | os.O_TRUNC)
            else:
                fd = os.open(self.temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
                if self.target.exists():    # replacing a file keeps its permissions
                    os.fchmod(fd, stat.S_IMODE(self.target.stat().st_mode))
        except OSError as exc:
            raise output_error(self.path, exc, "cannot create") from None
        self.file = open(fd, mode, **({} if "b" in mode else {"newline": "", "encoding": "utf-8"}))
        self.finished = False

    def write(self, data) -> None:
        try:
            self.file.write(data)
        except OSError as exc:
            raise output_error(self.path, exc) from None

    def close(self) -> None:
        try:
            self.file.close()
            if not self.direct:
                os.replace(self.temp, self.target)
        except OSError as exc:
            self.discard()
            raise output_error(self.path, exc) from None
        self.finished = True

    def discard(self) -> None:
        if self.finished:
            return
        self.finished = True
        try:
            self.file.close()
        except OSError:
            pass        # the contents are being thrown away
        if not self.direct:
            try:
                os.unlink(self.temp)
            except FileNotFoundError:
                pass
