"""The emulator as a flight stack's simulator, tested against models of the stacks' side transcribed from their
sources (no flight stack builds in CI's time):

- ArduPilot SITL's JSON backend, ArduPilot/ardupilot libraries/SITL/SIM_JSON.cpp at commit
  2ebd1127ac11b2a2b02dfabeb9f9e9318170af46 and SIM_JSON.h at 0394cbc9084433e45d6bc2a8c234d6c265931d39: the servo
  packet (magic 18458, frame_rate, frame_count, pwm[16]), frame_count counting parsed lines, the '\\n' -> NUL
  framing of recv_fdm and parse_sensors' strstr/sscanf("[%f, %f, %f]") reading of the keytable's keys.
- PX4 SITL's simulator_mavlink, PX4/PX4-Autopilot src/modules/simulation/simulator_mavlink/SimulatorMavlink.cpp at
  commit 000f5fdbbef9c88ea7acf446136fdbe213b5fc5f: a TCP client of port 4560 that sends HEARTBEAT first, asks for
  HIL_STATE_QUATERNION with COMMAND_LONG, takes its clock from HIL_SENSOR.time_usec and sends
  HIL_ACTUATOR_CONTROLS (flags bit 0: lockstep) after each step; decoded and encoded with pymavlink.
"""
from __future__ import annotations

import csv
import re
import select
import socket
import struct
import threading
import time

import numpy as np
import pymap3d
import pytest
from pymavlink.dialects.v20 import common as mavlink2

import firmware_protocols as fp
from imu_emulator.errors import TargetError
from imu_emulator.live.transport import TargetOptions, parse_target
from imu_emulator.live.transport.ardupilot_sitl import ArduPilotJsonTransport
from imu_emulator.live.transport.px4_sim import Px4SimTransport
from imu_emulator.live.transport.stack_link import LockstepTimeout
from tests.support.timing import scaled

PERIOD_S = 0.004


