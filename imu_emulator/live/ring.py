"""The producer's blocks to the sender through shared memory (issue 25). The producer writes a block's serial packets
(or a device's raw samples) into a ring of bytes the two processes share and describes the block in a table there
(first sample, length, where each stream's items lie, the encoders' saturation counts), then counts it published. The sender sees a block is
there by reading that count and takes it by reading its description: no system call, no unpickling. Before, the
block crossed a pipe pickled: at 10 kHz reading and unpickling it cost the sender 120-300 us of CPU every 200
samples (the code runs once per block, so its caches are cold: a 163-byte unpickle that takes 3 us in a loop took 45
us there), more than a period, and the block's first deadline was missed.

Blocks with other items (CAN frames, samples with attributes of their own), one too large for the ring, one whose
effect counters changed, the end and a failure still cross the pipe pickled, in order: their description says so.

The ring is an anonymous shared mapping made before the producer is forked: it has no name, no file in /dev/shm,
and only these two processes (and nothing they did not fork) can reach it; it goes with them however they end
(killed, crashed), so nothing can be left behind.

Who may write where: the sender holds at most two blocks at a time (the one it sends and the next, taken early while
there is slack), so when it takes block t, blocks up to t - 2 are done with; it stores that count, and the producer
reuses their bytes and table slots only then. A producer with no room sleeps _FULL_SLEEP_S at a time (it never wakes
the sender: that costs the sender CPU; the ring holds about a second, so it wakes rarely and still stays well
ahead) and gives up when its parent has gone. A sender with no block sets a flag and
waits on a doorbell pipe the producer writes a byte to when the flag is set; the flag and the count are plain
stores, which x86 may see out of order, so the sender's waits also end every _WAIT_S to look again.
"""
from __future__ import annotations

import ctypes
import mmap
import os
import platform
import select
import time

import numpy as np

from firmware_protocols.base import _FIELD_WIDTHS, Samples

# Bytes of packets the producer may run ahead by, and blocks: a pipe's buffer (64 KiB) bounded it before, a few
# blocks at 10 kHz; a mapping's pages are only taken when first written.
RING_BYTES = 1 << 21
MAX_BLOCKS = 64
MAX_STREAMS = 8             # more streams than this: blocks go through the pipe
_HEAD = 8                   # a block's description: j0, n, via pipe, streams, then per stream _PER of int64
_PER = 6                    # kind, position, samples, saturation total, then packets: bytes; samples: fields, start_ns
_PACKETS, _SAMPLES = 1, 2
# A device's raw samples (firmware_protocols.Samples): time_ns, then each field present (float64, n x width), in
# this order; which are present is a bit mask.
_SAMPLE_FIELDS = tuple(_FIELD_WIDTHS.items())
_NO_FIELDS = dict.fromkeys(_FIELD_WIDTHS)
_SLOT = _HEAD + _PER * MAX_STREAMS      # int64s per table slot
_HEADER = 64                # done, published, waiting (int64 each), on a cache line of their own
_TABLE = _SLOT * 8 * MAX_BLOCKS
_FULL_SLEEP_S = 0.05        # a full ring is looked at again after this (module docstring)
_WAIT_S = 0.001             # a waiting sender looks at the count at least this often
_ALIGN = 8
# The count is published by a plain store after the block's: only a CPU that keeps stores in order (x86's TSO) makes
# the block visible before the count without a barrier Python cannot issue. Elsewhere (ARM) blocks go down the pipe.
SHARED_RING = platform.machine().lower() in ("x86_64", "amd64", "i386", "i686")


class Packets:
    """One block's serial packets as one buffer and their offsets, as the producer makes them: written into the
    ring (or, when they do not fit, pickled as one bytes object: a fraction of what a list of small ones costs)."""

    __slots__ = ("data", "offsets")

    def __init__(self, data: bytes, offsets: list):
        self.data, self.offsets = data, offsets

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def __getitem__(self, j: int) -> bytes:
        return self.data[self.offsets[j]:self.offsets[j + 1]]

    def __getstate__(self):
        return self.data, self.offsets

    def __setstate__(self, state):
        self.data, self.offsets = state


