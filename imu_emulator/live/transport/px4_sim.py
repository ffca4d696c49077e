"""PX4 SITL's simulator interface: the emulator is the simulator, a TCP server the stack connects to.

The other side, as PX4-Autopilot src/modules/simulation/simulator_mavlink/SimulatorMavlink.cpp has it (commit
000f5fdbbef9c88ea7acf446136fdbe213b5fc5f): run() connects to the simulator's TCP port (4560 by default), retrying
until it is accepted, then starts a sender thread that sends one HEARTBEAT "to initiate the SITL simulator to start
sending sensor data which will set the time", and from then on one HIL_ACTUATOR_CONTROLS (msg 93; flags bit 0 =
lockstep) each time actuator_outputs_sim is published, after px4_lockstep_wait_for_components(); it also asks for
HIL_STATE_QUATERNION with a COMMAND_LONG (a MAVLink device on this link answers it DENIED: no ground truth is
streamed). Every HIL_SENSOR with id 0 sets PX4's clock to its time_usec (px4_clock_settime): the sensor time
stamps ARE the stack's time, so lockstep needs only that the simulator wait for the stack. The first stamp is one
sample period, never 0 (power_up_lead_periods): the unit's power-up is a period before the run's start.

Lockstep (--speed 0, the target's blocking mode): until the stack's first HIL_ACTUATOR_CONTROLS on a connection
the samples go at the scene's rate by the wall clock (the stack publishes outputs only once its modules have run
on some sensor time); after it, exactly one sample per HIL_ACTUATOR_CONTROLS, and none comes for `timeout` s is a
LockstepTimeout naming it. Wall clock (--speed > 0): samples at the scene's rate, the stack's messages read and
recorded as they come. Either way the actuator outputs are recorded (record=PATH, CSV), never obeyed: the
scene's motion is scripted. A stack that disconnects is announced in one line; samples meanwhile are dropped
(counted) at wall-clock rate, or wait for it to connect again in lockstep; the stream's clock and sequence numbers
carry on (PX4 takes its time from the sensor messages, so a restarted stack simply starts at the stream's time).
"""
from __future__ import annotations

import select
import socket
import struct
import time
from types import SimpleNamespace

from firmware_protocols.wire_formats.mavlink import MavlinkDecoder
from imu_emulator.live.transport.base import TargetOptions, Transport, error_name
from imu_emulator.live.transport.spec import TargetSpec
from imu_emulator.live.transport.stack_link import (ActuatorRecord, LockstepTimeout, bind, note, record_path,
                                                   timeout_of)

HIL_ACTUATOR_CONTROLS = 93
# common.xml as pymavlink generates it: time_usec u64, flags u64, controls f32[16], mode u8 (CRC_EXTRA 47)
_ACTUATOR = struct.Struct("<QQ16fB")


def _decode_actuators(payload: bytes) -> dict:
    values = _ACTUATOR.unpack(payload)
    return {"time_usec": values[0], "flags": values[1], "controls": values[2:18], "mode": values[18]}


_ACTUATOR_SPEC = SimpleNamespace(name="HIL_ACTUATOR_CONTROLS", crc_extra=47, payload_len=_ACTUATOR.size,
                                 decode=_decode_actuators)
_COLUMNS = ["sample", "time_usec", "mode", "flags"] + [f"control{i}" for i in range(16)]
# What the stack sent, kept for the stream's device: a stream without one never takes it
_INPUT_KEPT = 1 << 16