def _free_port(kind=socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# --- SIM_JSON's side ----------------------------------------------------------------------------------------------

# keytable[] of SIM_JSON.h (the keys this backend sends, in the table's order): section, key, type, required
_KEYTABLE = [("", "timestamp", "double", True), ("imu", "gyro", "vector3f", True),
             ("imu", "accel_body", "vector3f", True), ("", "position", "vector3d", True),
             ("", "attitude", "vector3f", False), ("", "quaternion", "quaternion", False),
             ("", "velocity", "vector3f", True)]
_NUMBER = r"\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?inf|[+-]?nan)"


def _atof(text: str) -> float:
    match = re.match(_NUMBER, text)
    return float(match.group(1)) if match else 0.0


def _sscanf_vector(text: str, count: int):
    """sscanf(p, "[%f, %f, %f]"): '[' must be the very next character; %f skips white space before a number; a
    ',' must follow each number at once; ' ' in the format takes any white space. None unless all are read."""
    pattern = r"\[" + r",\s*".join([_NUMBER] * count)
    match = re.match(pattern, text)
    return None if match is None else [float(v) for v in match.groups()]


def sim_json_parse_sensors(json: str):
    """JSON::parse_sensors: received_bitmask and the state, float32 where the struct holds floats."""
    state, mask = {}, 0
    for i, (section, key, kind, required) in enumerate(_KEYTABLE):
        p = json.find(section)
        if p < 0:
            if required:
                return 0, state
            continue
        p += len(section) + 1
        p = json.find(key, p)
        if p < 0:
            if required:
                return 0, state
            continue
        mask |= 1 << i
        p += len(key) + 2
        if kind == "double":
            state[key] = _atof(json[p:])
            continue
        values = _sscanf_vector(json[p:], 4 if kind == "quaternion" else 3)
        if values is None:
            return mask, state
        state[key] = np.array(values, dtype=np.float64 if kind == "vector3d" else np.float32)
    return mask, state


class SimJsonModel:
    """ArduPilot SITL's JSON backend: update() = output_servos + recv_fdm, frame_counter counting parsed lines."""

    def __init__(self, port: int, frame_rate: int = 250):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port, self.frame_rate = port, frame_rate
        self.frame_counter = 0
        self.buffer = b""

    def output_servos(self, pwm):
        self.sock.sendto(struct.pack("<HHI16H", 18458, self.frame_rate, self.frame_counter, *pwm),
                         ("127.0.0.1", self.port))

    def recv_fdm(self, timeout: float = 5.0):
        """One datagram, framed as recv_fdm does: '\\n' -> NUL, parse between the last two NULs."""
        ready, _, _ = select.select([self.sock], (), (), timeout)
        assert ready, "no JSON line came back"
        self.buffer += self.sock.recv(65000).replace(b"\n", b"\0")
        p2 = self.buffer.rfind(b"\0")
        if p2 <= 0:
            return None
        p1 = self.buffer.rfind(b"\0", 0, p2)
        if p1 < 0:
            return None
        mask, state = sim_json_parse_sensors(self.buffer[p1 + 1:p2].decode())
        self.buffer = self.buffer[p2:]
        if mask == 0 or not mask & (1 << 4 | 1 << 5):
            return None
        self.frame_counter += 1
        return state

    def update(self, pwm):
        self.output_servos(pwm)
        return self.recv_fdm()

    def close(self):
        self.sock.close()


def _json_samples(n: int):
    """A known flight: a geodetic track near Zurich climbing, with rates, forces and attitudes of its own."""
    k = np.arange(n)
    llh = np.stack([47.4 + 1e-5 * k, 8.5 + 2e-5 * k, 500.0 + 0.3 * k], axis=1)
    angle = 0.05 * k
    quat = np.stack([np.cos(angle / 2), np.zeros(n), np.zeros(n), np.sin(angle / 2)], axis=1)
    return fp.Samples(time_ns=1_000_000_000 + k * int(PERIOD_S * 1e9), accel=np.stack([0.1 * k, -0.2 + 0 * k,
                      -9.81 + 0.01 * k], axis=1), gyro=np.stack([0.001 * k, -0.002 * k, 0.5 + 0 * k], axis=1),
                      quat=quat, position_llh=llh, velocity_ned=np.stack([1.0 + k, -2.0 + 0 * k, 0.5 * k], axis=1))


def _stepper(transport, payloads, failures):
    """The streaming loop's part: before each sample await_turn, then send."""
    def run():
        try:
            for payload in payloads:
                transport.await_turn()
                transport.send(payload)
        except Exception as exc:     # noqa: BLE001 - handed to the test
            failures.append(exc)
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def _ardupilot(port, *params, lockstep=True):
    spec = parse_target(f"ardupilot:127.0.0.1:{port}" + "".join("," + p for p in params))
    transport = ArduPilotJsonTransport(spec, TargetOptions(blocking=lockstep))
    transport.sample_period_s = PERIOD_S
    return transport


def test_json_line_reads_back_through_sim_json_parser_as_the_samples():
    samples = _json_samples(5)
    batch = fp.create_encoder("ardupilot-json").encode(samples)
    origin = samples.position_llh[0]
    for i in range(5):
        line = batch.packet(i)
        assert line.startswith(b"\n") and line.endswith(b"\n") and line.count(b"\n") == 2
        mask, state = sim_json_parse_sensors(line.strip().decode())
        assert mask == 0b1101111          # every required key, and the quaternion (not euler)
        assert state["timestamp"] == samples.time_ns[i] / 1e9
        np.testing.assert_array_equal(state["gyro"], samples.gyro[i].astype(np.float32))
        np.testing.assert_array_equal(state["accel_body"], samples.accel[i].astype(np.float32))
        np.testing.assert_array_equal(state["quaternion"], samples.quat[i].astype(np.float32))
        np.testing.assert_array_equal(state["velocity"], samples.velocity_ned[i].astype(np.float32))
        expected = pymap3d.geodetic2ned(*samples.position_llh[i], *origin)       # the oracle for NED
        np.testing.assert_allclose(state["position"], expected, atol=1e-6)


def test_json_line_with_json_dumps_default_spacing_would_fail_sim_json():
    """Why the line is compact: sscanf's '[' must follow the colon at once (this is what the model checks)."""
    mask, state = sim_json_parse_sensors('{"timestamp": 1.0, "imu": {"gyro": [1.0, 2.0, 3.0]}}')
    assert "gyro" not in state


def test_json_origin_option_sets_home_and_bad_origin_is_refused():
    samples = _json_samples(3)
    encoder = fp.create_encoder("ardupilot-json", origin="47.39,8.49,480")
    _, state = sim_json_parse_sensors(encoder.encode(samples).packet(2).strip().decode())
    np.testing.assert_allclose(state["position"], pymap3d.geodetic2ned(*samples.position_llh[2], 47.39, 8.49, 480),
                               atol=1e-6)
    with pytest.raises(ValueError, match="origin: expected 'LAT,LON,HEIGHT'"):
        fp.create_encoder("ardupilot-json", origin="north pole")


def test_ardupilot_lockstep_one_line_per_servo_packet_and_servos_recorded(tmp_path):
    port = _free_port()
    record = tmp_path / "servos.csv"
    transport = _ardupilot(port, f"record={record}")
    samples = _json_samples(20)
    batch = fp.create_encoder("ardupilot-json").encode(samples)
    failures = []
    thread = _stepper(transport, [batch.packet(i) for i in range(20)], failures)
    sitl = SimJsonModel(port)
    try:
        stamps = []
        for frame in range(20):
            state = sitl.update([1000 + frame] * 16)
            assert state is not None, f"line {frame} did not parse"
            stamps.append(state["timestamp"])
        thread.join(5)
    finally:
        sitl.close()
        transport.close()
    assert not failures
    assert sitl.frame_counter == 20
    np.testing.assert_allclose(np.diff(stamps), PERIOD_S, rtol=0, atol=1e-9)    # one scene period per step
    rows = list(csv.reader(record.open()))
    assert rows[0][:4] == ["sample", "frame_rate", "frame_count", "pwm1"] and len(rows) == 21
    assert [int(r[2]) for r in rows[1:]] == list(range(20))          # frame_count as SITL sent it
    assert [int(r[3]) for r in rows[1:]] == [1000 + f for f in range(20)]
    assert transport.link_report()["counts"]["servo packets"] == 20


def test_ardupilot_malformed_packet_counted_not_answered_stream_keeps_state(capsys):
    port = _free_port()
    transport = _ardupilot(port, "timeout=5")
    batch = fp.create_encoder("ardupilot-json").encode(_json_samples(3))
    failures = []
    thread = _stepper(transport, [batch.packet(i) for i in range(3)], failures)
    sitl = SimJsonModel(port)
    try:
        first = sitl.update([1500] * 16)
        sitl.sock.sendto(b"\x1a\x48garbage", ("127.0.0.1", port))                           # wrong size
        sitl.sock.sendto(struct.pack("<HHI16H", 12345, 250, 1, *[0] * 16), ("127.0.0.1", port))  # wrong magic
        second = sitl.update([1500] * 16)
        third = sitl.update([1500] * 16)
        thread.join(5)
    finally:
        sitl.close()
        transport.close()
    assert not failures
    assert [s["timestamp"] for s in (first, second, third)] == pytest.approx([1.0, 1.004, 1.008], abs=1e-12)
    assert transport.malformed == 2
    err = capsys.readouterr().err
    assert "malformed servo packet" in err and "9 bytes" in err and "magic 12345" in err


def test_ardupilot_restart_is_announced_and_the_clock_carries_on(capsys):
    port = _free_port()
    transport = _ardupilot(port)
    batch = fp.create_encoder("ardupilot-json").encode(_json_samples(4))
    failures = []
    thread = _stepper(transport, [batch.packet(i) for i in range(4)], failures)
    sitl = SimJsonModel(port)
    try:
        stamps = [sitl.update([1000] * 16)["timestamp"], sitl.update([1000] * 16)["timestamp"]]
        sitl.frame_counter = 0                    # SITL restarted: a new process counts from 0 again
        stamps += [sitl.update([1000] * 16)["timestamp"], sitl.update([1000] * 16)["timestamp"]]
        thread.join(5)
    finally:
        sitl.close()
        transport.close()
    assert not failures and transport.restarts == 1
    assert np.all(np.diff(stamps) > 0)
    assert "SITL restarted (frame_count 0 after 1)" in capsys.readouterr().err


def test_ardupilot_step_that_never_comes_is_a_named_timeout():
    port = _free_port()
    transport = _ardupilot(port, "timeout=0.3")
    batch = fp.create_encoder("ardupilot-json").encode(_json_samples(3))
    failures = []
    thread = _stepper(transport, [batch.packet(i) for i in range(3)], failures)
    sitl = SimJsonModel(port)
    try:
        assert sitl.update([1000] * 16) is not None
        start = time.monotonic()
        thread.join(5)              # SITL sends nothing more
        waited = time.monotonic() - start
    finally:
        sitl.close()
        transport.close()
    assert len(failures) == 1 and isinstance(failures[0], LockstepTimeout)
    assert isinstance(failures[0], TargetError)        # the CLI's one-line error, exit 2
    assert "lockstep timeout" in str(failures[0]) and "0.3 s" in str(failures[0]) and "timeout=" in str(failures[0])
    assert 0.25 < waited < 3


@pytest.mark.parametrize("spec, expected", [
    ("ardupilot:127.0.0.1:0", "port between 1 and 65535"),
    ("ardupilot:9002,speed=3", "'speed=3' is not one of record=PATH, timeout=SECONDS"),
    ("px4:4560,timeout=-1", "timeout= expects a positive number"),
    ("px4:4560,timeout=nan", "timeout= expects a positive number"),
    ("px4:4560,record=a.csv,record=b.csv", "record= given twice"),
])
def test_bad_stack_specs_are_named(spec, expected):
    with pytest.raises(TargetError, match=re.escape(expected)):
        parse_target(spec)


def test_stack_specs_default_to_the_stacks_ports():
    assert (parse_target("px4").path, parse_target("px4").port) == ("127.0.0.1", 4560)
    assert parse_target("ardupilot").port == 9002
    spec = parse_target("ardupilot:0.0.0.0:9003,record=x.csv,timeout=2")
    assert (spec.path, spec.port, dict(spec.params)) == ("0.0.0.0", 9003, {"record": "x.csv", "timeout": "2"})


# --- simulator_mavlink's side -------------------------------------------------------------------------------------

class Px4Model:
    """SimulatorMavlink over TCP: run() connects, send() starts with HEARTBEAT, run() asks for
    HIL_STATE_QUATERNION; HIL_SENSOR id 0 sets the clock; one HIL_ACTUATOR_CONTROLS per step (flags 1: lockstep)."""

    def __init__(self, port: int):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=scaled(5))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        self.clock_usec = None
        self.gps = []
        hb = self.mav.heartbeat_encode(type=0, autopilot=12, base_mode=0, custom_mode=0, system_status=0)
        self.sock.sendall(hb.pack(self.mav))
        cmd = self.mav.command_long_encode(0, 0, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                           mavlink2.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, 5e3, 0, 0, 0, 0, 0)
        self.sock.sendall(cmd.pack(self.mav))

    def sensors(self, timeout: float, until_one: bool = False):
        """HIL_SENSOR messages (id 0) that arrive within timeout (or until the first, `until_one`); HIL_GPS ones
        are kept in self.gps."""
        end = time.monotonic() + timeout
        found = []
        while time.monotonic() < end:
            ready, _, _ = select.select([self.sock], (), (), max(end - time.monotonic(), 0))
            if not ready:
                break
            data = self.sock.recv(65536)
            if not data:
                break
            for msg in self.mav.parse_buffer(data) or []:
                if msg.get_type() == "HIL_SENSOR" and msg.id == 0:
                    self.clock_usec = msg.time_usec          # px4_clock_settime
                    found.append(msg)
                elif msg.get_type() == "HIL_GPS":
                    self.gps.append(msg)                     # handle_message_hil_gps
            if found and until_one:
                break
        return found

    def sensors_until_one(self, timeout):
        """What arrives until the first HIL_SENSOR (with any others in the same read)."""
        return self.sensors(timeout, until_one=True)

    def send_controls(self, value: float):
        msg = self.mav.hil_actuator_controls_encode(self.clock_usec or 0, [value] * 16, 1 | 128, 1)
        self.sock.sendall(msg.pack(self.mav))

    def close(self):
        self.sock.close()