class RingPackets:
    """One stream's packets of one block read in place from the ring: n + 1 int64 offsets (positions in the ring's
    data), then the bytes. A sample's packet is copied out (bytes) when it is sent, so nothing is read from the
    ring past the block. Built from four numbers: taking a block must cost the sender little (module docstring)."""
    __slots__ = ("words", "data", "k", "n")

    def __init__(self, words: memoryview, data: memoryview, pos: int, n: int):
        self.words, self.data, self.k, self.n = words, data, pos >> 3, n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, j: int) -> bytes:
        words = self.words
        k = self.k + j
        return bytes(self.data[words[k]:words[k + 1]])


class RingBlock:
    """A block taken from the ring, as the send loop reads it (the producer's _Block without the bytes)."""
    __slots__ = ("j0", "n", "items", "saturated", "counts")

    def __init__(self, j0, n, items, saturated, counts):
        self.j0, self.n, self.items, self.saturated, self.counts = j0, n, items, saturated, counts

    def __len__(self) -> int:
        return self.n


class Ring:
    """The shared mapping and the doorbell pipe, made before the fork; the producer calls put, the sender uses a
    BlockReceiver."""

    def __init__(self, capacity: int | None = None, max_blocks: int | None = None):
        self.capacity = capacity = -(-(RING_BYTES if capacity is None else capacity) // _ALIGN) * _ALIGN
        self.max_blocks = max_blocks = MAX_BLOCKS if max_blocks is None else max_blocks
        size = _HEADER + _SLOT * 8 * max_blocks + capacity
        self.map = mmap.mmap(-1, size, flags=mmap.MAP_SHARED | mmap.MAP_ANONYMOUS)
        header = (ctypes.c_int64 * 3).from_buffer(self.map)
        self.header = header                    # done (sender), published (producer), waiting (sender)
        table_end = _HEADER + _SLOT * 8 * max_blocks
        self.table = memoryview(self.map)[_HEADER:table_end].cast("q")
        self.data = memoryview(self.map)[table_end:]
        self.owner = os.getpid()                # the sender, whose child the producer is
        self.bell_r, self.bell_w = os.pipe()
        os.set_blocking(self.bell_r, False)
        os.set_blocking(self.bell_w, False)
        # The producer's side only (after the fork): blocks published, and where the bytes of those the sender may
        # still read lie.
        self._published = 0
        self._live = []             # (block number, start, end)
        self._head = 0
        self._counts = {}           # the counters as the sender knows them (last sent through the pipe)

    # - producer -
    def put(self, block, pipe) -> None:
        """Publish one block (the producer's _Block, or None at the end, or a ProducerFailure): its serial packets
        into the ring when it can, else the whole of it down `pipe`. Waits for room while the sender is behind."""
        items = getattr(block, "items", None)
        sizes = [_record_size(item) for item in items] if items else [None]
        ring = (0 < len(sizes) <= MAX_STREAMS and None not in sizes and block.counts == self._counts
                and sum(sizes) <= self.capacity // 4)   # with the sender holding two blocks, a third always has room
        size = sum(sizes) if ring else 0
        seq = self._published
        pos = self._room(size if ring else 0)
        slot = (seq % self.max_blocks) * _SLOT
        table = self.table
        if ring:
            table[slot:slot + 4] = _int64s((block.j0, block.n, 0, len(items)))
            for s, (item, saturated, item_size) in enumerate(zip(items, block.saturated, sizes)):
                at = slot + _HEAD + _PER * s
                if type(item) is Packets:
                    start = pos + len(item.offsets) * 8
                    self.data[pos:start] = _int64s([start + offset for offset in item.offsets]).cast("B")
                    self.data[start:start + len(item.data)] = item.data
                    table[at:at + _PER] = _int64s((_PACKETS, pos, len(item), saturated, len(item.data), 0))
                else:
                    n, mask, at_byte = len(item), 0, pos + len(item) * 8
                    self.data[pos:at_byte] = np.ascontiguousarray(item.time_ns).view(np.uint8)
                    for bit, (name, _) in enumerate(_SAMPLE_FIELDS):
                        value = getattr(item, name)
                        if value is not None:
                            mask |= 1 << bit
                            self.data[at_byte:at_byte + value.nbytes] = np.ascontiguousarray(value).reshape(-1).view(
                                np.uint8)
                            at_byte += value.nbytes
                    table[at:at + _PER] = _int64s((_SAMPLES, pos, n, saturated, mask, item.start_ns))
                pos += item_size
            self._publish(seq)
        else:
            table[slot + 2] = 1
            if items is not None:
                self._counts = block.counts
            self._publish(seq)      # before sending: a block larger than the pipe's buffer needs the sender reading
            pipe.send(block)

    def _publish(self, seq: int) -> None:
        self._published = seq + 1
        self.header[1] = seq + 1
        if self.header[2]:
            try:
                os.write(self.bell_w, b"\0")
            except BlockingIOError:     # the doorbell is full of rings already
                pass

    def _room(self, size: int) -> int:
        """Where a record of `size` bytes goes (after the last one, or at the start when it does not fit before
        the end), once a table slot is free and no block the sender may still read lies there."""
        pos = self._head if self._head + size <= self.capacity else 0
        while True:
            done = self.header[0]
            self._live = [b for b in self._live if b[0] >= done]
            if len(self._live) < self.max_blocks and not any(start < pos + size and pos < end
                                                             for _, start, end in self._live):
                break
            if os.getpid() != self.owner and os.getppid() != self.owner:    # the sender is gone: nobody will read
                raise BrokenPipeError("the sender has gone")
            time.sleep(_FULL_SLEEP_S)
        self._live.append((self._published, pos, pos + size))
        self._head = pos + size
        return pos


class BlockReceiver:
    """The sender's end. poll(0): whether the next block is there (a read of shared memory); recv(): take it
    (waiting if not); fileno(): a descriptor that becomes readable when a block comes while the sender waits for
    one (after poll(0) said no)."""

    def __init__(self, ring: Ring, connection):
        self.ring = ring
        self.connection = connection
        self.header = ring.header
        self.words = ring.data.cast("q")       # the offsets tables, indexed by position / 8
        self.taken = 0
        self.counts = {}
        self._armed = False

    def fileno(self) -> int:
        return self.ring.bell_r

    def poll(self, timeout=0) -> bool:
        header = self.header
        if header[1] > self.taken:
            if self._armed:
                self._disarm()
            return True
        if not self._armed:
            self._armed = True
            header[2] = 1
        if timeout:
            select.select((self.ring.bell_r,), (), (), timeout)
        return header[1] > self.taken

    def _disarm(self) -> None:
        self._armed = False
        self.header[2] = 0
        try:
            os.read(self.ring.bell_r, 4096)
        except BlockingIOError:
            pass

    def recv(self):
        while not self.poll(0):
            self.poll(_WAIT_S)
        ring = self.ring
        table = ring.table
        slot = (self.taken % ring.max_blocks) * _SLOT
        # Taking block t: the sender holds at most t - 1 besides (see the module's docstring).
        self.taken += 1
        if self.taken >= 2:
            self.header[0] = self.taken - 2
        if table[slot + 2]:
            block = self.connection.recv()
            if getattr(block, "items", None) is not None:
                self.counts = block.counts
            return block
        words, data = self.words, ring.data
        if table[slot + 3] == 1 and table[slot + _HEAD] == _PACKETS:      # one stream of packets: the usual case
            at = slot + _HEAD
            return RingBlock(table[slot], table[slot + 1], [RingPackets(words, data, table[at + 1], table[at + 2])],
                             [table[at + 3]], self.counts)
        items, saturated = [], []
        for at in range(slot + _HEAD, slot + _HEAD + _PER * table[slot + 3], _PER):
            if table[at] == _PACKETS:
                items.append(RingPackets(words, data, table[at + 1], table[at + 2]))
            else:
                items.append(_samples(data, table[at + 1], table[at + 2], table[at + 4], table[at + 5]))
            saturated.append(table[at + 3])
        return RingBlock(table[slot], table[slot + 1], items, saturated, self.counts)

    def close(self) -> None:
        self.connection.close()
        os.close(self.ring.bell_r)
        os.close(self.ring.bell_w)


class PipeReceiver:
    """The sender's end where there is no ring (see SHARED_RING): the pipe alone, with BlockReceiver's methods."""

    def __init__(self, connection):
        self.connection = connection

    def fileno(self) -> int:
        return self.connection.fileno()

    def poll(self, timeout=0) -> bool:
        # select() on the descriptor, not Connection.poll: that builds a selector per call (14 us against 0.75 us).
        return bool(select.select((self.connection.fileno(),), (), (), timeout)[0])

    def recv(self):
        return self.connection.recv()

    def close(self) -> None:
        self.connection.close()


def _samples(data: memoryview, pos: int, n: int, mask: int, start_ns: int) -> Samples:
    """A device's samples read from the ring, copied out (a device may keep them past the block). Built without
    Samples' checks: the producer's Samples had passed them, and the fields are as it had them.

    The record is copied once and each field is a view of that copy: a frombuffer and a copy per field cost the
    sender 148-161 us of CPU a block with every field (32) and cold caches, as in the send loop, against 97-105 us
    (tools/bench_catch_up.py); a block is taken inside a 100 us period at 10 kHz."""
    layout = _LAYOUTS.get((n, mask))
    if layout is None:
        layout = _layout(n, mask)
    record = np.frombuffer(data, np.float64, layout[0], pos).copy()
    samples = object.__new__(Samples)
    fields = samples.__dict__
    fields.update(_NO_FIELDS)
    fields["time_ns"] = record[:n].view(np.int64)
    fields["start_ns"] = start_ns
    for name, span, shape in layout[1]:
        fields[name] = record[span] if shape is None else record[span].reshape(shape)
    return samples


_LAYOUTS: dict = {}


def _layout(n: int, mask: int) -> tuple:
    """(float64 words in the record, (field, slice of the record, shape or None) for each field in the mask)."""
    at, fields = n, []
    for bit, (name, width) in enumerate(_SAMPLE_FIELDS):
        if mask >> bit & 1:
            count = n * (width or 1)
            fields.append((name, slice(at, at + count), (n, width) if width else None))
            at += count
    if len(_LAYOUTS) >= 64:     # block lengths vary only at a run's end; a bound all the same
        _LAYOUTS.clear()
    _LAYOUTS[n, mask] = layout = (at, tuple(fields))
    return layout


def _record_size(item) -> int | None:
    """Bytes an item takes in the ring (a multiple of _ALIGN); None: it crosses the pipe (a list of CAN frames;
    samples with attributes of their own)."""
    if type(item) is Packets:
        size = len(item.offsets) * 8 + len(item.data)
    elif type(item) is Samples and _plain(item):
        size = item.time_ns.nbytes + sum(getattr(item, name).nbytes for name in _FIELD_WIDTHS
                                         if getattr(item, name) is not None)
    else:
        return None
    return -(-size // _ALIGN) * _ALIGN


_SAMPLE_KEYS = {"time_ns", "start_ns", *_FIELD_WIDTHS}


def _plain(samples: Samples) -> bool:
    """Samples the ring carries: its fields only, each of the dtype and shape Samples' checks give it (a field set
    later might not have them; one that is a view, as quat, is copied into the ring in order)."""
    n = len(samples.time_ns)
    if samples.__dict__.keys() != _SAMPLE_KEYS or type(samples.start_ns) is not int:
        return False
    if samples.time_ns.dtype != np.int64 or samples.time_ns.ndim != 1:
        return False
    for name, width in _SAMPLE_FIELDS:
        value = getattr(samples, name)
        if value is not None and (value.dtype != np.float64 or value.shape != ((n, width) if width else (n,))):
            return False
    return True


def _int64s(values) -> memoryview:
    return memoryview((ctypes.c_int64 * len(values))(*values)).cast("B").cast("q")
