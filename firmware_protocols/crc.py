"""Table-driven checksums used by the wire formats, compiled with numba so batch encoders can call
them per packet without leaving machine code.

- crc16_ccitt: poly 0x1021, not reflected, no final xor. init 0x0000 is CRC-16/XMODEM (VectorNav),
  init 0xFFFF is CRC-16/CCITT-FALSE (DroneCAN transfer CRC). One function serves both.
- crc16_mcrf4xx: poly 0x1021 reflected (0x8408), init 0xFFFF, no final xor (MAVLink's X.25 variant).
"""
from imu_emulator.native.lazy import jit
import numpy as np


def _table_ccitt() -> np.ndarray:
    table = np.zeros(256, dtype=np.uint16)
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
        table[byte] = crc & 0xFFFF
    return table


def _table_reflected() -> np.ndarray:
    table = np.zeros(256, dtype=np.uint16)
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc >> 1) ^ 0x8408) if crc & 1 else (crc >> 1)
        table[byte] = crc
    return table


CCITT_TABLE = _table_ccitt().astype(np.int64)  # int64: numba mixes uint16 with int into float
REFLECTED_TABLE = _table_reflected().astype(np.int64)


@jit(cache=True, nogil=True)
def crc16_ccitt(data, start, stop, crc):
    """CRC over data[start:stop] (uint8 array), continuing from `crc` (an int)."""
    table = CCITT_TABLE
    crc = np.int64(crc)
    for i in range(start, stop):
        crc = ((crc << 8) & 0xFFFF) ^ table[((crc >> 8) ^ data[i]) & 0xFF]
    return crc


@jit(cache=True, nogil=True)
def crc16_mcrf4xx(data, start, stop, crc):
    """MAVLink's CRC over data[start:stop] (uint8 array), continuing from `crc` (0xFFFF to start)."""
    table = REFLECTED_TABLE
    crc = np.int64(crc)
    for i in range(start, stop):
        crc = (crc >> 8) ^ table[(crc ^ data[i]) & 0xFF]
    return crc


def crc16_ccitt_bytes(data: bytes, init: int = 0) -> int:
    return int(crc16_ccitt(np.frombuffer(data, dtype=np.uint8), 0, len(data), init))


def crc16_mcrf4xx_bytes(data: bytes, init: int = 0xFFFF) -> int:
    return int(crc16_mcrf4xx(np.frombuffer(data, dtype=np.uint8), 0, len(data), init))
