"""A virtual SLCAN adapter: CAN frames as SLCAN text lines on a pty, read by e.g. python-can's `slcan`.

The emulator plays the adapter side, so it writes lines an adapter sends for received frames
(T/t/D/d/B/b lines, identical to the transmit commands of the Lawicel protocol).
"""
from __future__ import annotations

from firmware_protocols.base import FD_LENGTHS
from imu_emulator.live.transport.base import TargetOptions
from imu_emulator.live.transport.pty import PtyTransport


def slcan_lines(rows, bitrate_switch: bool = False) -> bytes:
    lines = []
    for r in rows:
        length = int(r["length"])
        data = r["data"][:length].tobytes().hex().upper()
        if r["fd"]:
            letter = ("B" if bitrate_switch else "D") if r["extended"] else ("b" if bitrate_switch else "d")
            dlc = f"{FD_LENGTHS.index(length):X}"     # the FD DLC: its position in ISO 11898-1's lengths
        else:
            letter, dlc = ("T" if r["extended"] else "t"), str(length)
        ident = f"{int(r['can_id']):08X}" if r["extended"] else f"{int(r['can_id']):03X}"
        lines.append(f"{letter}{ident}{dlc}{data}\r")
    return "".join(lines).encode("ascii")


def parse_slcan_line(line: bytes):
    """One transmit command of the Lawicel protocol (T/t, classic frames) -> can.Message; None for the
    adapter's other commands (O, C, S, V, ...) and for malformed lines."""
    try:
        text = line.decode("ascii")
        if text[:1] not in ("T", "t"):
            return None
        width = 8 if text[0] == "T" else 3
        can_id, length = int(text[1:1 + width], 16), int(text[1 + width], 16)
        data = bytes.fromhex(text[2 + width:2 + width + 2 * length])
    except (UnicodeDecodeError, ValueError, IndexError):
        return None
    if length > 8 or len(data) != length:
        return None
    import can      # here: python-can's import (its loggers, asyncio) would delay a stream's first frame
    return can.Message(arbitration_id=can_id, is_extended_id=width == 8, data=data)


class SlcanPtyTransport(PtyTransport):

    _MAX_LINE = 64

    def __init__(self, options: TargetOptions):
        super().__init__(options)
        self._brs = bool(options.data_bitrate)
        self._pending = b""

    def recv(self) -> list:
        """Frames the host's SLCAN driver asked the adapter to transmit (its setup commands are answered by
        nothing and dropped: python-can's slcan interface does not wait for answers)."""
        data = self._pending + super().recv()
        *lines, rest = data.split(b"\r")
        self._pending = rest[-self._MAX_LINE:]
        return [m for m in map(parse_slcan_line, lines) if m is not None]

    def prepare(self, payload, time_ns: int):
        # One write per sample: a full pty drops the sample's whole transfer, never half of it.
        return slcan_lines(payload, self._brs)

    def describe(self) -> str:
        return "slcan " + super().describe()