def _px4(port, *params, lockstep=True):
    spec = parse_target(f"px4:127.0.0.1:{port}" + "".join("," + p for p in params))
    transport = Px4SimTransport(spec, TargetOptions(blocking=lockstep))
    transport.sample_period_s = PERIOD_S
    return transport


def _hil_sensor_packets(n: int):
    k = np.arange(n)
    samples = fp.Samples(time_ns=k * int(PERIOD_S * 1e9), accel=np.tile([0.0, 0.0, -9.81], (n, 1)),
                         gyro=np.stack([0.001 * k, 0 * k, 0 * k], axis=1))
    batch = fp.create_encoder("mavlink-hil-sensor").encode(samples)
    return [batch.packet(i) for i in range(n)]


def test_px4_lockstep_one_sensor_step_per_actuator_message(tmp_path):
    port = _free_port(socket.SOCK_STREAM)
    record = tmp_path / "actuators.csv"
    transport = _px4(port, f"record={record}")
    failures = []
    thread = _stepper(transport, _hil_sensor_packets(40), failures)
    px4 = Px4Model(port)
    try:
        # before its first HIL_ACTUATOR_CONTROLS the stack gets sensor time at the scene's rate
        before = px4.sensors_until_one(5) + px4.sensors(0.05)
        assert len(before) >= 2
        times = [m.time_usec for m in before]
        for step in range(10):
            px4.send_controls(0.1 * step)
            got = px4.sensors_until_one(5)
            if step == 0:
                # Samples the wall clock paced before the stream read this first step may still have been on their
                # way (one every 4 ms; a loaded machine took longer than that to answer): take everything the
                # stream sent until it has answered the step.
                end = time.monotonic() + scaled(5)
                while not (transport.stepping and transport.pending == 0
                           and len(before) + len(got) == transport.samples_sent) and time.monotonic() < end:
                    got += px4.sensors(0.01)
            else:
                got += px4.sensors(0.08 if step < 3 else 0.0)      # nothing more comes until the next step
                assert len(got) == 1, f"step {step}: {len(got)} HIL_SENSOR for one HIL_ACTUATOR_CONTROLS"
            times.extend(m.time_usec for m in got)
    finally:
        px4.close()
        thread.join(5)
        transport.close()
    assert np.all(np.diff(times) == int(PERIOD_S * 1e6))        # time stamps advance by the scene's period
    assert transport.actuator_messages == 10
    rows = list(csv.reader(record.open()))
    assert rows[0][:5] == ["sample", "time_usec", "mode", "flags", "control0"] and len(rows) == 11
    assert np.all(np.diff([int(r[0]) for r in rows[1:]]) == 1)     # the stream: one sample per step, step 0 too
    assert [float(r[4]) for r in rows[1:]] == pytest.approx([np.float32(0.1 * s) for s in range(10)])
    assert {int(r[3]) for r in rows[1:]} == {1}


