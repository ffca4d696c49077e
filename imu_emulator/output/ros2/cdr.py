"""Blocks of ROS 2 messages in CDR as rows of a numpy structured array: one row is one whole MCAP message record
(its header, then the CDR payload), so a block of n messages is filled by a few array assignments and written
as one buffer, instead of a Python call per message and per field (issue 25: ~92 us a message that way).

This works because the messages written here have a fixed layout per topic: every string in them (frame ids)
is a constant of the topic and every array has a fixed length, so each field sits at the same offset in every
message. The layout follows the CDR rules ROS 2 uses (XCDR1, little endian, as rmw and rosbags write it): a
4-byte encapsulation header 00 01 00 00, then each primitive aligned to its own size (doubles to 8) counted
from the header's end; a string is a uint32 length (with its NUL), its bytes and a NUL; a sequence a uint32
count and its elements; nested messages add no padding of their own. Padding bytes are zero.

MCAP's message record (opcode 0x05): uint64 record length, uint16 channel id, uint32 sequence, uint64 log time,
uint64 publish time, then the payload (https://mcap.dev/spec#message-op0x05).
"""
from __future__ import annotations

import numpy as np

ENCAPSULATION = b"\x00\x01\x00\x00"      # CDR little endian (CDR_LE), options 0
MESSAGE_OPCODE = 0x05
#: the message record's fields before the payload: opcode 1, length 8, channel 2, sequence 4, times 8 + 8
RECORD_HEADER = 31


class Layout:
    """A message's CDR layout, built field by field in the message definition's order. Variable fields get a
    name (filled per message); constants (frame ids, covariances that never change) are given their value and
    written once into the block's buffer."""

    def __init__(self):
        self._at = 0                # offset after the encapsulation header
        self.fields: list[tuple[str, str, tuple, int]] = []     # name, numpy type, shape, offset in the payload
        self.constants: list[tuple[int, bytes]] = []            # offset in the payload, bytes

    def _align(self, size: int) -> int:
        self._at = -(-self._at // size) * size
        return self._at

    def field(self, name: str, kind: str, count: int = 1) -> "Layout":
        """A primitive (numpy type code: "<f8", "<i4", "<u4", "<u2", "u1", "i1") or a fixed array of `count`."""
        size = np.dtype(kind).itemsize
        at = self._align(size)
        self.fields.append((name, kind, (count,) if count > 1 else (), at))
        self._at += size * count
        return self

    def constant(self, kind: str, value) -> "Layout":
        """A primitive or a fixed array whose value is the same in every message."""
        data = np.asarray(value, dtype=kind)
        at = self._align(data.dtype.itemsize)
        self.constants.append((at, data.tobytes()))
        self._at += data.nbytes
        return self

    def string(self, text: str) -> "Layout":
        """A constant string (frame ids are the topic's)."""
        raw = text.encode() + b"\x00"
        self.constant("<u4", len(raw))
        self.constants.append((self._at, raw))
        self._at += len(raw)
        return self

    @property
    def size(self) -> int:
        """The payload's bytes with its encapsulation header (no padding after the last field)."""
        return 4 + self._at

    def record_dtype(self) -> np.dtype:
        """One MCAP message record carrying this message: the record header's fields, then "payload" fields
        at their offsets (all unaligned in memory, which numpy handles)."""
        base = RECORD_HEADER + 4
        names = ["opcode", "length", "channel", "sequence", "log_time", "publish_time"]
        formats = ["u1", "<u8", "<u2", "<u4", "<u8", "<u8"]
        offsets = [0, 1, 9, 11, 15, 23]
        for name, kind, shape, at in self.fields:
            names.append(name)
            formats.append((kind, shape) if shape else kind)
            offsets.append(base + at)
        return np.dtype({"names": names, "formats": formats, "offsets": offsets,
                         "itemsize": RECORD_HEADER + self.size})

    def record_template(self, channel: int) -> bytes:
        """The bytes every record of a channel shares: opcode, length, channel id, the encapsulation header and
        the constants; the variable fields are zero."""
        raw = bytearray(RECORD_HEADER + self.size)
        raw[0] = MESSAGE_OPCODE
        raw[1:9] = (len(raw) - 9).to_bytes(8, "little")
        raw[9:11] = channel.to_bytes(2, "little")
        raw[RECORD_HEADER:RECORD_HEADER + 4] = ENCAPSULATION
        for at, data in self.constants:
            start = RECORD_HEADER + 4 + at
            raw[start:start + len(data)] = data
        return bytes(raw)

    def payload(self, record: bytes) -> bytes:
        """The CDR message of one record (tests compare it with rosbags' serializer)."""
        return bytes(record[RECORD_HEADER:])
