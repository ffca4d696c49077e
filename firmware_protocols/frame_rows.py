"""CAN frame arrays (base.CLASSIC_FRAME_DTYPE, FD_FRAME_DTYPE) as the plain bytes compiled encoders write.

Machine code (imu_emulator.native.objects) passes plain arrays only, so an encoder takes `frame_bytes(frames)`, a
uint8 view with one row of the record's bytes per frame, and writes each field at its offset in the record (read from the
dtype here, the same in both widths), little-endian as the dtype declares. A warm stream then never needs numba.
"""
from __future__ import annotations

from imu_emulator.native.lazy import jit
import numpy as np

from firmware_protocols.base import CLASSIC_FRAME_DTYPE, FD_FRAME_DTYPE


def _offset(name: str) -> int:
    offsets = {dtype.fields[name][1] for dtype in (CLASSIC_FRAME_DTYPE, FD_FRAME_DTYPE)}
    if len(offsets) != 1:
        raise ImportError(f"frame field {name!r} lies at different offsets in the classic and FD records")
    return offsets.pop()


SAMPLE_AT, CAN_ID_AT, EXTENDED_AT, FD_AT, LENGTH_AT, DATA_AT = (
    _offset(name) for name in ("sample", "can_id", "extended", "fd", "length", "data"))
if (CLASSIC_FRAME_DTYPE.fields["sample"][0].str, CLASSIC_FRAME_DTYPE.fields["can_id"][0].str) != ("<i8", "<u4"):
    raise ImportError("put_header writes sample as <i8 and can_id as <u4")


_BYTE = np.dtype(np.uint8)


def frame_bytes(frames: np.ndarray) -> np.ndarray:
    """The frames' bytes, one row per frame: a view (writes land in `frames`), built on the array's buffer, the
    cheapest view numpy makes (devices encode one sample at a time: tools/bench_encode.py --per-sample). `frames`
    is a contiguous empty_frames(...) array, which the encoder made itself or has checked."""
    return np.ndarray((frames.shape[0], frames.dtype.itemsize), _BYTE, frames)


@jit(cache=True, nogil=True, inline="always")
def put_header(frame_rows, f, sample, can_id, extended, fd, length):
    """Row f's fields other than data (extended, fd: 0 or 1)."""
    for b in range(8):
        frame_rows[f, SAMPLE_AT + b] = (sample >> (8 * b)) & 0xFF
    for b in range(4):
        frame_rows[f, CAN_ID_AT + b] = (can_id >> (8 * b)) & 0xFF
    frame_rows[f, EXTENDED_AT] = extended
    frame_rows[f, FD_AT] = fd
    frame_rows[f, LENGTH_AT] = length
