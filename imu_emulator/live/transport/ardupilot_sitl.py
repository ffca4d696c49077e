"""ArduPilot SITL's JSON physics backend: the emulator is the physics, on UDP 9002.

The other side, as ArduPilot/ardupilot libraries/SITL/SIM_JSON.cpp (commit 2ebd1127ac11b2a2b02dfabeb9f9e9318170af46)
and SIM_JSON.h (commit 0394cbc9084433e45d6bc2a8c234d6c265931d39) have it: JSON::update() sends one servo packet to
the simulator's port (control_port 9002 at target_ip, 127.0.0.1 unless `-f JSON:ADDRESS`), then recv_fdm() waits
for the reply line, resending the same servo packet (same frame_count) after each second without one; frame_count
counts the lines parsed, so it repeats on a resend and starts again at 0 when SITL restarts. The packet:

    struct servo_packet { uint16 magic = 18458; uint16 frame_rate; uint32 frame_count; uint16 pwm[16]; }   40 bytes

and the 32-channel variant of newer SITL, magic 29569 with pwm[32] (72 bytes). Little-endian (x86/ARM SITL).

Lockstep (--speed 0): exactly one sample (one line of the ardupilot-json format) per valid servo packet, sent
back to the address it came from; none for `timeout` s once SITL has spoken is a LockstepTimeout naming it
(before that, the stream waits for SITL as long as it takes). Wall clock (--speed > 0): a sample at each of the
scene's deadlines to the last address heard from, servo packets read and recorded as they come. A malformed packet
(size or magic) is counted and announced, never answered; the stream keeps its state. A resend is counted and
answered with the next sample (SITL did not get the last one; resends already queued behind a packet share its
answer), a frame_count going back is announced as SITL
restarting; the emulator's clock carries on (SITL calls a step back in time "physics reset", forward is fine).
The servo outputs are recorded (record=PATH, CSV), never obeyed: the scene's motion is scripted.
"""
from __future__ import annotations

import select
import socket
import struct
import time

from imu_emulator.live.transport.base import TargetOptions, Transport, error_name
from imu_emulator.live.transport.spec import TargetSpec
from imu_emulator.live.transport.stack_link import (ActuatorRecord, LockstepTimeout, bind, note, record_path,
                                                   timeout_of)

# magic -> pwm channels
SERVO_MAGIC = {18458: 16, 29569: 32}
_HEADER = struct.Struct("<HHI")
_COLUMNS = ["sample", "frame_rate", "frame_count"] + [f"pwm{i + 1}" for i in range(32)]


def parse_servo_packet(data: bytes):
    """(frame_rate, frame_count, pwm tuple) of a servo packet, or None when its size or magic is not SIM_JSON's."""
    if len(data) < _HEADER.size:
        return None
    magic, frame_rate, frame_count = _HEADER.unpack_from(data)
    channels = SERVO_MAGIC.get(magic)
    if channels is None or len(data) != _HEADER.size + 2 * channels:
        return None
    return frame_rate, frame_count, struct.unpack_from(f"<{channels}H", data, _HEADER.size)


