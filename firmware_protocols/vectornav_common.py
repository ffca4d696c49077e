"""What VectorNav's two wire formats (firmware_protocols.wire_formats.vectornav_binary and .vectornav_ascii) and
its device (firmware_protocols.devices.vectornav) share: the defaults for optional Samples fields, degrees per
radian, and the ASCII framing `$body*CS\r\n` with its two checksum kinds, which the device's command replies use
in either output mode. Not a format itself, so it sits beside the wire_formats package that the registry scans.
"""
from __future__ import annotations

import numpy as np

from firmware_protocols.crc import crc16_ccitt_bytes

DEG = 180.0 / np.pi

# Documented defaults for optional Samples fields a selected wire field needs (one row, broadcast).
SAMPLE_DEFAULTS = {
    "mag": (0.0, 0.0, 0.0),
    "quat": (1.0, 0.0, 0.0, 0.0),
    "euler": (0.0, 0.0, 0.0),
    "temperature_c": (25.0,),
    "pressure_pa": (101325.0,),
}


def xor8(body: bytes) -> int:
    """The 8-bit XOR of all bytes (in C: a Python loop costs microseconds per sentence)."""
    return int(np.bitwise_xor.reduce(np.frombuffer(body, dtype=np.uint8))) if body else 0


def checksum_text(body: bytes, kind: str) -> bytes:
    """What follows '*': the 8-bit XOR of `body` as 2 hex digits, or its CRC-16/XMODEM as 4."""
    if kind == "xor":
        return b"%02X" % xor8(body)
    return b"%04X" % crc16_ccitt_bytes(body)


def sentence(body: bytes, kind: str = "xor") -> bytes:
    """`$body*CS\\r\\n`."""
    return b"$" + body + b"*" + checksum_text(body, kind) + b"\r\n"


def verify_line(line: bytes):
    """`$body*CS` (line ending stripped) -> body if CS is a valid XOR (2 hex) or CRC (4 hex), else None."""
    if not line.startswith(b"$") or line.count(b"*") != 1:
        return None
    body, _, cs = line[1:].partition(b"*")
    try:
        value = int(cs, 16)
    except ValueError:
        return None
    if len(cs) == 2 and value == xor8(body):
        return body
    if len(cs) == 4 and value == crc16_ccitt_bytes(body):
        return body
    return None
