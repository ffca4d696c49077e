"""A path a running stream holds (its pty link, its capture file) is locked by a file beside it,
`.NAME.lock`, flock'ed while the stream runs and holding its pid: a second stream on the same path is refused with
an error naming the holder, instead of silently taking over the first one's link or log. The lock is released by
the kernel when the process dies, so a crash leaves no lock that blocks the next run (only the file, reused).
"""
from __future__ import annotations

import errno
import fcntl
import os
import stat
from pathlib import Path


class PathLock:
    def __init__(self, lock: Path, fd: int):
        self.lock, self.fd = lock, fd

    def release(self) -> None:
        if self.fd < 0:
            return
        try:
            if os.stat(self.lock, follow_symlinks=False).st_ino == os.fstat(self.fd).st_ino:
                os.unlink(self.lock)     # while still locked: a waiter that opened it retries on the new one
        except OSError:
            pass
        os.close(self.fd)
        self.fd = -1


def lock_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.lock")


def hold(path: Path) -> PathLock:
    """Lock `path` for this process. BlockingIOError naming the holder's pid if another process holds it;
    PermissionError if the lock file there is not the user's own (it could be a link to anything)."""
    lock = lock_path(path)
    for _ in range(20):
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_uid != os.geteuid() or st.st_nlink != 1:
            os.close(fd)
            raise PermissionError(errno.EPERM, f"its lock file {lock} is not yours (uid {st.st_uid}): remove it")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise BlockingIOError(errno.EWOULDBLOCK, f"in use by another running stream (pid {holder}; lock "
                                                     f"{lock}): stop it, or choose another path") from None
        try:
            current = os.stat(lock, follow_symlinks=False).st_ino
        except FileNotFoundError:
            current = None
        if current == st.st_ino:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            return PathLock(lock, fd)
        os.close(fd)        # its holder removed it while we opened it: lock the one there now
    raise BlockingIOError(errno.EWOULDBLOCK, f"its lock file {lock} keeps changing: another stream is starting")