class ArduPilotJsonTransport(Transport):
    sets_pace = True

    def __init__(self, spec: TargetSpec, options: TargetOptions):
        self.host, self.port = spec.path, spec.port
        self.lockstep = options.blocking
        self.timeout = timeout_of(spec)
        self.sock = bind("ardupilot", self.host, self.port, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.record = ActuatorRecord(record_path(spec), _COLUMNS, spec.text)
        self.peer = None
        self.last_frame_count = None
        self.samples_sent = 0
        self.servo_packets = self.malformed = self.resends = self.restarts = 0
        self._rate_noted = False

    def _take(self, data: bytes, peer) -> bool:
        """One datagram; whether it was a servo packet (then it asks for one sample)."""
        parsed = parse_servo_packet(data)
        if parsed is None:
            self.malformed += 1
            if self.malformed & (self.malformed - 1) == 0:     # the 1st, 2nd, 4th, 8th ...: a flood stays readable
                magic = f", magic {int.from_bytes(data[:2], 'little')}" if len(data) >= 2 else ""
                note(f"ardupilot: malformed servo packet from {peer[0]}:{peer[1]} ({len(data)} bytes{magic}): "
                     "ignored, not answered (SIM_JSON sends 40 bytes with magic 18458, or 72 with 29569); "
                     f"{self.malformed} so far")
            return False
        frame_rate, frame_count, pwm = parsed
        if peer != self.peer:
            note(f"ardupilot: ArduPilot SITL {'now ' if self.peer else ''}at {peer[0]}:{peer[1]}"
                 + (" (lockstep: one sample per servo packet)" if self.lockstep else ""))
            self.peer = peer
        if self.last_frame_count is not None and frame_count < self.last_frame_count:
            self.restarts += 1
            note(f"ardupilot: SITL restarted (frame_count {frame_count} after {self.last_frame_count}); the "
                 f"stream carries on at sample {self.samples_sent}")
        elif frame_count == self.last_frame_count:
            self.resends += 1     # SITL resent: it did not get our last line in time
        self.last_frame_count = frame_count
        if not self._rate_noted and self.sample_period_s and abs(frame_rate * self.sample_period_s - 1) > 0.01:
            self._rate_noted = True
            note(f"ardupilot: SITL asks for {frame_rate} Hz, the scene runs at {1 / self.sample_period_s:g} Hz: "
                 "SITL follows the time stamps it is sent")
        self.servo_packets += 1
        self.record.add([self.samples_sent, frame_rate, frame_count, *pwm])
        return True

    def _receive(self) -> bool:
        """One datagram if there is one; whether it was a servo packet."""
        try:
            data, peer = self.sock.recvfrom(65536)
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:
            return False       # an ICMP error for an earlier reply (SITL gone): it will speak again or time out
        return self._take(data, peer)

    def _pending(self) -> bool:
        """Whether a datagram is waiting (a malformed one makes _receive False without ending the queue)."""
        ready, _, _ = select.select([self.sock], (), (), 0)
        return bool(ready)

    def await_turn(self) -> None:
        if not self.lockstep:
            while True:
                try:
                    data, peer = self.sock.recvfrom(65536)
                except OSError:
                    return
                self._take(data, peer)
        if self.peer is None:
            note(f"ardupilot: waiting for ArduPilot SITL's servo packets on {self.host}:{self.port}")
        now = time.monotonic_ns()
        deadline = now + int(self.timeout * 1e9)
        while True:
            wait = None if self.peer is None else (deadline - now) / 1e9
            if wait is not None and wait <= 0:
                raise LockstepTimeout(f"ardupilot: lockstep timeout: no servo packet from ArduPilot SITL for "
                                      f"{self.timeout:g} s after sample {self.samples_sent} (timeout= in the target "
                                      "sets the limit)")
            ready, _, _ = select.select([self.sock], (), (), wait)
            if ready and self._receive():
                # Packets queued behind it are resends of the same step (SITL sends one per step, then waits, and
                # repeats it each second without an answer: while the emulator started, say). One line answers
                # them all: a line per packet would leave SITL reading a stale line at every step from then on.
                while self._receive() or self._pending():
                    pass
                return
            now = time.monotonic_ns()

    def send(self, payload: bytes) -> bool:
        if self.peer is None:
            self.count_refusal("no SITL heard from yet")
            return False
        try:
            self.sock.sendto(payload, self.peer)
        except OSError as exc:
            self.count_refusal(error_name(exc))
            return False
        self.samples_sent += 1
        return True

    def describe(self) -> str:
        return (f"ardupilot json udp {self.host}:{self.port} ({'lockstep' if self.lockstep else 'wall clock'}"
                + (f", servo outputs recorded to {self.record.path})" if self.record.path else ")"))

    def link_report(self) -> dict:
        return {**super().link_report(),
                "counts": {"servo packets": self.servo_packets, "malformed": self.malformed, "resends": self.resends,
                           "restarts": self.restarts}}

    def close(self) -> None:
        self.sock.close()
        self.record.close()
