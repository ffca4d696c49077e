"""VectorNav (VN-100/200/300) ASCII output: $VNYMR / $VNIMU sentences and their stream decoder (the binary
packets: vectornav_binary; the replies a driver waits for: firmware_protocols.devices.vectornav).

ASCII number formats are the device's own, read off published output with valid checksums: VectorNav's
programming-library example `$VNYMR,+100.949,-007.330,+000.715,-00.0049,...*69` and a VN-200 capture
`$VNIMU,-00.0350,+00.4222,-00.6643,-00.015,+00.019,+09.948,+00.002066,...,+20.7,+084.322*66`:
angles %+08.3f, mag %+08.4f, accel %+07.3f, gyro %+010.6f, temperature %+05.1f, pressure %+08.3f
(kPa). Values are rounded to float32 first, as the device prints its float registers. Wider values
simply widen the field, as printf does; `bytes_per_sample` is the nominal (fixed-width) length.
"""
from __future__ import annotations

import functools
import struct
from dataclasses import dataclass

import numpy as np

from firmware_protocols.base import DecoderStats, Packet, SaturationStats, Samples, SerialBatch
from firmware_protocols.registry import FormatInfo, register
from firmware_protocols.vectornav_common import DEG, SAMPLE_DEFAULTS, sentence, verify_line

_F32_MAX = float(np.finfo(np.float32).max)


# --- ASCII sentences -------------------------------------------------------------------------

@dataclass(frozen=True)
class _Sentence:
    name: str
    parts: tuple    # (Samples field, component order, scale SI -> wire, printf format)


_SENTENCES = {
    "VNYPR": _Sentence("VNYPR", (("euler", (2, 1, 0), DEG, "%+08.3f"),)),
    "VNYMR": _Sentence("VNYMR", (("euler", (2, 1, 0), DEG, "%+08.3f"), ("mag", (0, 1, 2), 1.0, "%+08.4f"),
                                 ("accel", (0, 1, 2), 1.0, "%+07.3f"), ("gyro", (0, 1, 2), 1.0, "%+010.6f"))),
    "VNIMU": _Sentence("VNIMU", (("mag", (0, 1, 2), 1.0, "%+08.4f"), ("accel", (0, 1, 2), 1.0, "%+07.3f"),
                                 ("gyro", (0, 1, 2), 1.0, "%+010.6f"), ("temperature_c", (0,), 1.0, "%+05.1f"),
                                 ("pressure_pa", (0,), 1e-3, "%+08.3f"))),
}
_CHECKSUM_KINDS = ("xor", "crc")


def _check_kind(checksum: str) -> str:
    if checksum not in _CHECKSUM_KINDS:
        raise ValueError(f"VectorNav checksum: expected 'xor' or 'crc', got {checksum!r}")
    return checksum


class AsciiEncoder:
    """Samples -> $VNYMR or $VNIMU lines, one per sample."""
    body_axes, reference = "FRD", "NED"      # as vectornav_binary.BinaryEncoder (one device, two encodings)
    axes_source = "VN-100 User Manual UM001 4.4.3-4.4.5: body frame w.r.t. NED (so x fwd, y right, z down)"


    def __init__(self, name: str, checksum: str = "xor"):
        self.spec = _SENTENCES[name]
        self.checksum = _check_kind(checksum)
        self.saturated = SaturationStats()
        self._format = (name + "," + ",".join(fmt for _, order, _, fmt in self.spec.parts for _ in order))
        self._f32 = "<%df" % sum(len(order) for _, order, _, _ in self.spec.parts)
        widths = sum(int(fmt[2:fmt.index(".")]) * len(order) + len(order) for _, order, _, fmt in self.spec.parts)
        self.bytes_per_sample = 1 + len(name) + widths + 1 + (2 if checksum == "xor" else 4) + 2

    def encode(self, samples: Samples) -> SerialBatch:
        # Plain Python per line (the formatting is per line anyway): one path serves a batch and the
        # single sample of the live path, which a dozen numpy calls per block would make cost ~40 us.
        n = len(samples)
        parts = []
        for src, order, scale, _ in self.spec.parts:
            value = getattr(samples, src)
            rows = [SAMPLE_DEFAULTS[src]] * n if value is None else value.reshape(n, -1).tolist()
            parts.append((rows, order, scale, src))
        lines = []
        for i in range(n):
            values = [row[i][j] * scale for row, order, scale, _ in parts for j in order]
            if not all(-_F32_MAX <= v <= _F32_MAX for v in values):   # false for NaN too
                values = self._saturate(values, samples, parts)
            # The device prints its float32 registers: round there first so the last digit agrees.
            values = struct.unpack(self._f32, struct.pack(self._f32, *values))
            lines.append(sentence((self._format % values).encode(), self.checksum))
        offsets = np.zeros(n + 1, dtype=np.int64)
        np.cumsum([len(line) for line in lines], out=offsets[1:])
        return SerialBatch(b"".join(lines), offsets)

    def _saturate(self, values: list, samples: Samples, parts) -> list:
        samples.require_finite([src for *_, src in parts])      # raises, naming field and sample
        out, k = [], 0
        for _, order, _, src in parts:
            for _ in order:
                v = values[k]
                k += 1
                if abs(v) > _F32_MAX:
                    self.saturated.add(f"{self.spec.name.lower()}.{src}", 1)
                    v = _F32_MAX if v > 0 else -_F32_MAX
                out.append(v)
        return out


