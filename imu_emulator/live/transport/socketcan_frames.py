"""SocketCAN's frame layout, packed for a whole sample at once, and one system call to send them.

python-can's `Bus.send` costs a `select` and a `send` per frame plus a Message object. A DroneCAN RawIMU
transfer is seven classic frames, so at 1 kHz that is 14 000 system calls a second. Where a system call is
expensive (the one-CPU User Mode Linux guest: tens of microseconds each) the sender then falls behind and
its catch-up starves the very reader it feeds. Packing the frames with numpy and handing them to the kernel
with one `sendmmsg` makes that one call per sample. The layout is `struct can_frame` / `struct canfd_frame`
of <linux/can.h>, exactly as python-can's `build_can_frame` writes it (a test compares the two).
"""
from __future__ import annotations

import ctypes
import errno
import socket

import numpy as np

from firmware_protocols.base import FD_LENGTH_TABLE

CAN_EFF_FLAG = 0x80000000
CANFD_BRS = 0x01
CANFD_FDF = 0x04
CAN_MTU, CANFD_MTU = 16, 72


def _layout(data_bytes: int) -> np.dtype:
    return np.dtype([("can_id", "=u4"), ("len", "u1"), ("flags", "u1"), ("res0", "u1"), ("dlc", "u1"),
                     ("data", "u1", (data_bytes,))])


_CLASSIC, _FD = _layout(8), _layout(64)
assert _CLASSIC.itemsize == CAN_MTU and _FD.itemsize == CANFD_MTU


def pack(rows: np.ndarray, bitrate_switch: bool = False) -> tuple[bytes, int]:
    """One sample's CAN_FRAME_DTYPE rows -> (frames back to back, bytes per frame). One encoder made them, so
    they are all classic or all FD."""
    fd = bool(rows["fd"].any())
    out = np.zeros(len(rows), dtype=_FD if fd else _CLASSIC)
    out["can_id"] = rows["can_id"] | np.where(rows["extended"], np.uint32(CAN_EFF_FLAG), np.uint32(0))
    length = rows["length"]
    out["dlc"] = length
    width = out["data"].shape[1]
    out["data"] = rows["data"][:, :width] * (np.arange(width) < length[:, None])
    out["len"] = FD_LENGTH_TABLE[length] if fd else length
    if fd:
        out["flags"] = CANFD_FDF | (CANFD_BRS if bitrate_switch else 0)
    return out.tobytes(), out.dtype.itemsize


class _Iovec(ctypes.Structure):
    _fields_ = [("iov_base", ctypes.c_void_p), ("iov_len", ctypes.c_size_t)]


class _Msghdr(ctypes.Structure):
    _fields_ = [("msg_name", ctypes.c_void_p), ("msg_namelen", ctypes.c_uint32),
                ("msg_iov", ctypes.POINTER(_Iovec)), ("msg_iovlen", ctypes.c_size_t),
                ("msg_control", ctypes.c_void_p), ("msg_controllen", ctypes.c_size_t),
                ("msg_flags", ctypes.c_int)]


class _Mmsghdr(ctypes.Structure):
    _fields_ = [("msg_hdr", _Msghdr), ("msg_len", ctypes.c_uint)]


def _libc_sendmmsg():
    try:
        function = ctypes.CDLL(None, use_errno=True).sendmmsg
    except (OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.POINTER(_Mmsghdr), ctypes.c_uint, ctypes.c_int]
    function.restype = ctypes.c_int
    return function


class FrameSender:
    """Sends packed frames on a datagram socket without blocking: one `sendmmsg` for all of them (one `send`
    per frame where libc lacks it). `send` returns None when every frame went, else the errno that stopped
    it; the frames after a refused one are not sent, so a receiver sees at worst a truncated transfer."""

    def __init__(self, sock: socket.socket, capacity: int = 64):
        self.sock = sock
        self._sendmmsg = _libc_sendmmsg()
        self._iov = (_Iovec * capacity)()
        self._msgs = (_Mmsghdr * capacity)()
        for i in range(capacity):
            self._msgs[i].msg_hdr.msg_iov = ctypes.pointer(self._iov[i])
            self._msgs[i].msg_hdr.msg_iovlen = 1

    def send(self, frames: bytes, frame_size: int) -> int | None:
        count = len(frames) // frame_size
        if self._sendmmsg is None or count > len(self._msgs):
            return self._send_each(frames, frame_size)
        base = ctypes.cast(ctypes.c_char_p(frames), ctypes.c_void_p).value
        for i in range(count):
            self._iov[i].iov_base = base + i * frame_size
            self._iov[i].iov_len = frame_size
        done = 0
        while done < count:
            sent = self._sendmmsg(self.sock.fileno(), ctypes.byref(self._msgs[done]), count - done,
                                  socket.MSG_DONTWAIT)
            if sent < 0:
                code = ctypes.get_errno()
                if code == errno.EINTR:
                    continue
                return code
            done += sent   # fewer than asked: the next call reports why
        return None

    def _send_each(self, frames: bytes, frame_size: int) -> int | None:
        view = memoryview(frames)
        for start in range(0, len(frames), frame_size):
            try:
                self.sock.send(view[start:start + frame_size], socket.MSG_DONTWAIT)
            except OSError as exc:
                return exc.errno
        return None