def test_px4_reconnect_stream_keeps_its_clock(capsys):
    port = _free_port(socket.SOCK_STREAM)
    transport = _px4(port)
    failures = []
    thread = _stepper(transport, _hil_sensor_packets(200), failures)
    px4 = Px4Model(port)
    try:
        px4.sensors_until_one(5)
        px4.send_controls(0.0)
        last = px4.sensors_until_one(5)[-1].time_usec
        px4.close()                               # the stack goes away while the stream waits for its step
        time.sleep(0.2)
        px4 = Px4Model(port)                      # ... and comes back
        again = px4.sensors_until_one(5)[0].time_usec
        counts = (transport.connections, transport.disconnects)
    finally:
        px4.close()
        transport.close()
        thread.join(5)
    assert again == last + int(PERIOD_S * 1e6)   # no sample lost, none repeated: the stream kept its state
    assert counts == (2, 1)
    err = capsys.readouterr().err
    assert "PX4 SITL disconnected (connection closed)" in err and err.count("PX4 SITL connected from") == 2


def test_px4_step_that_never_comes_is_a_named_timeout():
    port = _free_port(socket.SOCK_STREAM)
    transport = _px4(port, "timeout=0.3")
    failures = []
    thread = _stepper(transport, _hil_sensor_packets(50), failures)
    px4 = Px4Model(port)
    try:
        px4.sensors_until_one(5)
        px4.send_controls(0.0)                    # lockstep begins ... and the stack hangs
        thread.join(5)
    finally:
        px4.close()
        transport.close()
    assert len(failures) == 1 and isinstance(failures[0], LockstepTimeout)
    assert "px4: lockstep timeout: no HIL_ACTUATOR_CONTROLS" in str(failures[0]) and "0.3 s" in str(failures[0])


