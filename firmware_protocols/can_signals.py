"""Pieces shared by the fixed-layout CAN signal formats (J1939, Bosch MM7): an explicit, configurable
mapping from sensor axes to wire quantities, and packing of 8-byte payloads into CAN frame rows."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from firmware_protocols.base import empty_frames

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


def fixed_frames(payloads: np.ndarray, can_ids, extended: bool) -> np.ndarray:
    """(n, m, 8) payloads of m messages per sample -> CAN frames, sample-major, message order kept."""
    n, m, _ = payloads.shape
    frames = empty_frames(n * m)
    frames["sample"] = np.repeat(np.arange(n, dtype=np.int64), m)
    frames["can_id"] = np.tile(np.asarray(can_ids, dtype=np.uint32), n)
    frames["extended"] = extended
    frames["length"] = 8
    frames["data"][:, :8] = payloads.reshape(n * m, 8)
    return frames


def put_u16(payload: np.ndarray, byte: int, raw: np.ndarray) -> None:
    payload[:, byte] = raw & 0xFF
    payload[:, byte + 1] = raw >> 8
