"""A parsed target spec, and the record each kind of target declares (one module in kinds/ each)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from imu_emulator.errors import TargetError
from imu_emulator.live.transport.base import LinkCapacity, TargetOptions, Transport


@dataclass(frozen=True)
class TargetSpec:
    kind: str             # a key of TARGET_KINDS
    text: str             # as written, for messages
    path: str = ""        # device, CAN channel, host or file
    interface: str = ""   # python-can interface (can)
    port: int = 0         # udp; udp_multicast (0: python-can's default)
    rate: int | None = None   # baud (serial) or bit rate (can), when the spec names one
    params: tuple = ()        # (key, value) pairs after ',' (the flight-stack targets' record=, timeout=)


def no_capacity(spec: TargetSpec, format_kind: str, options: TargetOptions) -> LinkCapacity:
    """A link with no limit the emulator should enforce."""
    return LinkCapacity()


@dataclass(frozen=True)
class TargetKind:
    """What a kind of target declares. A module `kinds/<name>.py` defines `KIND = TargetKind(name=<name>, ...)`;
    the package finds it there, so the declaration stays light: `open` imports the transport module (python-can,
    pyserial) only when a target of this kind is opened, and `imu-emulator targets` imports none of them."""

    name: str            # the spec's prefix, before ':'
    order: int           # place in `imu-emulator targets` and in messages listing the kinds
    syntax: str          # e.g. "serial:DEVICE[@BAUD]"
    help: str            # what it is, one line
    carries: str         # the format kind it carries: "serial", "can" or "any"
    # (spec as written, what follows "NAME:") -> TargetSpec; a malformed spec raises TargetError naming the syntax
    parse: Callable[[str, str], TargetSpec]
    # (spec, format kind, options) -> the opened Transport
    open: Callable[[TargetSpec, str, TargetOptions], Transport]
    # (spec, format kind, options) -> what the link budget is checked against, known from the spec alone
    capacity: Callable[[TargetSpec, str, TargetOptions], LinkCapacity] = no_capacity
    takes_argument: bool = True     # False: the spec may be the bare name (pty)
    refusal_hint: str = ""          # appended when a format of the wrong kind is refused
    # False: the link cannot carry a driver's commands back, so a device there would only change what is
    # streamed and none is made
    talks_back: bool = True


def split_rate(text: str, body: str, what: str) -> tuple[str, int | None]:
    if "@" not in body:
        return body, None
    head, _, rate = body.rpartition("@")
    if not rate.isdigit() or int(rate) <= 0:
        raise TargetError(f"{text}: {what} after '@' must be a positive integer, got {rate!r}")
    return head, int(rate)