class Px4SimTransport(Transport):
    sets_pace = True
    # PX4's clock IS the HIL_SENSOR stamps (handle_message_hil_sensor: px4_clock_settime(CLOCK_MONOTONIC,
    # time_usec), then update_sensors(hrt_absolute_time(), ...); SimulatorMavlink.cpp at the commit above), and 0
    # there is uORB's "never published" (its send_controls sends only once actuator_outputs.timestamp > 0) and a
    # zero interval for the first FIFO sample (dt = time - the last stamp). The unit powers up one sample period before scene time 0, as a physics
    # simulator's first sensor message comes after its first step: time_usec of sample k is t_k - t_start + period.
    power_up_lead_periods = 1

    def __init__(self, spec: TargetSpec, options: TargetOptions):
        self.host, self.port = spec.path, spec.port
        self.lockstep = options.blocking
        self.timeout = timeout_of(spec)
        self.server = bind("px4", self.host, self.port, socket.SOCK_STREAM)
        self.record = ActuatorRecord(record_path(spec), _COLUMNS, spec.text)
        self.conn = None
        self._input = bytearray()          # what the stack sent, for the stream's device (COMMAND_LONG)
        self._decoder = MavlinkDecoder(messages={HIL_ACTUATOR_CONTROLS: _ACTUATOR_SPEC})
        self.pending = 0                   # HIL_ACTUATOR_CONTROLS not yet answered by a sample
        self.stepping = False              # the connection's first HIL_ACTUATOR_CONTROLS has come
        self.samples_sent = 0
        self.connections = self.disconnects = self.actuator_messages = 0
        self.input_dropped = 0             # bytes the stack sent that no device took (beyond _INPUT_KEPT)
        self._last_turn_ns = 0

    # - the connection -
    def _accept(self, wait_s: float | None) -> None:
        """Take a stack's connection, waiting up to wait_s (None: as long as it takes: the user starts the stack)."""
        if wait_s is None:
            note(f"px4: waiting for PX4 SITL to connect on {self.host}:{self.port}")
        ready, _, _ = select.select([self.server], (), (), wait_s)
        if not ready:
            return
        conn, peer = self.server.accept()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)   # as PX4 sets on its side
        conn.setblocking(False)    # reads never wait; sends wait for room up to the timeout (_send_all)
        self.conn, self.stepping, self.pending = conn, False, 0
        self._decoder = MavlinkDecoder(messages={HIL_ACTUATOR_CONTROLS: _ACTUATOR_SPEC})
        self.connections += 1
        note(f"px4: PX4 SITL connected from {peer[0]}:{peer[1]}"
             + (" (lockstep: one sample per HIL_ACTUATOR_CONTROLS once they come)" if self.lockstep else ""))

    def _disconnect(self, reason: str) -> None:
        self.conn.close()
        self.conn = None
        self.disconnects += 1
        note(f"px4: PX4 SITL disconnected ({reason}) after {self.samples_sent} samples; the stream carries on "
             f"and waits for it on {self.host}:{self.port}")

    def _read(self) -> None:
        """Everything the stack has sent so far, without blocking: actuator messages counted and recorded."""
        while self.conn is not None:
            try:
                chunk = self.conn.recv(65536, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                self._disconnect(error_name(exc))
                return
            if not chunk:
                self._disconnect("connection closed")
                return
            self._input += chunk
            if len(self._input) > _INPUT_KEPT:     # nobody reads it (--device off): keep the newest only
                self.input_dropped += len(self._input) - _INPUT_KEPT
                del self._input[:-_INPUT_KEPT]
            for packet in self._decoder.feed(chunk):
                f = packet.fields
                self.actuator_messages += 1
                self.pending += 1
                self.stepping = True
                self.record.add([self.samples_sent, f["time_usec"], f["mode"], f["flags"], *f["controls"]])

    def _wait_readable(self, seconds: float) -> None:
        if self.conn is not None:
            select.select([self.conn], (), (), max(seconds, 0.0))
        self._read()

    # - the streaming loop's side -
    def await_turn(self) -> None:
        if self.conn is None:
            self._accept(None if self.lockstep else 0)
        self._read()
        if self.conn is None and self.lockstep:
            self._accept(None)
        if self.conn is None or not self.lockstep:
            return
        now = time.monotonic_ns()
        if not self.stepping:
            # before the first actuator message: the scene's rate by the wall clock, or as soon as one comes
            due = self._last_turn_ns + int((self.sample_period_s or 0.0) * 1e9)
            while self.conn is not None and not self.stepping and now < due:
                self._wait_readable((due - now) / 1e9)
                now = time.monotonic_ns()
            if not self.stepping:
                self._last_turn_ns = now
                return
        deadline = now + int(self.timeout * 1e9)
        while self.conn is not None and self.pending == 0:
            if now >= deadline:
                raise LockstepTimeout(f"px4: lockstep timeout: no HIL_ACTUATOR_CONTROLS from PX4 SITL for "
                                      f"{self.timeout:g} s after sample {self.samples_sent} (timeout= in the "
                                      "target sets the limit)")
            self._wait_readable((deadline - now) / 1e9)
            now = time.monotonic_ns()
        if self.conn is None:       # it left while we waited: wait for it to come back
            self.await_turn()
            return
        self.pending -= 1
        self._last_turn_ns = now

    def send(self, payload: bytes) -> bool:
        if self.conn is None:
            self.count_refusal("no stack connected")
            return False
        try:
            self._send_all(payload)
        except OSError as exc:
            self._disconnect(error_name(exc))
            self.count_refusal("stack disconnected")
            return False
        self.samples_sent += 1
        return True

    def _send_all(self, payload: bytes) -> None:
        """All of it (a stream link: half a message would garble the rest), waiting for room up to the timeout."""
        view = memoryview(payload)
        deadline = time.monotonic() + self.timeout
        while view:
            try:
                view = view[self.conn.send(view):]
            except (BlockingIOError, InterruptedError):
                pass
            if view:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise LockstepTimeout(f"px4: PX4 SITL took no data for {self.timeout:g} s (timeout= in the "
                                          "target sets the limit)")
                select.select((), [self.conn], (), remaining)

    def recv(self) -> bytes:
        self._read()
        data = bytes(self._input)
        self._input.clear()
        return data

    def describe(self) -> str:
        return (f"px4 simulator interface tcp {self.host}:{self.port} ({'lockstep' if self.lockstep else 'wall clock'}"
                + (f", actuators recorded to {self.record.path})" if self.record.path else ")"))

    def link_report(self) -> dict:
        return {**super().link_report(),
                "counts": {"connections": self.connections, "disconnects": self.disconnects,
                           "HIL_ACTUATOR_CONTROLS": self.actuator_messages,
                           **({"input bytes not read": self.input_dropped} if self.input_dropped else {})}}

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None
        self.server.close()
        self.record.close()
