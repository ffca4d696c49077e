"""Format-neutral pieces of the big-endian serial formats (Xsens Xbus, MicroStrain MIP): a numba batch
packer that writes fixed-size packets straight from the sample arrays, and a stream scanner that finds
frames by sync pattern, length and checksum without ever raising."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

from imu_emulator.native.lazy import jit
import numpy as np

from firmware_protocols.base import DecoderStats, EncodeError, SaturationStats, Samples, SerialBatch

# ============================================================================================
# Format-neutral batch packer: fixed-size big-endian packets straight from the sample arrays.
# ============================================================================================

KIND_U8, KIND_U16, KIND_U32, KIND_F32, KIND_F64, KIND_FP1220, KIND_FP1632, KIND_I32 = range(8)
CHECKSUM_XBUS, CHECKSUM_FLETCHER16 = 0, 1
# Where a column's value comes from.
FROM_FIELD, FROM_COUNTER, FROM_TIME_DIV, FROM_TIME_REM_S, FROM_CONSTANT = range(5)

KIND_SIZE = {KIND_U8: 1, KIND_U16: 2, KIND_U32: 4, KIND_F32: 4, KIND_F64: 8, KIND_FP1220: 4, KIND_FP1632: 6,
             KIND_I32: 4}
_F32_MAX = float(np.finfo(np.float32).max)
_F64_MAX = float(np.finfo(np.float64).max)

# Range of each kind in wire units (integer kinds: the raw integer after scaling and rounding).
_KIND_RANGE = {
    KIND_U8: (0.0, 255.0),
    KIND_U16: (0.0, 65535.0),
    KIND_U32: (0.0, 4294967295.0),
    KIND_F32: (-_F32_MAX, _F32_MAX),
    KIND_F64: (-_F64_MAX, _F64_MAX),
    KIND_FP1220: (-2.0 ** 31, 2.0 ** 31 - 1),
    KIND_FP1632: (-2.0 ** 47, 2.0 ** 47 - 1),
    KIND_I32: (-2.0 ** 31, 2.0 ** 31 - 1),      # two's complement: _put_be of a negative int64 writes it
}
# Fixed-point kinds carry their LSB inside the column scale, so the range check sees raw integers.
_KIND_UNIT = {KIND_FP1220: 2.0 ** 20, KIND_FP1632: 2.0 ** 32}
# Sources are passed as a fixed-length tuple so that one compiled kernel serves every layout.
_SLOTS = 16
_EMPTY_SOURCE = np.zeros((1, 1), dtype=np.float64)


@jit(cache=True, nogil=True)
def _put_be(out, p, value, nbytes):
    for k in range(nbytes - 1, -1, -1):
        out[p + k] = value & 0xFF
        value >>= 8


@jit(cache=True, nogil=True)
def pack_fixed_packets(sources, time_ns, counter0, ilayout, flayout, template, checksum_kind, out, sat_counts):
    """Write len(time_ns) packets of len(template) bytes into out.

    sources: tuple of (rows, k) float64 arrays; a source with one row serves every sample (defaults).
    ilayout: (m, 8) int64 per column: kind, byte position, origin, source slot, component, divisor,
             offset, modulus.
    flayout: (m, 4) float64 per column: scale, lo, hi, constant.
      origin FROM_FIELD       value = sources[slot][i, component]
             FROM_COUNTER     value = counter0 + i
             FROM_TIME_DIV    value = (time_ns[i] + offset) // divisor       (exact integer arithmetic)
             FROM_TIME_REM_S  value = ((time_ns[i] + offset) mod divisor) / 1e9
             FROM_CONSTANT    value = constant
    Counter and time-quotient values are reduced modulo `modulus` (if > 0), as a device's counters wrap.
    The value is then multiplied by scale; integer kinds are rounded to nearest; anything outside
    [lo, hi] is clipped and counted in sat_counts[column].
    Returns (flat index i*m + j of the first non-finite value or -1, number of values clipped).
    """
    n = time_ns.shape[0]
    m = ilayout.shape[0]
    length = template.shape[0]
    f32 = np.empty(1, np.float32)
    f32_bits = f32.view(np.uint32)
    f64 = np.empty(1, np.float64)
    f64_bits = f64.view(np.int64)
    clipped = 0
    for i in range(n):
        base = i * length
        out[base:base + length] = template
        for j in range(m):
            kind = ilayout[j, 0]
            origin = ilayout[j, 2]
            if origin == FROM_FIELD:
                src = sources[ilayout[j, 3]]
                v = src[i if src.shape[0] > 1 else 0, ilayout[j, 4]]
                if not np.isfinite(v):
                    return i * m + j, clipped
            elif origin == FROM_COUNTER or origin == FROM_TIME_DIV:
                count = counter0 + i if origin == FROM_COUNTER else (time_ns[i] + ilayout[j, 6]) // ilayout[j, 5]
                if ilayout[j, 7] > 0:
                    count %= ilayout[j, 7]
                v = float(count)
            elif origin == FROM_TIME_REM_S:
                v = ((time_ns[i] + ilayout[j, 6]) % ilayout[j, 5]) / 1e9
            else:
                v = flayout[j, 3]
            v = v * flayout[j, 0]
            if kind != KIND_F32 and kind != KIND_F64:
                v = np.rint(v)
            if v < flayout[j, 1]:
                v = flayout[j, 1]
                sat_counts[j] += 1
                clipped += 1
            elif v > flayout[j, 2]:
                v = flayout[j, 2]
                sat_counts[j] += 1
                clipped += 1
            p = base + ilayout[j, 1]
            if kind == KIND_F32:
                f32[0] = v
                _put_be(out, p, np.int64(f32_bits[0]), 4)
            elif kind == KIND_F64:
                f64[0] = v
                _put_be(out, p, f64_bits[0], 8)
            elif kind == KIND_FP1632:
                raw = np.int64(v)
                _put_be(out, p, raw & 0xFFFFFFFF, 4)          # fraction first
                _put_be(out, p + 4, (raw >> 32) & 0xFFFF, 2)  # then the integer part
            else:
                nbytes = 1 if kind == KIND_U8 else (2 if kind == KIND_U16 else 4)
                _put_be(out, p, np.int64(v), nbytes)
        if checksum_kind == CHECKSUM_XBUS:
            total = 0
            for k in range(base + 1, base + length - 1):
                total += out[k]
            out[base + length - 1] = (-total) & 0xFF
        else:
            a = 0
            b = 0
            for k in range(base, base + length - 2):
                a = (a + out[k]) & 0xFF
                b = (b + a) & 0xFF
            out[base + length - 2] = a
            out[base + length - 1] = b
    return -1, clipped


@dataclass(frozen=True)
class Column:
    """One wire value: where it lands in the packet and how it is obtained from a Samples block."""

    kind: int
    position: int
    label: str                    # name in encoder.saturated and in error messages
    origin: int = FROM_FIELD
    source: str = ""              # FROM_FIELD: the Samples field (or an extra source the format computes)
    component: int = 0
    scale: float = 1.0            # SI -> wire
    divisor: int = 1              # FROM_TIME_*: ns per unit
    offset: int = 0               # FROM_TIME_*: ns added to time_ns first
    modulus: int = 0              # FROM_COUNTER / FROM_TIME_DIV: wrap (0: none; saturate instead)
    constant: float = 0.0         # FROM_CONSTANT


class FixedPacketPacker:
    """Packets of one fixed layout, one per sample, packed by one compiled kernel.

    `defaults` maps a source name to the row used when the Samples field is None (Samples' documented
    defaults); `extra` sources (values a format derives, e.g. Xsens DeltaQ) are passed to pack().
    """

    def __init__(self, template: bytes, columns: Sequence[Column], checksum_kind: int, defaults: dict):
        self.template = np.frombuffer(bytes(template), dtype=np.uint8).copy()
        self.columns = list(columns)
        self.checksum_kind = checksum_kind
        self.slots = sorted({c.source for c in self.columns if c.origin == FROM_FIELD})
        if len(self.slots) > _SLOTS:
            raise ValueError(f"at most {_SLOTS} distinct source fields per packet")
        self.defaults = {name: np.asarray(defaults[name], dtype=np.float64).reshape(1, -1)
                         for name in self.slots if name in defaults}
        m = len(self.columns)
        self.ilayout = np.zeros((m, 8), dtype=np.int64)
        self.flayout = np.zeros((m, 4), dtype=np.float64)
        for j, c in enumerate(self.columns):
            lo, hi = _KIND_RANGE[c.kind]
            slot = self.slots.index(c.source) if c.origin == FROM_FIELD else 0
            self.ilayout[j] = (c.kind, c.position, c.origin, slot, c.component, c.divisor, c.offset, c.modulus)
            self.flayout[j] = (c.scale * _KIND_UNIT.get(c.kind, 1.0), lo, hi, c.constant)

    @property
    def packet_size(self) -> int:
        return int(self.template.shape[0])

    def pack(self, samples: Samples, saturated: SaturationStats, counter0: int = 0,
             extra: dict | None = None) -> SerialBatch:
        sources = [_EMPTY_SOURCE] * _SLOTS
        for k, name in enumerate(self.slots):
            value = extra[name] if extra and name in extra else getattr(samples, name, None)
            if value is None:
                value = self.defaults[name]
            elif value.ndim == 1:
                value = value.reshape(-1, 1)
            if not (value.flags.c_contiguous and value.flags.writeable):
                value = np.array(value, dtype=np.float64, order="C")   # one array type for the kernel
            sources[k] = value
        n = len(samples)
        size = self.packet_size
        out = np.empty(n * size, dtype=np.uint8)
        counts = np.zeros(len(self.columns), dtype=np.int64)
        bad, clipped = pack_fixed_packets(tuple(sources), samples.time_ns, counter0, self.ilayout,
                                          self.flayout, self.template, self.checksum_kind, out, counts)
        if bad >= 0:
            col = self.columns[bad % len(self.columns)]
            where = f"sample {bad // len(self.columns)}, component {col.component}"
            if col.source in _FIELD_NAMES:
                samples.require_finite([col.source])     # the base class's wording when it applies
            raise EncodeError(f"non-finite value in field '{col.source}' (wire field '{col.label}') at {where}")
        if clipped:
            for j in np.flatnonzero(counts):
                saturated.add(self.columns[j].label, int(counts[j]))
        return SerialBatch(out.tobytes(), np.arange(0, (n + 1) * size, size, dtype=np.int64))


_FIELD_NAMES = {"accel", "gyro", "mag", "quat", "euler", "temperature_c", "pressure_pa", "delta_theta",
                "delta_velocity"}


# ============================================================================================
# Format-neutral stream scanner: sync pattern, length from the header, checksum, never raises.
# ============================================================================================

NEED_MORE = -1
NOT_A_FRAME = -2


class FrameScanner:
    """Cuts frames out of an arbitrarily chunked byte stream.

    frame_length(buf, j) returns the total length of the frame whose sync starts at j, NEED_MORE if the
    header is incomplete, or NOT_A_FRAME if the header is impossible; checksum_ok(frame) validates a
    complete candidate. A failed candidate costs one byte: scanning resumes just after its sync, so a
    real frame hidden behind a false sync is still found (late, once the false frame's claimed length
    has arrived; for Xbus at most 8 KiB, for MIP 261 bytes).
    """

    def __init__(self, sync: bytes, frame_length: Callable, checksum_ok: Callable):
        self.sync = sync
        self.frame_length = frame_length
        self.checksum_ok = checksum_ok
        self.stats = DecoderStats()
        self._buf = bytearray()
        self._offset = 0        # stream offset of the buffer's first byte
        self._bad_end = 0       # stream offset just after the last damaged candidate answered

    def frames(self, chunk: bytes) -> list[bytes]:
        """The complete frames whose checksum held, in stream order."""
        return [frame for frame, ok in self._candidates(chunk, keep_damaged=False) if ok]

    def candidates(self, chunk: bytes) -> list[tuple[bytes, bool]]:
        """Complete candidates in stream order with whether their checksum held: a device answers a damaged
        command (Xsens Error, MIP NACK) where a decoder only counts it. A damaged candidate that starts inside
        the last damaged one is left out: a device answers only the first, so a flood of sync patterns (each a
        false frame overlapping the previous) gets one error reply per claimed frame length, not one per sync."""
        return self._candidates(chunk, keep_damaged=True)

    def _candidates(self, chunk: bytes, keep_damaged: bool) -> list[tuple[bytes, bool]]:
        # Damaged candidates are copied out only when kept: a flood of false Xbus headers, each promising
        # 8 KiB, held a copy of every one until the call returned (2.7 GB for a 2 MB flood).
        buf = self._buf
        buf += chunk
        found = []
        pos = search = 0
        while True:
            j = buf.find(self.sync, search)
            if j < 0:
                # keep a tail that could still be the start of a sync pattern
                keep = next((k for k in range(len(self.sync) - 1, 0, -1) if buf.endswith(self.sync[:k])), 0)
                drop_to = max(pos, len(buf) - keep)
                self.stats.skipped_bytes += drop_to - pos
                pos = drop_to
                break
            self.stats.skipped_bytes += j - pos
            pos = j
            total = self.frame_length(buf, j)
            if total == NEED_MORE:
                break
            if total == NOT_A_FRAME:
                search = j + 1
                continue
            if len(buf) - j < total:
                break
            frame = bytes(buf[j:j + total])
            if not self.checksum_ok(frame):
                self.stats.bad_checksum += 1
                start = self._offset + j
                if keep_damaged and start >= self._bad_end:
                    found.append((frame, False))
                    self._bad_end = start + total
                search = j + 1
                continue
            found.append((frame, True))
            pos = search = j + total
        del buf[:pos]
        self._offset += pos
        return found

    def drop_partial(self) -> int:
        """Forget a frame still arriving (its datagram ended: the rest will never come); how many bytes."""
        n = len(self._buf)
        self.stats.skipped_bytes += n
        self._buf.clear()
        self._offset += n
        return n

def parse_names(value, known, what: str) -> tuple:
    names = tuple(n.strip() for n in value.split(",") if n.strip()) if isinstance(value, str) else tuple(value)
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise ValueError(f"{what}: unknown or empty {unknown or names!r}; choose from {', '.join(known)}")
    if len(set(names)) != len(names):
        raise ValueError(f"{what}: an item is listed twice: {names!r}")
    return names

def as_int(value) -> int:
    """Option value -> int; strings (from a command line) may be written in hex, e.g. "0x1C"."""
    return int(value, 0) if isinstance(value, str) else int(value)
