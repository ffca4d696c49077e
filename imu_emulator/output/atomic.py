"""Output files that appear whole or not at all.

The file is created at once under a temporary name in the directory given (so a path that cannot be written fails
before any work is done), written, then renamed over the path on `close` or removed on `discard`: a run
that fails half-way leaves neither a half-written file nor a stale temporary one (and a part left by a killed run
is removed by the next). The temporary file is created O_EXCL | O_NOFOLLOW and the rename replaces a symbolic link
at the path itself, never its target; a link another user placed in a shared directory is refused
(imu_emulator.files.create). Every OSError becomes one OutputError line naming the path.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

from imu_emulator.errors import ImuEmulatorError
from imu_emulator.files.create import create_part, is_direct, refuse_foreign, remove_stale_parts


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
        self.temp = None
        try:
            refuse_foreign(self.path)
            self.direct = is_direct(self.path)
            if self.direct:
                fd = os.open(self.path, os.O_WRONLY | os.O_TRUNC | os.O_CLOEXEC)
            else:
                remove_stale_parts(self.path)
                fd, self.temp = create_part(self.path)
                replaced = os.lstat(self.path) if os.path.lexists(self.path) else None
                if replaced is not None and stat.S_ISREG(replaced.st_mode):    # replacing a file keeps its mode
                    os.fchmod(fd, stat.S_IMODE(replaced.st_mode))
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
                os.replace(self.temp, self.path)     # a link at the path is replaced, not followed
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


def write_text(path, text: str) -> None:
    """A whole small file (a report), written as every output is."""
    with AtomicOutput(path) as out:
        out.write(text)


def save_figure(fig, path, **options) -> None:
    """A matplotlib figure, written as every output is (savefig(path) would write through any link); the format
    is the path's suffix, as savefig would pick it."""
    path = Path(path)
    with AtomicOutput(path, "wb") as out:
        fig.savefig(out.file, format=path.suffix[1:] or None, **options)
