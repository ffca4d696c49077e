"""What every target offers the streaming loop, and the options a target spec cannot carry."""
from __future__ import annotations

import errno
import fcntl
import struct
import termios
from collections import Counter
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

    # Whether the link is a byte stream whose reader sees the same bytes whether the samples' packets are written
    # one by one or joined in one write (a pty, a serial port, a raw capture file; not datagrams or CAN frames).
    joins_writes = False

    def send_many(self, items: list) -> int:
        """Several samples' items at once, in order (a stream behind its deadlines catching up): on a byte stream
        one write, sent or dropped whole like one packet, so catching up costs one system call rather than one per
        sample; elsewhere one `send` each. Returns how many were sent (the others were dropped)."""
        if self.joins_writes:
            return len(items) if self.send(b"".join(items)) else 0
        return sum(map(self.send, items))

    # Whether input comes in datagrams, each whole (then `recv_datagrams` gives them one by one).
    datagrams = False

    def recv(self):
        """What arrived since the last call; this default is a one-way link (capture files)."""
        return b""

    def recv_datagrams(self) -> list:
        """What arrived since the last call, one item per datagram (links whose `datagrams` is True)."""
        data = self.recv()
        return [data] if len(data) else []

    def fileno(self) -> int | None:
        return None

    # The stream's sample period, s, set when the stream opens the link (a link that sets the pace uses it).
    sample_period_s: float | None = None
    # Sample periods from the unit's power-up to the run's start: fields counting since power-up (Samples.start_ns)
    # then read this many periods at scene time 0. 0 for a part (it counts from the run's start); a flight stack
    # that takes its clock from the sensor time stamps (PX4 SITL) gets 1, so the first stamp is not 0.
    power_up_lead_periods = 0
    # Whether the other end sets the pace (a flight stack's simulator interface): then the streaming loop calls
    # `await_turn` before each sample of this link.
    sets_pace = False

    def await_turn(self) -> None:
        """Before each sample: a link whose other end steps the simulation (lockstep) waits here until it asks
        for the next sample, and raises a TargetError naming its timeout when that never comes."""

    def set_baud(self, baud: int) -> bool:
        """Follow a baud-rate change the device agreed to; False when the link has no baud rate to follow."""
        return False

    def describe(self) -> str:  # pragma: no cover - interface
        raise NotImplementedError

    # What a `send` returning False met, by cause (errno names such as EAGAIN or ENOBUFS, or what the link
    # says): a subclass counts into it with count_refusal. Class-level empty default for links that never refuse.
    send_errors: Counter = Counter()

    def count_refusal(self, cause: str) -> None:
        if "send_errors" not in self.__dict__:
            self.send_errors = Counter()
        self.send_errors[cause] += 1

    def queued(self) -> int | None:
        """Bytes the link holds that the other end has not taken yet, when the kernel says (None otherwise)."""
        return None

    def publish(self) -> None:
        """Once the stream is ready to answer: make the target visible under the name a driver opens (a pty's
        --link). Nothing for links whose name exists from the start."""

    def finish(self) -> None:
        """At the end of a run, before link_report and close: let the other end take what was sent (bounded)."""

    def link_report(self) -> dict:
        """What the link itself reports, beside the emulator's own sent/dropped counts: refusals by cause
        and what a subclass can read from the kernel (queues, interface counters)."""
        return {"send_errors": dict(self.send_errors)} if self.send_errors else {}

    def close(self) -> None:
        pass


def error_name(exc: BaseException) -> str:
    """ENOBUFS, EAGAIN, ... for an OSError or a python-can error carrying an errno; the type otherwise."""
    code = getattr(exc, "errno", None)
    if not isinstance(code, int):
        code = getattr(exc, "error_code", None)
    if isinstance(code, int):
        return errno.errorcode.get(code, f"errno {code}")
    return type(exc).__name__


def output_queue(fd: int, request: int = termios.TIOCOUTQ) -> int | None:
    """SIOCOUTQ (= TIOCOUTQ): bytes a socket has not sent yet, or a tty has not transmitted (FIONREAD: bytes
    waiting to be read); None if refused."""
    try:
        return struct.unpack("i", fcntl.ioctl(fd, request, b"\0" * 4))[0]
    except OSError:
        return None
