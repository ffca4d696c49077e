"""What every target offers the streaming loop, and the options a target spec cannot carry."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TargetOptions:
    """Settings that belong to the link rather than to the wire format."""

    link: str | None = None            # pty: stable symlink to the slave path
    pace_baud: int | None = None       # pty: deliver no faster than a UART at this baud would
    bitrate: int | None = None         # CAN nominal bit rate (budget; passed to interfaces that set it)
    data_bitrate: int | None = None    # CAN FD data phase bit rate
    fd: bool = False                   # open the CAN bus in FD mode
    blocking: bool = False             # --speed 0: wait for the link instead of dropping


@dataclass(frozen=True)
class LinkCapacity:
    """What a real link of this kind could carry; None = no limit the emulator should enforce."""

    bytes_per_s: float | None = None        # serial: baud / 10 (8N1)
    bits_per_s: float | None = None         # CAN nominal bit rate
    data_bits_per_s: float | None = None    # CAN FD data phase


class Transport:
    """One open target, two-way like python-can's `BusABC` (`send`, `recv`, `fileno`).

    `send` takes everything belonging to ONE sample (as made by `prepare`), or one reply, and either sends
    all of it or drops all of it (returns False), so a receiver never sees half a packet or half a transfer.
    `recv` never blocks: what the other end wrote since the last call (bytes for byte streams, a list of
    `can.Message` for buses), empty when nothing came. `fileno` is a descriptor that becomes readable
    when `recv` has something, or None when the link has none to offer (then it is polled at each
    deadline instead).
    """

    def prepare(self, payload, time_ns: int):
        """Turn one sample's CAN_FRAME_DTYPE rows into what `send` takes (serial packets go as bytes).
        Runs in the producer process, ahead of time, so the send loop does as little as possible."""
        return payload

    def send(self, item) -> bool:  # pragma: no cover - interface
        raise NotImplementedError

    def recv(self):
        """What arrived since the last call; this default is a one-way link (capture files)."""
        return b""

    def fileno(self) -> int | None:
        return None

    def set_baud(self, baud: int) -> bool:
        """Follow a baud-rate change the device agreed to; False when the link has no baud rate to follow."""
        return False

    def describe(self) -> str:  # pragma: no cover - interface
        raise NotImplementedError

    def close(self) -> None:
        pass
