"""An MCAP file (https://mcap.dev/spec) written a block of messages at a time: the messages of a block are the
rows of one structured array (cdr.Layout.record_dtype, one field per channel), cut into chunks of about
CHUNK_BYTES, each compressed with zstd in its fast mode (level -3) in one call and followed by its message index
records, built with numpy. Python does per-chunk work, never per-message work. The summary (schemas, channels,
statistics, chunk and metadata indexes, summary offsets) is written with the mcap library's record classes, as
its own writer would; readers (mcap, rosbag2_storage_mcap, Foxglove) find everything through it.

Chunks carry the CRC-32 of their uncompressed records (readers that validate CRCs check it); the data section's
CRC is computed over every byte before the DataEnd record. zstd level -3 rather than the library's default 3:
measured on this project's machines (tools/bench_mcap.py's chunks of random Imu samples, interleaved), 0.31 us a
message against 0.56 at level 1 and more at 3, for a compressed size of 0.259 of the records against 0.254:
the constant fields (covariances, frame ids, record headers) compress away at any level and the random doubles
at none.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

import numpy as np

from imu_emulator.output.ros2.cdr import Layout

MAGIC = b"\x89MCAP0\r\n"
CHUNK_BYTES = 1 << 20
ZSTD_LEVEL = -3
_CHUNK, _MESSAGE_INDEX = 0x06, 0x07


@dataclass
class Channel:
    id: int
    topic: str
    layout: Layout
    dtype: np.dtype             # one message record
    template: bytes             # its constant bytes
    messages: int = 0


class BagFile:
    """Writes an MCAP file with the ros2 profile to a binary file object; finish() writes the summary (the
    caller closes the file)."""

    def __init__(self, file, library: str):
        from mcap.data_stream import RecordBuilder
        from mcap.records import Header
        import zstandard
        self._file = file
        self._crc = 0
        self._offset = 0
        self._compress = zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress
        self.schemas: dict = {}          # name -> mcap.records.Schema
        self.channels: list[Channel] = []
        self._channel_records: list = []
        self._chunk_indexes: list = []
        self._metadata_indexes: list = []
        self._start = self._end = None
        self._rows_cache: tuple | None = None
        self._write(MAGIC)
        builder = RecordBuilder()
        Header(profile="ros2", library=library).write(builder)
        self._write(builder.end())

    def _write(self, data) -> None:
        self._file.write(data)
        self._crc = zlib.crc32(data, self._crc)
        self._offset += len(data) if isinstance(data, bytes) else memoryview(data).nbytes

    def _record(self, record) -> int:
        """Write one mcap.records record; returns its offset."""
        from mcap.data_stream import RecordBuilder
        builder = RecordBuilder()
        record.write(builder)
        at = self._offset
        self._write(builder.end())
        return at

    def channel(self, topic: str, schema_name: str, definition: str, layout: Layout,
                metadata: dict | None = None) -> Channel:
        from mcap.records import Channel as ChannelRecord, Schema
        if schema_name not in self.schemas:
            schema = Schema(id=len(self.schemas) + 1, name=schema_name, encoding="ros2msg",
                            data=definition.encode())
            self.schemas[schema_name] = schema
            self._record(schema)
        record = ChannelRecord(id=len(self.channels) + 1, topic=topic, message_encoding="cdr",
                               schema_id=self.schemas[schema_name].id, metadata=dict(metadata or {}))
        self._record(record)
        self._channel_records.append(record)
        channel = Channel(record.id, topic, layout, layout.record_dtype(), layout.record_template(record.id))
        self.channels.append(channel)
        return channel

    def metadata(self, name: str, values: dict[str, str]) -> None:
        from mcap.records import Metadata, MetadataIndex
        at = self._record(Metadata(name=name, metadata=values))
        self._metadata_indexes.append(MetadataIndex(offset=at, length=self._offset - at, name=name))

    def rows(self, channels: list[Channel], n: int, keep: bool = True) -> np.ndarray:
        """n rows of one message per channel, back to back (field "c<id>" each), constants in place: fill the
        variable fields (and "log_time", "publish_time") and give them to write_rows. The array is reused by
        next call with the same channels and n when `keep` (constants are written once)."""
        key = (tuple(c.id for c in channels), n)
        if self._rows_cache is not None and self._rows_cache[0] == key:
            return self._rows_cache[1]
        offsets = np.cumsum([0] + [c.dtype.itemsize for c in channels])
        dtype = np.dtype({"names": [f"c{c.id}" for c in channels], "formats": [c.dtype for c in channels],
                          "offsets": list(offsets[:-1]), "itemsize": int(offsets[-1])})
        rows = np.empty(n, dtype)
        rows.view(np.uint8).reshape(n, dtype.itemsize)[:] = np.frombuffer(
            b"".join(c.template for c in channels), np.uint8)
        if keep:
            self._rows_cache = (key, rows)
        return rows

    def write_rows(self, rows: np.ndarray) -> None:
        """Write the messages of `rows` (from rows()): chunks of whole rows, each with its message indexes."""
        n = len(rows)
        if n == 0:
            return
        size = rows.dtype.itemsize
        raw = rows.view(np.uint8).reshape(n, size)
        fields = [(self.channels[int(name[1:]) - 1], rows.dtype.fields[name][1]) for name in rows.dtype.names]
        times = {channel.id: rows[f"c{channel.id}"]["log_time"] for channel, _ in fields}
        per_chunk = max(1, CHUNK_BYTES // size)
        for a in range(0, n, per_chunk):
            b = min(n, a + per_chunk)
            self._chunk(raw[a:b].reshape(-1), [(channel, at, times[channel.id][a:b]) for channel, at in fields],
                        size)
        for channel, _ in fields:
            channel.messages += n

    def _chunk(self, records: np.ndarray, channels, row_size: int) -> None:
        from mcap.records import ChunkIndex
        start = int(min(t.min() for _, _, t in channels))
        end = int(max(t.max() for _, _, t in channels))
        self._start = start if self._start is None else min(self._start, start)
        self._end = end if self._end is None else max(self._end, end)
        compressed = self._compress(records)
        chunk_start = self._offset
        header = struct.pack("<QQQI", start, end, records.nbytes, zlib.crc32(records)) + _string("zstd")
        self._write(struct.pack("<BQ", _CHUNK, len(header) + 8 + len(compressed)) + header
                    + struct.pack("<Q", len(compressed)))
        self._write(compressed)
        chunk_length = self._offset - chunk_start
        index_offsets = {}
        for channel, at, t in channels:
            entries = np.empty((len(t), 2), "<u8")
            entries[:, 0] = t
            entries[:, 1] = at + row_size * np.arange(len(t), dtype=np.uint64)
            index_offsets[channel.id] = self._offset
            self._write(struct.pack("<BQHI", _MESSAGE_INDEX, 2 + 4 + entries.nbytes, channel.id, entries.nbytes)
                        + entries.tobytes())
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start, message_end_time=end, chunk_start_offset=chunk_start,
            chunk_length=chunk_length, message_index_offsets=index_offsets,
            message_index_length=self._offset - chunk_start - chunk_length, compression="zstd",
            compressed_size=len(compressed), uncompressed_size=records.nbytes))

    def finish(self) -> None:
        from mcap.data_stream import RecordBuilder
        from mcap.opcode import Opcode
        from mcap.records import DataEnd, Footer, Statistics, SummaryOffset
        DataEnd(data_section_crc=self._crc).write(builder := RecordBuilder())
        self._write(builder.end())
        summary_start = self._offset
        summary = RecordBuilder()
        offsets = []
        groups = [(Opcode.SCHEMA, list(self.schemas.values())), (Opcode.CHANNEL, self._channel_records),
                  (Opcode.STATISTICS, [Statistics(
                      message_count=sum(c.messages for c in self.channels), schema_count=len(self.schemas),
                      channel_count=len(self.channels), attachment_count=0, metadata_count=len(self._metadata_indexes),
                      chunk_count=len(self._chunk_indexes), message_start_time=self._start or 0,
                      message_end_time=self._end or 0,
                      channel_message_counts={c.id: c.messages for c in self.channels})]),
                  (Opcode.CHUNK_INDEX, self._chunk_indexes), (Opcode.METADATA_INDEX, self._metadata_indexes)]
        for opcode, records in groups:
            if not records:
                continue
            at = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + at,
                                         group_length=summary.count - at))
        summary_offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        data = summary.end()
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, summary_offset_start),
                         zlib.crc32(data))
        self._file.write(data)
        builder = RecordBuilder()
        Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc).write(builder)
        self._file.write(builder.end() + MAGIC)


def _string(text: str) -> bytes:
    raw = text.encode()
    return struct.pack("<I", len(raw)) + raw
