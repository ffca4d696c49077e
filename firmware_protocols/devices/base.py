"""What every emulated device shares: the conversation half of a format.

A device is a state machine behind one link. It consumes what the driver writes (`receive`: bytes from a
byte stream, or CAN frames), returns the replies the real part would send, and owns the active output
configuration (which messages and fields, rate divider, paused or streaming, mode). `output(samples, i)`
is everything the device puts on the link for sample i under the configuration in force at that moment, so
a command takes effect at the next sample the link carries. Periodic announcements (MAVLink HEARTBEAT,
DroneCAN NodeStatus) ride on `output` too, counted in samples, so they keep the sample clock's rhythm.

Devices know nothing of scenes: they see `Samples` (SI units, sensor frame) like the encoders.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from firmware_protocols import attitude
from firmware_protocols.base import Samples


@dataclass
class DeviceStats:
    """What the device made of its input; every command lands in exactly one of these counters."""

    commands: int = 0         # well-formed commands answered with an acknowledgement / the data asked for
    errors: int = 0           # commands answered with an error (bad checksum, unknown register, bad value)
    ignored_bytes: int = 0    # input that was no command at all (noise, other protocols' traffic)
    replies: int = 0          # replies produced (a command may produce several)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class LinkRequest:
    """A change of the link itself the device agreed to (sent after the reply that announced it)."""

    baud: int | None = None


class Device:
    """Base of the per-format devices. Subclasses implement `_receive` and `output`."""

    kind = "serial"           # "serial": bytes in, bytes out; "can": frames in, frame rows out

    def __init__(self, rate_hz: float):
        if not rate_hz > 0:
            raise ValueError(f"rate_hz: must be positive, got {rate_hz}")
        self.rate_hz = float(rate_hz)
        self.stats = DeviceStats()
        self.link_requests: list[LinkRequest] = []
        self.notes: list[str] = []     # things the user should hear about (lost address claim, ...)

    # - input -
    def receive(self, data, now_ns: int = 0, whole: bool = False) -> list:
        """Feed what the driver wrote; returns the replies in order (bytes, or CAN frame row arrays).

        `whole`: the data is one complete datagram (UDP). A frame it leaves unfinished will never be finished,
        so it is dropped and counted instead of swallowing the start of the next datagram's commands."""
        replies = self._receive(data, now_ns)
        if whole:
            self.stats.ignored_bytes += self._drop_partial()
        self.stats.replies += len(replies)
        return replies

    def _drop_partial(self) -> int:
        """Forget input kept for a frame still arriving; how many bytes that was (devices that keep some)."""
        return 0

    def _receive(self, data, now_ns: int) -> list:  # pragma: no cover - interface
        raise NotImplementedError

    # - output -
    def output(self, samples: Samples, i: int):  # pragma: no cover - interface
        """Everything sent for sample i of `samples` (b"" / an empty frame array when nothing is due)."""
        raise NotImplementedError

    def output_many(self, samples: Samples, i: int, k: int) -> list:
        """What `output` gives for samples i to k - 1 one after the other, in a list: a sender catching up after a
        stall asks for the samples already due at once, and a device may encode them in one call. This default
        asks `output` for each."""
        return [self.output(samples, m) for m in range(i, k)]

    def prepare(self, samples: Samples, i: int) -> None:
        """The sender has time to spare before sample i is due: do now what `output` would do for it and may do
        early, undone if what is due changes before (a device that encodes several samples at once). This default
        has nothing to do early."""

    def warm_up(self, samples: Samples) -> None:
        """Compile now what a driver's configuration command could make the device compile later: the streamer
        calls it on a throwaway device before the first deadline. A reply delayed by a compile (seconds on a cold
        cache) reaches a driver after its timeout, and its resend is then answered twice (issue 23, item 7).
        This default has nothing beyond `output`, which the streamer runs anyway."""

    def encoders(self):
        """The encoders whose saturation counts this device reports (one `encoder` unless overridden)."""
        encoder = getattr(self, "encoder", None)
        return [] if encoder is None else [encoder]

    @property
    def saturated(self) -> int:
        return sum(e.saturated.total for e in self.encoders())

    def take_link_requests(self) -> list[LinkRequest]:
        requests, self.link_requests = self.link_requests, []
        return requests

    def take_notes(self) -> list[str]:
        notes, self.notes = self.notes, []
        return notes


_SAMPLE_FIELDS = tuple(f.name for f in dataclasses.fields(Samples) if f.name != "start_ns")   # the arrays


