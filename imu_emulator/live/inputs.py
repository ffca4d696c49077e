"""The links' incoming side while streaming: a driver's commands go to the stream's device and its replies out
between two deadlines; input on a link without a device is read and counted."""
from __future__ import annotations

import select
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from imu_emulator.live.stream import Stream


# Links without a descriptor (polled) and the producer's blocks are looked at this often while the sender waits
# for the producer.
_UNWATCHED_POLL_S = 0.001


class Inputs:
    """The links' incoming side: which descriptors to watch, and what to do with what arrives. Bytes or
    frames go to the stream's device and its replies out at once; a link without a device has its input
    read and counted (so the writer never blocks) and otherwise ignored."""

    def __init__(self, streams: list[Stream], note):
        self.note = note
        self.by_fd = {}
        self.unwatched = []
        for stream in streams:
            fd = stream.transport.fileno()
            if fd is None:
                self.unwatched.append(stream)
            else:
                self.by_fd.setdefault(fd, []).append(stream)
        self.fds = list(self.by_fd)
        self.served_ns = 0          # when input was last served (monotonic): a deadline missed meanwhile is its
        self.block_waited = False   # next_block found the producer's block not there yet
        # Unwatched links that can talk are polled at each deadline; one-way ones not at all.
        self.unwatched = [s for s in self.unwatched if s.device is not None]

    def ready(self, fds) -> bool:
        """Serve the streams on these descriptors; whether any of them had input."""
        found = False
        for fd in fds:
            for stream in self.by_fd[fd]:
                found = self.serve(stream) or found
        return found

    def poll_unwatched(self) -> None:
        for stream in self.unwatched:
            self.serve(stream)

    def poll_all(self) -> None:
        if self.fds:
            ready, _, _ = select.select(self.fds, (), (), 0)
            self.ready(ready)
        self.poll_unwatched()

    def next_block(self, blocks):
        """The producer's next block (`blocks`: the pipe's receiving Connection), the links served while it is
        not there yet: a driver's command never waits for the simulation (at start-up, or when the producer falls
        behind under load), so it is answered within the period it arrived in (issue 23 item 7: replies later
        than a driver's timeout turn into wrong values in VectorNav's library)."""
        # Whether the block was not there yet (the miss classification reads it): a read of shared memory
        # (ring.BlockReceiver) or one select() on the pipe, once per block.
        self.block_waited = waited = not blocks.poll(0)
        if not waited or not (self.fds or self.unwatched):
            return blocks.recv()
        bell = blocks.fileno()
        watched = [bell] + self.fds
        while not blocks.poll(0):
            # A timeout even with nothing polled: the ring's doorbell may be missed (see ring.py).
            ready, _, _ = select.select(watched, (), (), _UNWATCHED_POLL_S)
            for fd in ready:
                if fd != bell and not self.ready([fd]):
                    # Readable with nothing to read: a hang-up (a pty nobody has open). Not watched until the block.
                    watched.remove(fd)
            self.poll_unwatched()
        return blocks.recv()

    def serve(self, stream: Stream) -> bool:
        transport = stream.transport
        whole = transport.datagrams
        units = transport.recv_datagrams() if whole else [transport.recv()]
        if not any(len(data) for data in units):
            return False
        device = stream.device
        if device is None:
            stream.ignored_input += sum(len(data) for data in units)
            self.served_ns = time.monotonic_ns()
            return True
        for data in units:
            for reply in device.receive(data, time.monotonic_ns(), whole=whole):
                stream.send_reply(reply if stream.info.kind == "serial" else transport.prepare(reply, 0))
        for request in device.take_link_requests():
            if request.baud:
                followed = transport.set_baud(request.baud)
                self.note(f"{stream.config.format}: baud rate {request.baud} "
                          + ("followed" if followed else "acknowledged (this link has no baud rate to follow)"))
        for text in device.take_notes():
            self.note(f"{stream.config.format}: {text}")
        self.served_ns = time.monotonic_ns()
        return True
