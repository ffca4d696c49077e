"""`imu-emulator stream` as a flight stack's simulator, end to end in a subprocess, against the models of the stacks'
side in test_sitl_backends (SIM_JSON, SimulatorMavlink: sources and commits cited there). The scene is a circle of
radius 5 m at 0.5 Hz in a NED frame tangent at a known origin, so the values have closed forms:
speed 2 pi r f, yaw rate 2 pi f, centripetal acceleration (2 pi f)^2 r, and the chord from the start
2 r sin(pi f t)."""
from __future__ import annotations

import csv
import math
import socket
import subprocess

import numpy as np
import pytest

from tests.interop.test_sitl_backends import Px4Model, SimJsonModel, _free_port
from tests.support.stream import REPO, emulator_command
from tests.support.timing import scaled

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

RATE_HZ, RADIUS_M, FREQ_HZ = 250.0, 5.0, 0.5
ORIGIN = (47.397742, 8.545594, 488.0)
SCENE = f"""
[scene]
rate_hz = {RATE_HZ}
duration_s = 5.0
frame = "NED"
origin = {{ lat_deg = {ORIGIN[0]}, lon_deg = {ORIGIN[1]}, height_m = {ORIGIN[2]} }}

[trajectory]
shape = "circle"
radius_m = {RADIUS_M}
frequency_hz = {FREQ_HZ}
height_m = 0.0

[attitude]
mode = "tangent"

[[imu]]
name = "imu0"

[effects]
gravity = true
"""


def _start(tmp_path, *args):
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    proc = subprocess.Popen(emulator_command(scene, *args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=REPO)
    announced = proc.stdout.readline()        # printed once the stream is warm and the link is open
    assert "->" in announced, proc.stderr.read()
    return proc


def test_ardupilot_sitl_steps_the_stream_and_reads_the_scene(tmp_path):
    port = _free_port()
    record = tmp_path / "servos.csv"
    proc = _start(tmp_path, "--format", "ardupilot-json", "--to", f"ardupilot:127.0.0.1:{port},timeout=1,"
                  f"record={record}", "--speed", "0", "--count", "40")
    sitl = SimJsonModel(port, frame_rate=400)
    try:
        states = [sitl.update([1000 + k] * 16) for k in range(30)]        # then SITL stops stepping
        out, err = proc.communicate(timeout=scaled(120))
    finally:
        sitl.close()
        if proc.poll() is None:
            proc.kill()
    assert all(s is not None for s in states)
    stamps = np.array([s["timestamp"] for s in states])
    np.testing.assert_allclose(np.diff(stamps), 1 / RATE_HZ, atol=1e-9)
    omega = 2 * math.pi * FREQ_HZ
    for s, t in zip(states, stamps - stamps[0]):
        assert np.linalg.norm(s["velocity"]) == pytest.approx(omega * RADIUS_M, rel=1e-5)
        assert abs(s["gyro"][2]) == pytest.approx(omega, rel=1e-5)           # yaw rate of the tangent attitude
        assert np.linalg.norm(s["accel_body"][:2]) == pytest.approx(omega ** 2 * RADIUS_M, rel=1e-5)
        assert abs(s["accel_body"][2]) == pytest.approx(9.80665, rel=1e-5)
        chord = 2 * RADIUS_M * abs(math.sin(math.pi * FREQ_HZ * t))
        assert np.linalg.norm(s["position"]) == pytest.approx(chord, abs=1e-4)
        assert np.linalg.norm(s["quaternion"]) == pytest.approx(1, abs=1e-6)
    # the step that never came: one named error line, exit 2, after the summary
    assert proc.returncode == 2
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith("error: ardupilot: lockstep timeout: no servo packet")
    assert "restarted" not in err and "SITL asks for 400 Hz, the scene runs at 250 Hz" in err
    rows = list(csv.reader(record.open()))
    assert len(rows) == 31 and [int(r[3]) for r in rows[1:]] == [1000 + k for k in range(30)]


def test_px4_sitl_gets_hil_sensor_and_hil_gps_in_lockstep(tmp_path):
    port = _free_port(socket.SOCK_STREAM)
    proc = _start(tmp_path, "--format", "mavlink-hil-sensor", "--option", "also=mavlink-hil-gps",
                  "--to", f"px4:127.0.0.1:{port}", "--speed", "0", "--count", "25")
    px4 = Px4Model(port)
    try:
        times = [m.time_usec for m in px4.sensors_until_one(30)]
        for step in range(5):
            px4.send_controls(0.2)
            got = px4.sensors_until_one(10) + px4.sensors(0.1)
            assert len(got) == 1
            times.append(got[0].time_usec)
        while proc.poll() is None and len(times) < 25:
            px4.send_controls(0.2)
            times += [m.time_usec for m in px4.sensors_until_one(10)]
        out, err = proc.communicate(timeout=scaled(60))
    finally:
        px4.close()
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    # PX4 sets its clock from time_usec (px4_clock_settime): the first is one sample period after power-up, not 0
    assert times[0] == int(1e6 / RATE_HZ)
    assert np.all(np.diff(times) == int(1e6 / RATE_HZ))
    assert "HIL_ACTUATOR_CONTROLS" in err and "connections 1" in err
    # HIL_GPS as handle_message_hil_gps reads it: degE7, mm, cm/s; the circle passes through the origin
    assert px4.gps and all(m.fix_type == 3 for m in px4.gps)
    for m in px4.gps:
        assert abs(m.lat / 1e7 - ORIGIN[0]) < 2 * RADIUS_M / 111e3      # degrees of latitude: ~111 km
        assert abs(m.lon / 1e7 - ORIGIN[1]) < 2 * RADIUS_M / 75e3       # of longitude at 47.4 N: ~75 km
        assert math.hypot(m.vn, m.ve) / 100 == pytest.approx(2 * math.pi * FREQ_HZ * RADIUS_M, abs=0.02)