def preset_settings(presets: dict, preset: str, fields_given: bool) -> dict:
    """The settings of a named preset ({name: (settings, text)}), refusing an unknown name, or a preset given
    together with explicit fields (they would contradict each other), with a one-line ValueError."""
    if preset not in presets:
        raise ValueError(f"preset: unknown {preset!r} (known: {', '.join(presets)})")
    if fields_given:
        raise ValueError("preset and fields: give one or the other")
    return presets[preset][0]


def single(samples: Samples, i: int) -> Samples:
    """Sample i as a block of one (views, no copies), for encoders that take blocks."""
    return view(samples, i, i + 1)


def view(samples: Samples, i: int, k: int) -> Samples:
    """Samples i to k - 1 as a block (views, no copies). The block's arrays are already contiguous float64
    (Samples.__post_init__ saw to it), so their row slices are too and the checks are skipped: half the cost of
    Samples.slice, which the sender pays per sample (single) or per catch-up (Device.output_many)."""
    rows = Samples.__new__(Samples)
    for name in _SAMPLE_FIELDS:
        value = getattr(samples, name)
        setattr(rows, name, None if value is None else value[i:k])
    rows.start_ns = samples.start_ns
    return rows


class SinceLastOutput:
    """The integrated outputs since the device last sent them. Real parts reset their integrals at each output
    that carries them (VectorNav's DeltaTheta/DeltaVel description; Xsens DeltaQ/DeltaV and MIP delta
    fields alike), so with an output divider a packet's increments span every sample since the previous one,
    paused time included: Δθ and Δv summed, the attitude change multiplied in order (q(t_a)^-1 q(t_c) =
    [q(t_a)^-1 q(t_b)] [q(t_b)^-1 q(t_c)]). Nothing happens when the samples carry no increments."""

    __slots__ = ("theta", "velocity", "time_s", "change")

    def __init__(self):
        self.theta = self.velocity = self.time_s = self.change = None

    def add(self, samples: Samples, i: int, increments=None) -> None:
        """Sample i's interval; `increments` (Δθ, Δv) replaces the sample's own (a device that re-expresses
        them, e.g. VectorNav's NED integration frame, before summing)."""
        if samples.delta_theta is None:
            return
        theta, velocity = increments if increments is not None else (samples.delta_theta[i],
                                                                      samples.delta_velocity[i])
        period = 0.0 if samples.delta_time_s is None else float(samples.delta_time_s[i])
        change = None if samples.attitude_change is None else samples.attitude_change[i]
        if self.theta is None:
            self.theta, self.velocity = np.array(theta, dtype=float), np.array(velocity, dtype=float)
            self.time_s, self.change = period, None if change is None else change.copy()
        else:
            self.theta += theta
            self.velocity += velocity
            self.time_s += period
            if change is not None and self.change is not None:
                self.change = attitude.multiply(self.change, change)

    def attach(self, one: Samples) -> Samples:
        """`one` (a sample alone) carrying the sums so far instead of its own interval's."""
        if self.theta is not None and one.delta_theta is not None:
            one.delta_theta, one.delta_velocity = self.theta[None, :].copy(), self.velocity[None, :].copy()
            if one.delta_time_s is not None:
                one.delta_time_s = np.array([self.time_s])
            if self.change is not None and one.attitude_change is not None:
                one.attitude_change = self.change[None, :].copy()
        return one

    def sent(self, encoder) -> None:
        """Start over when the packet just encoded carried increments."""
        if getattr(encoder, "uses_increments", False):
            self.theta = self.velocity = self.time_s = self.change = None


class Divider:
    """Every `divider`-th sample, counted from the moment the divider was set: rate = sample rate / divider.
    divider 0 means off."""

    __slots__ = ("divider", "count")

    def __init__(self, divider: int = 1):
        self.set(divider)

    def set(self, divider: int) -> None:
        self.divider = int(divider)
        self.count = 0

    def due(self) -> bool:
        if self.divider <= 0:
            return False
        due = self.count == 0
        self.count = (self.count + 1) % self.divider
        return due


@dataclass
class Periodic:
    """A message every `period_s` seconds of sample time (HEARTBEAT, NodeStatus), first one at once."""

    period_samples: int
    count: int = field(default=0)

    @classmethod
    def every(cls, period_s: float, rate_hz: float) -> "Periodic":
        return cls(max(1, int(round(period_s * rate_hz))))

    def due(self) -> bool:
        due = self.count == 0
        self.count = (self.count + 1) % self.period_samples
        return due
