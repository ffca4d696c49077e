"""CSV rows as bytes, fast: every number is the shortest text that reads back as the same double.

The digits come from orjson's float formatter (a Rust shortest-round-trip formatter, ~40 ns a number, against
pyarrow's ~180 ns): each group of columns is one float64 matrix serialized in one call, giving "[[a,b],[c,d]]".
The rows of those texts are found with numpy (every '[' opens a row, every ']' closes one) and one compiled
loop copies them into place with the IMU's name. Columns that are the same for every IMU of a sample (the time
stamp without [[imu]] time_offset_s, the truth and the Earth truth) are formatted once per sample, not once
per IMU.

orjson writes a non-finite number as "null"; a block holding one is left to the caller's fallback (`None`).

The compiled loops are declared with imu_emulator.native.lazy (`jit`, `intrinsic`): a warm run calls their machine
code without importing numba (its import and CPU-target start cost about a second, more than a short run's work).
"""
from __future__ import annotations

import numpy as np

from imu_emulator.native.lazy import intrinsic, jit

_OPEN, _CLOSE = ord("["), ord("]")


def quoted(name: str) -> bytes:
    """An IMU name as a CSV field (RFC 4180: quoted, with doubled quotes, only when it must be)."""
    if any(ch in name for ch in ',"\r\n'):
        name = '"' + name.replace('"', '""') + '"'
    return name.encode()


def _segment_text(matrix: np.ndarray):
    """orjson's text of a (rows, k) matrix and the [start, end) of each row's numbers in it, or None when a
    number is not finite."""
    import orjson
    matrix = np.ascontiguousarray(matrix, dtype=np.float64)
    if not np.isfinite(matrix).all():
        return None
    text = np.frombuffer(orjson.dumps(matrix, option=orjson.OPT_SERIALIZE_NUMPY), dtype=np.uint8)
    starts = np.flatnonzero(text == _OPEN)[1:] + 1      # the first '[' opens the whole list
    ends = np.flatnonzero(text == _CLOSE)[:-1]          # the last ']' closes it
    return text, starts, ends


class RowWriter:
    """Formats blocks of rows for one set of IMU names into buffers it keeps: fresh megabytes for every block
    cost a page fault each 4 KiB, as much as the formatting itself."""

    def __init__(self, imu_names):
        names = [quoted(name) for name in imu_names]
        self.n_imu = len(names)
        self._names = np.frombuffer(b"".join(names), dtype=np.uint8)
        self._name_ends = np.cumsum([len(x) for x in names], dtype=np.int64)
        self._name_starts = self._name_ends - np.array([len(x) for x in names], dtype=np.int64)
        self._text = np.empty(0, np.uint8)
        self._out = np.empty(0, np.uint8)

    def rows(self, segments, n: int) -> memoryview | None:
        """The CSV rows (no header) of n samples, sample k of every IMU before sample k + 1, valid until the
        next call.

        `segments`: the row's groups of columns in order, each (per_imu, matrix): per_imu matrices have one row
        per IMU per sample (IMU fastest), the others one row per sample. The name column follows the first
        group. None when a number is not finite (orjson has no text for it)."""
        n_imu = self.n_imu
        if n == 0 or n_imu == 0:
            return memoryview(b"")
        texts = []
        starts = np.zeros((len(segments), n * n_imu), np.int64)
        ends = np.zeros((len(segments), n * n_imu), np.int64)
        offset = 0
        for s, (per_imu, matrix) in enumerate(segments):
            found = _segment_text(matrix)
            if found is None:
                return None
            text, seg_starts, seg_ends = found
            starts[s, :len(seg_starts)] = seg_starts + offset
            ends[s, :len(seg_ends)] = seg_ends + offset
            texts.append(text)
            offset += len(text)
        self._text = _room(self._text, offset)
        np.concatenate(texts, out=self._text[:offset])
        per_imu = np.array([p for p, _ in segments], dtype=np.uint8)     # uint8: machine code takes no bool arrays
        size = _size(starts, ends, per_imu, self._name_starts, self._name_ends, n, n_imu)
        self._out = _room(self._out, size)
        _fill(self._out, self._text, starts, ends, per_imu, self._names, self._name_starts, self._name_ends, n,
              n_imu)
        return memoryview(self._out)[:size]


def _room(buffer: np.ndarray, size: int) -> np.ndarray:
    return buffer if len(buffer) >= size else np.empty(max(size, 2 * len(buffer)), np.uint8)


@intrinsic
def _copy(typingctx, dst, dst_start, src, src_start, count):
    """dst[dst_start:dst_start + count] = src[src_start:...] as one memcpy of bytes (uint8 arrays): a byte loop
    or a slice assignment costs ~1.5 ns a byte, and a row has ~250."""
    from numba.core import cgutils, types

    def codegen(context, builder, signature, args):
        dst_array = context.make_array(signature.args[0])(context, builder, args[0])
        src_array = context.make_array(signature.args[2])(context, builder, args[2])
        cgutils.raw_memcpy(builder, builder.gep(dst_array.data, [args[1]]),
                           builder.gep(src_array.data, [args[3]]), args[4], 1)
        return context.get_dummy_value()
    return types.void(dst, types.int64, src, types.int64, types.int64), codegen


@jit(cache=True, nogil=True)
def _size(starts, ends, per_imu, name_starts, name_ends, n, n_imu):
    size = 0
    for s in range(len(per_imu)):
        count = n * n_imu if per_imu[s] else n
        for r in range(count):
            size += (ends[s, r] - starts[s, r]) * (1 if per_imu[s] else n_imu)
    for m in range(n_imu):
        size += n * (name_ends[m] - name_starts[m])
    return size + n * n_imu * (len(per_imu) + 1)     # commas between the groups and the name, and the '\n'


@jit(cache=True, nogil=True)
def _fill(out, text, starts, ends, per_imu, name_bytes, name_starts, name_ends, n, n_imu):
    n_seg = len(per_imu)
    p = 0
    for k in range(n):
        for m in range(n_imu):
            for s in range(n_seg):
                if s > 0:
                    out[p] = 44                # ','
                    p += 1
                r = k * n_imu + m if per_imu[s] else k
                a, b = starts[s, r], ends[s, r]
                _copy(out, p, text, a, b - a)
                p += b - a
                if s == 0:
                    out[p] = 44
                    p += 1
                    a, b = name_starts[m], name_ends[m]
                    _copy(out, p, name_bytes, a, b - a)
                    p += b - a
            out[p] = 10                        # '\n'
            p += 1
