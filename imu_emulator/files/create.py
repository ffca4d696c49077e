"""Creating a file at a path without following, or being steered by, what another user placed there.

An output is written under a temporary name in the directory given (O_EXCL | O_NOFOLLOW: never through a link,
never over a file that exists), then renamed over the path: a link at the path is replaced itself, its target is
never written. A link (or a FIFO, socket or device) another user placed in a directory others can write is refused
with an error instead, as the kernel's fs.protected_symlinks rule would (root is not bound by that sysctl, and a
rename is not a link being followed, so we check it ourselves). A path that is a device, FIFO or pipe of the user's
(/dev/stdout) is written directly. The temporary name carries the writer's pid, so a part left by a process that
was killed is removed by the next writer of the same path; a live writer's part is kept.
"""
from __future__ import annotations

import errno
import os
import re
import stat
from pathlib import Path

_PART = re.compile(r"\.(?P<pid>\d+)\.[0-9a-f]{8}\.part\Z")


def refuse_foreign(path: Path) -> None:
    """PermissionError if `path` is a link, FIFO, socket or device owned by another user (not the directory's
    owner) in a directory others can write: writing through it would write where they chose."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode) or st.st_uid == os.geteuid():
        return
    parent = os.stat(path.parent)
    if st.st_uid != parent.st_uid and parent.st_mode & 0o022:
        what = "a symbolic link" if stat.S_ISLNK(st.st_mode) else "a special file"
        raise PermissionError(errno.EPERM, f"{what} owned by uid {st.st_uid} in a directory others can write: "
                                           "not written through nor replaced (remove it, or write elsewhere)")


def is_direct(path: Path) -> bool:
    """A device, FIFO or pipe (/dev/stdout) cannot be replaced by a rename: it is written directly."""
    return path.exists() and not path.is_file() and not path.is_dir()


def part_name(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.{os.urandom(4).hex()}.part")


def create_part(path: Path, mode: int = 0o666) -> tuple[int, Path]:
    """A new file under a temporary name beside `path` (the directory given, no link followed) and its fd."""
    temp = part_name(path)
    return os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, mode), temp


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True     # another user's process
    return True


def remove_stale_parts(path: Path) -> list[Path]:
    """Remove the user's temporary parts of `path` whose writer is dead (a SIGKILL leaves one); the removed."""
    prefix = f".{path.name}."
    removed = []
    try:
        names = [n for n in os.listdir(path.parent) if n.startswith(prefix) and n.endswith(".part")]
    except OSError:
        return removed
    for name in names:
        match = _PART.fullmatch(name[len(prefix) - 1:])
        if not match or _alive(int(match["pid"])):
            continue
        part = path.parent / name
        try:
            st = os.lstat(part)
            if st.st_uid == os.geteuid() and stat.S_ISREG(st.st_mode):
                os.unlink(part)
                removed.append(part)
        except OSError:
            pass
    return removed


def open_replacing(path: Path) -> int:
    """An fd to a new, empty file now at `path` (for a capture written as it goes): created beside it and renamed
    over it at once, so a link there is replaced, not followed. A device or FIFO of the user's is opened directly.
    OSError (PermissionError for another user's link) as open() would raise it."""
    refuse_foreign(path)
    if is_direct(path):
        return os.open(path, os.O_WRONLY | os.O_TRUNC | os.O_CLOEXEC)
    remove_stale_parts(path)
    fd, temp = create_part(path)
    try:
        os.replace(temp, path)
    except OSError:
        os.close(fd)
        os.unlink(temp)
        raise
    return fd