class AsciiDecoder:
    """Stream decoder for $VNYMR / $VNIMU lines. Valid sentences of other kinds (register replies,
    $VNERR) count as ignored_frames; anything outside a `$...\\r\\n` line counts as skipped bytes."""

    MAX_LINE = 256

    def __init__(self, checksum: str | None = None):
        # Both checksum kinds are accepted whatever the option says: a receiver cannot know which one
        # the device was told to use, and the kinds are told apart by their length.
        if checksum is not None:
            _check_kind(checksum)
        self.stats = DecoderStats()
        self._buf = bytearray()

    def _parse(self, body: bytes):
        name, _, rest = body.partition(b",")
        spec = _SENTENCES.get(name.decode("ascii", "replace"))
        if spec is None:
            return None
        try:
            numbers = [float(t) for t in rest.split(b",")]
        except ValueError:
            return None
        if len(numbers) != sum(len(order) for _, order, _, _ in spec.parts):
            return None
        fields, k = {}, 0
        for src, order, scale, _ in spec.parts:
            si = np.empty(len(order))
            si[list(order)] = np.asarray(numbers[k:k + len(order)]) / scale
            fields[src] = float(si[0]) if len(order) == 1 else si
            k += len(order)
        return Packet(spec.name, fields)

    def feed(self, chunk: bytes) -> list:
        buf = self._buf
        buf += chunk
        packets, pos = [], 0
        while True:
            start = buf.find(b"$", pos)
            if start < 0:
                self.stats.skipped_bytes += len(buf) - pos
                pos = len(buf)
                break
            self.stats.skipped_bytes += start - pos
            pos = start
            # Look no further than the longest line: searching to the end of the buffer for every '$'
            # made a flood of '$' cost quadratic time.
            window = min(len(buf), pos + self.MAX_LINE + 2)
            end = buf.find(b"\r\n", pos, window)
            restart = buf.find(b"$", pos + 1, end if end >= 0 else window)
            if restart >= 0:       # a line cut short by a new '$': drop the fragment
                self.stats.skipped_bytes += restart - pos
                pos = restart
                continue
            if end < 0:
                if window - pos == self.MAX_LINE + 2:    # no line end within reach: not a line
                    self.stats.skipped_bytes += window - pos
                    pos = window
                    continue
                break
            line = bytes(buf[pos:end])
            body = verify_line(line)
            if body is None:
                self.stats.bad_checksum += 1
                self.stats.skipped_bytes += end + 2 - pos
            else:
                packet = self._parse(body)
                if packet is None:
                    self.stats.ignored_frames += 1
                    self.stats.skipped_bytes += end + 2 - pos
                else:
                    packet.raw = bytes(buf[pos:end + 2])
                    packets.append(packet)
                    self.stats.packets += 1
            pos = end + 2
        del buf[:pos]
        return packets


# --- registry --------------------------------------------------------------------------------

for _name in ("VNYMR", "VNIMU"):      # VNYPR only for the device's register 6 (ADOR 1), not a format of its own
    register(FormatInfo(
        name=f"vectornav-{_name.lower()}", kind="serial",
        description=f"VectorNav ${_name} ASCII sentence",
        encoder=functools.partial(AsciiEncoder, _name),
        decoder=AsciiDecoder,
        bytes_per_sample=AsciiEncoder(_name).bytes_per_sample,
        options={"checksum": "'xor' (8-bit, 2 hex digits) or 'crc' (CRC-16/XMODEM, 4 hex digits)"},
    ))