def test_px4_wall_clock_drops_while_no_stack_and_records_what_comes():
    port = _free_port(socket.SOCK_STREAM)
    transport = _px4(port, lockstep=False)
    try:
        packets = _hil_sensor_packets(3)
        transport.await_turn()
        assert transport.send(packets[0]) is False
        assert transport.send_errors == {"no stack connected": 1}
        px4 = Px4Model(port)
        time.sleep(0.05)
        transport.await_turn()
        assert transport.send(packets[1])
        px4.send_controls(0.5)
        time.sleep(0.05)
        transport.await_turn()
        assert transport.send(packets[2])
        got = px4.sensors(0.2)
        assert [m.time_usec for m in got] == [4000, 8000]
        assert transport.actuator_messages == 1
        px4.close()
    finally:
        transport.close()


def test_ardupilot_32_channel_packets_and_resends_are_taken(tmp_path):
    """SERVO_32_ENABLE: magic 29569 with pwm[32]; a resend (same frame_count: SITL missed our line) is answered
    with the next sample and counted."""
    port = _free_port()
    record = tmp_path / "servos.csv"
    transport = _ardupilot(port, f"record={record}")
    batch = fp.create_encoder("ardupilot-json").encode(_json_samples(3))
    failures = []
    thread = _stepper(transport, [batch.packet(i) for i in range(3)], failures)
    sitl = SimJsonModel(port)
    try:
        packet = struct.pack("<HHI32H", 29569, 250, 0, *range(1000, 1032))
        sitl.sock.sendto(packet, ("127.0.0.1", port))
        first = sitl.recv_fdm()
        sitl.sock.sendto(packet, ("127.0.0.1", port))           # the same frame again
        second = sitl.recv_fdm()
        thread.join(0.5)
    finally:
        sitl.close()
        transport.close()
    assert not failures
    assert second["timestamp"] - first["timestamp"] == pytest.approx(PERIOD_S, abs=1e-12)
    assert (transport.servo_packets, transport.resends, transport.malformed) == (2, 1, 0)
    rows = list(csv.reader(record.open()))
    assert [int(v) for v in rows[1][3:]] == list(range(1000, 1032))


