"""The kernel cache is executed (generated source, machine code, numba's pickled index), so it is trusted only as
ssh trusts ~/.ssh: the cache root, every directory and file the program loads from it, are owned by the running
user and writable by nobody else, and the root's ancestors are the user's or root's and not writable by others
unless sticky (/tmp). Anything else is refused with one line naming the path and the fix.

Ownership is not enough: an entry edited or copied from another cache (or restored from a backup someone could
write) would still be the user's. Every file loaded carries an HMAC-SHA256 under a secret of 32 random bytes kept
in the cache root (mode 600, created on first use), over a label naming where the file belongs: an entry is
accepted only if this cache wrote it for this key. Checking costs one HMAC of the file loaded.
"""
from __future__ import annotations

import contextlib
import hashlib
import hmac
import os
import stat
from pathlib import Path

from imu_emulator.errors import ImuEmulatorError

SECRET_NAME = "secret.key"
_SECRET_BYTES = 32


class UntrustedCache(ImuEmulatorError):
    """The cache (or a file in it) is not the running user's alone: nothing in it is loaded."""


def cache_root() -> Path:
    root = os.environ.get("IMU_EMULATOR_CACHE")
    return Path(root) if root else Path.home() / ".cache" / "imu-emulator"


def _refuse(path, why: str) -> UntrustedCache:
    root = cache_root()
    return UntrustedCache(f"{path}: kernel cache not trusted: {why}; fix: rm -rf {root} (a cache: it is rebuilt) "
                          "or set IMU_EMULATOR_CACHE to a directory of your own")


def check_private(path, st: os.stat_result) -> None:
    """Owned by the running user, not a symbolic link, writable by nobody else."""
    uid = os.geteuid()
    if stat.S_ISLNK(st.st_mode):
        raise _refuse(path, "a symbolic link")
    if st.st_uid != uid:
        raise _refuse(path, f"owned by uid {st.st_uid}, not by you (uid {uid})")
    if st.st_mode & 0o022:
        raise _refuse(path, f"writable by {'group' if st.st_mode & 0o020 else 'others'} "
                            f"(mode {stat.S_IMODE(st.st_mode):o})")


def _check_ancestors(path: Path) -> None:
    """Who can rename a directory above the cache can put another cache in its place."""
    uid = os.geteuid()
    for parent in path.parents:
        st = os.stat(parent)
        if st.st_uid not in (0, uid):
            raise _refuse(parent, f"a directory above the cache owned by uid {st.st_uid}")
        if st.st_mode & 0o022 and not st.st_mode & stat.S_ISVTX:
            raise _refuse(parent, f"a directory above the cache writable by others and not sticky "
                                  f"(mode {stat.S_IMODE(st.st_mode):o})")


_checked_ancestors: set[tuple[str, int, int]] = set()


def trusted_dir(sub: str = "") -> Path:
    """The cache root (or its subdirectory `sub`), created private if missing, checked (one lstat a call; the
    ancestors once per process)."""
    root = Path(os.path.realpath(cache_root()))
    with private_umask():
        os.makedirs(root, mode=0o700, exist_ok=True)
    st = os.lstat(root)
    check_private(root, st)
    if (str(root), st.st_dev, st.st_ino) not in _checked_ancestors:
        _check_ancestors(root)
        _checked_ancestors.add((str(root), st.st_dev, st.st_ino))
    if not sub:
        return root
    path = root / sub
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    check_private(path, os.lstat(path))
    return path


@contextlib.contextmanager
def private_umask():
    """What is written into the cache (also by numba, which makes its __pycache__ with the umask) is writable by
    nobody else, whatever the user's umask: the next run refuses it otherwise."""
    old = os.umask(0)
    os.umask(old | 0o022)
    try:
        yield
    finally:
        os.umask(old)


def read_private(path) -> bytes:
    """The bytes of a file of the cache, refused unless it is the user's alone (read through the descriptor that
    was checked, so it cannot be swapped in between). FileNotFoundError if there is none."""
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    with open(fd, "rb") as f:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise _refuse(path, "not a regular file")
        check_private(path, st)
        return f.read()


def check_tree(directory: Path) -> None:
    """A cache entry: the directory and everything in it (numba's __pycache__ index is pickled data numba
    loads), each the user's alone."""
    check_private(directory, os.lstat(directory))
    for dirpath, dirnames, filenames in os.walk(directory):
        for name in dirnames + filenames:
            path = os.path.join(dirpath, name)
            try:
                st = os.lstat(path)
            except FileNotFoundError:
                # Gone since the listing: a concurrent run's temporary file, renamed into place (numba's index, the
                # machine code). Nothing loads a file that is not there; before this, the race raised instead.
                continue
            check_private(path, st)


_secrets: dict[tuple[str, int, int], bytes] = {}


def secret() -> bytes:
    """The cache's key: created 0600 on first use (written whole under another name, then linked in, so a
    concurrent run never reads half of it), refused if it is not the user's alone."""
    root = trusted_dir()
    st = os.lstat(root)
    known = (str(root), st.st_dev, st.st_ino)
    if known in _secrets:
        return _secrets[known]
    path = root / SECRET_NAME
    try:
        data = read_private(path)
    except FileNotFoundError:
        temp = root / f".{SECRET_NAME}.{os.getpid()}.{os.urandom(4).hex()}"
        fd = os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
        try:
            os.write(fd, os.urandom(_SECRET_BYTES))
            os.fsync(fd)
            os.close(fd)
            with contextlib.suppress(FileExistsError):    # another run made it first: theirs is the key
                os.link(temp, path)
        finally:
            os.unlink(temp)
        data = read_private(path)
    mode = stat.S_IMODE(os.stat(path, follow_symlinks=False).st_mode)
    if mode & 0o077:
        raise _refuse(path, f"the cache's key is readable by others (mode {mode:o}, must be 600)")
    if len(data) != _SECRET_BYTES:
        raise _refuse(path, f"the cache's key is {len(data)} bytes, not {_SECRET_BYTES}")
    _secrets[known] = data
    return data


def digest(label: str, data: bytes) -> bytes:
    """HMAC-SHA256 of `data` for the place `label` names (an entry's key and file name): a file moved to another
    key, or written under another cache's key, does not match."""
    return hmac.new(secret(), label.encode() + b"\0" + data, hashlib.sha256).digest()


def matches(label: str, data: bytes, mac: bytes) -> bool:
    return hmac.compare_digest(digest(label, data), mac)
