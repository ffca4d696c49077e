"""A virtual SLCAN adapter: CAN frames as SLCAN text lines on a pty, read by e.g. python-can's `slcan`.

The emulator plays the adapter side, so it writes lines an adapter sends for received frames
(T/t/D/d/B/b lines, identical to the transmit commands of the Lawicel protocol).
"""
from __future__ import annotations

from can.util import len2dlc

from imu_emulator.transport.base import TargetOptions
from imu_emulator.transport.pty import PtyTransport


def slcan_lines(rows, bitrate_switch: bool = False) -> bytes:
    lines = []
    for r in rows:
        length = int(r["length"])
        data = r["data"][:length].tobytes().hex().upper()
        if r["fd"]:
            letter = ("B" if bitrate_switch else "D") if r["extended"] else ("b" if bitrate_switch else "d")
            dlc = f"{len2dlc(length):X}"
        else:
            letter, dlc = ("T" if r["extended"] else "t"), str(length)
        ident = f"{int(r['can_id']):08X}" if r["extended"] else f"{int(r['can_id']):03X}"
        lines.append(f"{letter}{ident}{dlc}{data}\r")
    return "".join(lines).encode("ascii")


class SlcanPtyTransport(PtyTransport):

    def __init__(self, options: TargetOptions):
        super().__init__(options)
        self._brs = bool(options.data_bitrate)

    def prepare(self, payload, time_ns: int):
        # One write per sample: a full pty drops the sample's whole transfer, never half of it.
        return slcan_lines(payload, self._brs)

    def describe(self) -> str:
        return "slcan " + super().describe()