def test_ardupilot_wall_clock_sends_to_the_last_sitl_heard_and_refuses_before():
    port = _free_port()
    transport = _ardupilot(port, lockstep=False)
    batch = fp.create_encoder("ardupilot-json").encode(_json_samples(2))
    sitl = SimJsonModel(port)
    try:
        transport.await_turn()
        assert transport.send(batch.packet(0)) is False       # nobody to send to yet: counted
        assert transport.send_errors == {"no SITL heard from yet": 1}
        sitl.output_servos([1200] * 16)
        time.sleep(0.05)
        transport.await_turn()                                  # never blocks: reads what came
        assert transport.send(batch.packet(1))
        assert sitl.recv_fdm()["timestamp"] == pytest.approx(1.004)
    finally:
        sitl.close()
        transport.close()


@pytest.mark.parametrize("fmt, options, device, expected", [
    ("ardupilot-json", {}, True, True),                             # its encoder reads position and velocity
    ("mavlink-hil-sensor", {}, True, False),
    ("mavlink-hil-sensor", {"also": "mavlink-hil-gps"}, True, True),   # HIL_GPS beside it needs the navigation
    ("mavlink-hil-sensor", {"also": "mavlink-hil-gps"}, False, False),  # --device off: HIL_SENSOR alone goes out
    ("mavlink-highres", {}, True, False),
])
def test_the_simulation_computes_navigation_exactly_for_streams_that_send_it(fmt, options, device, expected):
    from imu_emulator.live.config import StreamConfig, needs_truth
    assert needs_truth([StreamConfig("imu0", fmt, "px4", options, device=device)]) is expected


def test_ardupilot_resends_queued_while_the_stream_started_get_one_line():
    """SITL resends its packet each second without an answer (SIM_JSON recv_fdm): the copies queued before the
    stream's first step are answered once, or SITL would read one stale line at every step from then on."""
    port = _free_port()
    transport = _ardupilot(port)
    batch = fp.create_encoder("ardupilot-json").encode(_json_samples(3))
    sitl = SimJsonModel(port)
    for _ in range(3):
        sitl.output_servos([1000] * 16)           # frame 0, sent three times before anyone answered
    time.sleep(0.05)
    failures = []
    thread = _stepper(transport, [batch.packet(i) for i in range(3)], failures)
    try:
        first = sitl.recv_fdm()
        assert not select.select([sitl.sock], (), (), 0.2)[0]        # one line, not three
        second = sitl.update([1000] * 16)
        thread.join(0.5)
    finally:
        sitl.close()
        transport.close()
    assert (first["timestamp"], second["timestamp"]) == pytest.approx((1.0, 1.004))
    assert (transport.servo_packets, transport.resends) == (4, 2)


def test_px4_input_no_device_reads_is_bounded_and_counted():
    port = _free_port(socket.SOCK_STREAM)
    transport = _px4(port, lockstep=False)
    px4 = Px4Model(port)
    try:
        time.sleep(0.05)
        transport.await_turn()
        for _ in range(800):                      # ~74 kB of HIL_ACTUATOR_CONTROLS nobody reads as a device would
            px4.send_controls(0.0)
        end = time.monotonic() + scaled(5)
        while transport.actuator_messages < 800 and time.monotonic() < end:
            time.sleep(0.02)
            transport.await_turn()
        assert transport.actuator_messages == 800
        assert len(transport.recv()) == 1 << 16
        assert transport.link_report()["counts"]["input bytes not read"] > 0
    finally:
        px4.close()
        transport.close()
