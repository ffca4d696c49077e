"""Opening the files a scene names (the scene file, track files, flight logs): regular files only, read up to a
bound. A path may be a symlink to /dev/zero (read without end) or a FIFO (an open for reading blocks until a
writer comes), so each file is opened without blocking and checked on its descriptor before a byte is read."""
from __future__ import annotations

import os
import stat
from pathlib import Path

from imu_emulator.errors import DataError

MAX_SCENE_BYTES = 16 << 20       # a scene file is text a person writes; arrays go to track files
MAX_TRACK_BYTES = 2 << 30        # a CSV or NPZ track read whole into memory
MAX_LOG_BYTES = 16 << 30         # flight logs are read by their own libraries, which page through them


def _open_regular(path: Path, limit: int) -> tuple[int, int]:
    """(descriptor, size) of `path` opened for reading if it is a regular file of at most `limit` bytes; DataError
    naming the file otherwise. O_NONBLOCK so that a FIFO's open returns at once (and is then refused)."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            kind = ("a directory" if stat.S_ISDIR(info.st_mode) else "a FIFO" if stat.S_ISFIFO(info.st_mode)
                    else "a device" if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode) else "a socket"
                    if stat.S_ISSOCK(info.st_mode) else "not a regular file")
            raise DataError(f"{path.name}: not a regular file ({kind}); give a file")
        if info.st_size > limit:
            raise DataError(f"{path.name}: {info.st_size} bytes is more than this reader takes ({limit} bytes)")
        os.set_blocking(fd, True)
        return fd, info.st_size
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: Path, limit: int) -> bytes:
    """The bytes of a regular file, at most `limit` of them (a file growing while read is cut at the bound and
    refused rather than read on)."""
    fd, _ = _open_regular(Path(path), limit)
    with os.fdopen(fd, "rb") as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise DataError(f"{Path(path).name}: more than {limit} bytes (grew while read)")
    return data


def check_regular(path: Path, limit: int) -> None:
    """For readers that open the path themselves (pyulog, DFReader, mcap): refuse what read_regular refuses."""
    fd, _ = _open_regular(Path(path), limit)
    os.close(fd)
