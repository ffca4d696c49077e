"""What a stream needs of its link against what the link can carry: serial bytes, or CAN bits with worst-case
stuffing; and the one-line account of what the link itself reported at the end."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from firmware_protocols.base import can_bits_worst_case

if TYPE_CHECKING:
    from imu_emulator.live.stream import Stream


@dataclass(frozen=True)
class LinkBudget:
    """What a stream needs of its link: `load` is the fraction of the link's capacity (None: no limit known)."""
    need: str              # e.g. "15,000 B/s (75 B/sample)" or "1120 bits/sample (7 frames, ...) = 0.224 Mbit/s"
    capacity: str | None   # e.g. "11,520 B/s (baud/10)" or "1 Mbit/s bus"
    load: float | None


def link_budget(stream: "Stream", rate_hz: float) -> LinkBudget:
    """The stream's demand at rate_hz against its link's capacity (serial bytes, or CAN bits with worst-case
    stuffing)."""
    capacity, encoder = stream.capacity, stream.encoder
    if stream.info.kind == "serial":
        per_sample = getattr(encoder, "bytes_per_sample", stream.info.bytes_per_sample)
        need = per_sample * rate_hz
        text = f"{need:,.0f} B/s ({per_sample} B/sample)"
        if capacity.bytes_per_s is None:
            return LinkBudget(text, None, None)
        return LinkBudget(text, f"{capacity.bytes_per_s:,.0f} B/s (baud/10)", need / capacity.bytes_per_s)
    frames = getattr(encoder, "frames_per_sample", stream.info.frames_per_sample)
    bits = sum(can_bits_worst_case(length, extended, fd) for length, extended, fd in frames)
    text = (f"{bits} bits/sample ({len(frames)} frames, worst-case stuffing) = "
            f"{bits * rate_hz / 1e6:.3f} Mbit/s")
    if capacity.bits_per_s is None:
        return LinkBudget(text, None, None)
    seconds = 0.0
    for length, extended, fd in frames:
        total = can_bits_worst_case(length, extended, fd)
        if fd and capacity.data_bits_per_s:
            # Approximation: payload and CRC ride the data phase, the rest the nominal phase.
            data_bits = total - can_bits_worst_case(0, extended, fd)
            seconds += (total - data_bits) / capacity.bits_per_s + data_bits / capacity.data_bits_per_s
        else:
            seconds += total / capacity.bits_per_s
    return LinkBudget(text, f"{capacity.bits_per_s / 1e6:g} Mbit/s bus", seconds * rate_hz)


def link_budget_problem(stream: "Stream", rate_hz: float) -> str | None:
    """None when the stream fits its link at rate_hz, else a one-line message naming the numbers."""
    budget = link_budget(stream, rate_hz)
    if budget.load is None or budget.load <= 1.0:
        return None
    label = f"{stream.config.imu} {stream.config.format} at {rate_hz:g} Hz"
    if stream.info.kind == "serial":
        return (f"{label} needs {budget.need} but {stream.config.target} carries {budget.capacity}; "
                f"lower the rate, raise the baud or pass --allow-overload")
    return (f"{label} needs {budget.need}, {budget.load:.0%} of the {budget.capacity} of {stream.config.target}; "
            f"lower the rate, raise --bitrate or pass --allow-overload")


def link_text(link: dict) -> str:
    """One line of what the link reported: refusals by cause, interface counters that moved, queue."""
    parts = [f"{n} {cause}" for cause, n in sorted(link.get("send_errors", {}).items())]
    parts = ["send refused: " + ", ".join(parts)] if parts else ["no send refused"]
    moved = {name: n for name, n in link.get("interface", {}).items() if n}
    if "interface" in link:
        parts.append("interface " + (", ".join(f"{name} +{n}" for name, n in moved.items()) or "counters unchanged"))
    if link.get("counts"):     # what a link counts of its own (steps, reconnects, malformed input)
        parts.append(", ".join(f"{name} {n}" for name, n in link["counts"].items()))
    if "queue_max_bytes" in link:
        parts.append(f"queue up to {link['queue_max_bytes']} B")
    if link.get("unread_lost"):
        lost = link["unread_lost"]
        parts.append(f"{lost['packets']} packets ({lost['bytes']} B) sent but left unread, lost "
                     f"({lost['readers']} times a reader closed or stopped reading with packets unread)")
    return "; ".join(parts)
