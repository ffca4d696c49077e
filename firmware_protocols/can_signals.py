"""Pieces shared by the fixed-layout CAN signal formats (J1939, Bosch MM7): an explicit, configurable
mapping from sensor axes to wire quantities, and a table-driven packer that turns sample arrays into
8-byte CAN frames in one compiled call (scaling, rounding, saturation counting, counter, CRC-8)."""
from __future__ import annotations

from dataclasses import dataclass

from imu_emulator.native.lazy import jit
import numpy as np

from firmware_protocols.base import SaturationStats, empty_frames
from firmware_protocols.frame_rows import DATA_AT, frame_bytes, put_header

@dataclass(frozen=True)
class AxisMap:
    """Which sensor axis (0, 1, 2) and sign feeds each of three wire quantities, in wire order."""

    axes: tuple
    signs: tuple

    def __post_init__(self):
        axes = tuple(int(a) for a in self.axes)
        signs = tuple(float(s) for s in self.signs)
        if sorted(axes) != [0, 1, 2]:
            raise ValueError(f"axes must be a permutation of 0, 1, 2, got {self.axes}")
        if any(s not in (1.0, -1.0) for s in signs) or len(signs) != 3:
            raise ValueError(f"signs must be three of +1/-1, got {self.signs}")
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "signs", signs)

    def to_wire(self, vectors: np.ndarray) -> np.ndarray:
        """(n, 3) sensor-frame vectors -> (n, 3) wire quantities."""
        return vectors[:, list(self.axes)] * np.asarray(self.signs)

    def to_sensor(self, wire: np.ndarray) -> np.ndarray:
        """Inverse of to_wire for one (3,) vector."""
        out = np.empty(3)
        out[list(self.axes)] = np.asarray(wire, dtype=float) * np.asarray(self.signs)
        return out


def axis_map(value) -> AxisMap:
    """An AxisMap from an AxisMap or a (axes, signs) pair, so options can come from a scene file."""
    if isinstance(value, AxisMap):
        return value
    axes, signs = value
    return AxisMap(tuple(axes), tuple(signs))


@dataclass(frozen=True)
class Signal:
    """One unsigned little-endian signal: raw = round((sources[:, source] * factor - offset) / scale),
    saturated to [lo, hi] (and counted under `name`), written at `byte` of message `message`."""

    name: str
    message: int
    byte: int
    width: int          # bytes: 1 or 2
    source: int         # column of the sources matrix the encoder passes
    factor: float       # SI -> the signal's unit, times the axis sign
    scale: float        # signal unit per bit
    offset: float
    lo: int
    hi: int


def crc8_sae_j1850_table() -> np.ndarray:
    """Table of CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xorout 0xFF; check b"123456789" -> 0x4B)."""
    table = np.zeros(256, dtype=np.int64)
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table[byte] = crc
    return table


CRC8_J1850_TABLE = crc8_sae_j1850_table()


class SignalLayout:
    """Messages of one sample (ids, constant bytes) and the signals in them.

    counter_byte: byte whose low nibble carries a 4-bit counter, equal in all messages of a sample and
    stepping by one per sample (-1: none). crc8: last byte = CRC-8/SAE-J1850 over bytes 0-6.
    """

    def __init__(self, can_ids, extended: bool, template, signals: list[Signal], counter_byte: int = -1,
                 crc8: bool = False):
        self.can_ids = np.asarray(can_ids, dtype=np.int64)
        self.extended = bool(extended)
        self.template = np.asarray(template, dtype=np.int64).reshape(len(self.can_ids), 8)
        self.names = [sig.name for sig in signals]
        self.spec = np.array([[sig.message, sig.byte, sig.width, sig.source] for sig in signals], dtype=np.int64)
        self.values = np.array([[sig.factor, sig.scale, sig.offset, sig.lo, sig.hi] for sig in signals])
        self.counter_byte = int(counter_byte)
        self.crc8 = bool(crc8)
        self._flags = (int(self.extended), int(self.crc8))   # as the compiled packer takes them
        self._counts = np.zeros(len(signals), dtype=np.int64)

    @property
    def frames_per_sample(self) -> tuple:
        return ((8, self.extended, False),) * len(self.can_ids)

    def pack(self, sources: np.ndarray, counter: int, saturated: SaturationStats) -> np.ndarray:
        """sources: (n, k) float64, finite. Returns n * messages frames, sample-major."""
        frames = empty_frames(sources.shape[0] * len(self.can_ids))
        # flags as ints and the frames as bytes: plain arguments, which a warm run passes to machine code
        extended, crc8 = self._flags
        total = _pack(np.ascontiguousarray(sources, dtype=np.float64), self.spec, self.values, self.template,
                      self.can_ids, extended, counter, self.counter_byte, crc8, CRC8_J1850_TABLE,
                      frame_bytes(frames), self._counts)
        if total:
            for name, count in zip(self.names, self._counts):
                saturated.add(name, int(count))
        return frames


@jit(cache=True, nogil=True)
def _pack(sources, spec, values, template, can_ids, extended, counter, counter_byte, crc8, crc_table,
          frame_rows, counts):
    counts[:] = 0
    n = sources.shape[0]
    m = can_ids.shape[0]
    total = 0
    for i in range(n):
        base = i * m
        for k in range(m):
            f = base + k
            put_header(frame_rows, f, i, can_ids[k], extended, 0, 8)
            for b in range(8):
                frame_rows[f, DATA_AT + b] = template[k, b]
            if counter_byte >= 0:
                frame_rows[f, DATA_AT + counter_byte] = (template[k, counter_byte] & 0xF0) | ((counter + i) & 0xF)
        for r in range(spec.shape[0]):
            raw = np.rint((sources[i, spec[r, 3]] * values[r, 0] - values[r, 2]) / values[r, 1])
            if raw < values[r, 3]:
                raw = values[r, 3]
                counts[r] += 1
                total += 1
            elif raw > values[r, 4]:
                raw = values[r, 4]
                counts[r] += 1
                total += 1
            word = np.int64(raw)
            f = base + spec[r, 0]
            frame_rows[f, DATA_AT + spec[r, 1]] = word & 0xFF
            if spec[r, 2] == 2:
                frame_rows[f, DATA_AT + spec[r, 1] + 1] = (word >> 8) & 0xFF
        if crc8:
            for k in range(m):
                f = base + k
                crc = 0xFF
                for b in range(7):
                    crc = crc_table[crc ^ frame_rows[f, DATA_AT + b]]
                frame_rows[f, DATA_AT + 7] = crc ^ 0xFF
    return total
