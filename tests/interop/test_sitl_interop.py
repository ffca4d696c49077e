"""tools/interop (issue 26): the defaults file ArduPilot SITL reads, the report's error computation, and the
stream's started_unix_ns the report's time base rests on. None needs a flight stack; the run against a built SITL
is the last test, skipped unless IMU_EMULATOR_ARDUCOPTER and IMU_EMULATOR_COPTER_PARM name the binary and
ArduPilot's Tools/autotest/default_params/copter.parm.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from scipy.spatial.transform import Rotation
from tests.support.paths import REPO

ROOT = REPO
sys.path.insert(0, str(ROOT / "tools" / "interop"))
import ardupilot_params  # noqa: E402
import ardupilot_sitl_run  # noqa: E402
import sitl_report  # noqa: E402
from tests.support.timing import scaled

pytestmark = pytest.mark.subprocess

ORIGIN = (-35.363262, 149.165237, 584.0)


@pytest.mark.parametrize("device", ["vn300", "gq7", "json"])
def test_defaults_file_reads_back_with_pymavlink(tmp_path, device):
    params = ardupilot_params.device_params(device)
    path = ardupilot_params.write_params(tmp_path / "emulated.parm", params)
    from pymavlink import mavparm
    read = mavparm.MAVParmDict()
    read.load(str(path))
    assert dict(read) == {k: float(v) for k, v in params.items()}
    if device != "json":
        # Tools/autotest/arduplane.py fly_external_AHRS's parameters, the port as SITL numbers it
        assert params["SERIAL4_PROTOCOL"] == 36 and params["AHRS_EKF_TYPE"] == 11 and params["GPS1_TYPE"] == 21
        assert params["EAHRS_TYPE"] == {"vn300": 1, "gq7": 7}[device]
        assert params["EAHRS_SENSORS"] == 0xF          # the parameter's default: GPS, IMU, baro, compass


def test_sensor_mask_is_ardupilots_bitmask():
    """AP_ExternalAHRS.h AvailableSensor (265753db8b): GPS 1<<0, IMU 1<<1, BARO 1<<2, COMPASS 1<<3."""
    assert ardupilot_params.sensors_mask("gps") == 1 and ardupilot_params.sensors_mask("gps,baro") == 5
    assert ardupilot_params.sensors_mask("imu,compass") == 10 and ardupilot_params.sensors_mask("all") == 15
    assert ardupilot_params.device_params("vn300", sensors="gps")["EAHRS_SENSORS"] == 1
    with pytest.raises(ValueError, match="airspeed"):
        ardupilot_params.sensors_mask("gps,airspeed")


@pytest.mark.parametrize("params, says", [({"EAHRS_TYPE_TOO_LONG_NAME": 1}, "not an ArduPilot parameter name"),
                                          ({"eahrs_type": 1}, "not an ArduPilot parameter name"),
                                          ({"EAHRS_RATE": float("nan")}, "not finite")])
def test_defaults_file_refuses_what_sitl_would_skip(params, says):
    with pytest.raises(ValueError, match=says):
        ardupilot_params.param_text(params)


def test_sitl_serial_argument_parses_as_uartdriver_reads_it(tmp_path):
    """libraries/AP_HAL_SITL/UARTDriver.cpp (ArduPilot 265753db8b): strtok at ':' -> devtype, path, baud."""
    cmd = ardupilot_sitl_run.sitl_command(Path("/bin/arducopter"), [Path("a.parm"), Path("b.parm")], "vn300",
                                          tmp_path, ORIGIN)
    serial = [a for a in cmd if a.startswith("--serial4=")]
    assert len(serial) == 1
    devtype, path, baud = serial[0].split("=", 1)[1].split(":")
    assert (devtype, path, int(baud)) == ("uart", str(tmp_path / "device"), 230400)
    assert cmd[cmd.index("--defaults") + 1] == "a.parm,b.parm"
    assert cmd[cmd.index("--home") + 1] == "-35.363262,149.165237,584.0,0"


def _truth():
    """A straight climbing line at 2 m/s north, 1 m/s east, 0.5 m/s up, yawing 10 deg/s, rolled and pitched:
    positions and velocity linear in time, so the linear interpolation of coarse samples is exact."""
    t = np.arange(0.0, 20.0 + 1e-9, 0.5)
    vel = np.tile([2.0, 1.0, -0.5], (t.size, 1))
    pos = vel * t[:, None]
    euler = np.column_stack([np.full(t.size, 0.1), np.full(t.size, -0.05), np.radians(10.0) * t])
    return sitl_report.Truth(t=t, position_ned=pos, velocity_ned=vel, euler=euler, origin=ORIGIN)


def test_errors_of_a_known_offset_estimate_against_the_closed_form():
    truth = _truth()
    te = np.arange(0.13, 19.9, 0.1)              # between the truth's samples
    pos = np.array([2.0, 1.0, -0.5]) * te[:, None]
    offset = np.where(te[:, None] < 5.0, [60.0, 80.0, 0.0], [3.0, 4.0, -1.0])   # 100 m before convergence
    lat, lon, alt = pymap3d.ned2geodetic(*(pos + offset).T, *ORIGIN)
    euler = np.column_stack([np.full(te.size, 0.1), np.full(te.size, -0.05), np.radians(10.0) * te + np.radians(2.0)])
    est = sitl_report.Estimates(attitude_t=te, euler=euler, position_t=te, lat_lon_alt=np.column_stack([lat, lon, alt]),
                                velocity_ned=np.tile([2.3, 1.4, -0.5], (te.size, 1)),
                                ekf_t=np.array([1.0, 4.0, 5.0, 6.0]),
                                ekf_flags=np.array([0, 1 | 2 | 4, sitl_report.EKF_HEALTHY_NEEDS,
                                                    sitl_report.EKF_HEALTHY_NEEDS]),
                                prearm_t=np.array([2.0, 3.0]), prearm_ok=np.array([False, True]))
    result = sitl_report.compare(est, truth)
    assert result["ekf_healthy_s"] == 5.0 and result["prearm_passed_s"] == 3.0
    s = result["stats"]
    after = int(np.sum(te >= 5.0))
    # a yaw offset of 2 deg after roll and pitch is still a rotation by 2 deg (R' R^T = Rz(2 deg), conjugated)
    assert s["attitude_deg"]["n"] == after
    assert s["attitude_deg"]["max"] == pytest.approx(2.0, abs=1e-9)
    assert s["attitude_deg"]["rms"] == pytest.approx(2.0, abs=1e-9)
    assert s["horizontal_m"]["max"] == pytest.approx(5.0, abs=1e-6)      # hypot(3, 4)
    assert s["horizontal_m"]["rms"] == pytest.approx(5.0, abs=1e-6)
    assert s["vertical_m"]["rms"] == pytest.approx(1.0, abs=1e-6)
    assert s["velocity_mps"]["max"] == pytest.approx(0.5, abs=1e-12)     # hypot(0.3, 0.4)
    # before convergence the 100 m error is in the series, not in the statistics
    t, horizontal = result["series"]["horizontal_m"]
    assert horizontal[t < 5.0] == pytest.approx(100.0, abs=1e-6)


def test_report_from_mavlink_messages_states_the_closed_form_errors(tmp_path):
    """The whole report path from pymavlink's own message objects: the estimate is the truth moved 3 m north,
    4 m east (5 m horizontally) and turned 2 deg in yaw once the EKF is healthy at 5 s; GLOBAL_POSITION_INT's
    1e-7 deg integers round positions to about a centimetre."""
    import argparse
    from pymavlink.dialects.v20 import ardupilotmega as m
    truth = _truth()
    started = 1.7e9
    rec = ardupilot_sitl_run.Recorder()
    for t in np.arange(0.05, 19.9, 0.1):
        boot_ms = int(round((t + 3.0) * 1000))     # the stack booted 3 s before the stream's first deadline
        t = boot_ms / 1000 - 3.0
        roll, pitch, yaw = 0.1, -0.05, math.remainder(math.radians(10.0 * t + (2.0 if t >= 5 else 0.0)), 2 * math.pi)
        rec.add(m.MAVLink_attitude_message(boot_ms, roll, pitch, yaw, 0, 0, 0), started + t)
        off = (3.0, 4.0, -1.0) if t >= 5 else (30.0, 40.0, 0.0)
        lat, lon, alt = pymap3d.ned2geodetic(2.0 * t + off[0], 1.0 * t + off[1], -0.5 * t + off[2], *ORIGIN)
        rec.add(m.MAVLink_global_position_int_message(boot_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1e3),
                                                      0, 200, 100, -50, 0), started + t)
        flags = sitl_report.EKF_HEALTHY_NEEDS if t >= 5 else m.EKF_ATTITUDE
        rec.add(m.MAVLink_ekf_status_report_message(flags, 0, 0, 0, 0, 0), started + t)
        health = m.MAV_SYS_STATUS_PREARM_CHECK if t >= 6 else 0
        rec.add(m.MAVLink_sys_status_message(0, 0, health, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0), started + t)
    rec.add(m.MAVLink_statustext_message(6, b"EAHRS: VectorNav VN-300-CR"), started + 1)
    outcome = {"work": tmp_path, "rec": rec, "truth": truth, "armed_at": started + 7.0,
               "stream": {"started_unix_ns": int(started * 1e9), "samples": 4000, "dropped": 0},
               "commands": [["imu-emulator", "stream"], ["arducopter"]], "params": {"EAHRS_TYPE": 1}}
    args = argparse.Namespace(device="vn300", scene=Path("examples/sitl_flight.toml"))
    report = ardupilot_sitl_run.write_report(tmp_path / "out", args, outcome, "265753db8b")
    text = report.read_text()
    assert (tmp_path / "out" / "ardupilot-vn300.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    def row(label):
        cells = text.split(f"| {label} | ")[1].split("\n")[0].split(" | ")
        return float(cells[0].split()[0]), float(cells[1].split()[0])
    assert row("attitude error (rotation angle)") == pytest.approx((2.0, 2.0), abs=2e-3)
    assert row("horizontal position error") == pytest.approx((5.0, 5.0), abs=0.02)
    assert row("vertical position error (down)") == pytest.approx((1.0, 1.0), abs=0.002)
    assert row("velocity error (3D)")[0] == pytest.approx(0.0, abs=1e-9)
    assert "EKF healthy (attitude, velocity, absolute position flags; not constant-position mode): 5.0 s" in text
    assert "pre-arm checks passed (SYS_STATUS pre-arm bit first set): 6.0 s" in text
    assert "- armed: 7.0 s" in text and "EAHRS: VectorNav VN-300-CR" in text


def test_attitude_error_is_the_rotation_angle_for_random_attitudes():
    rng = np.random.default_rng(26)
    truth = Rotation.random(50, random_state=7)
    axis = rng.normal(size=(50, 3))
    angle = rng.uniform(0, 0.3, 50)
    est = truth * Rotation.from_rotvec(axis / np.linalg.norm(axis, axis=1)[:, None] * angle[:, None])
    euler = est.as_euler("ZYX")[:, ::-1]
    np.testing.assert_allclose(sitl_report.attitude_error_deg(euler, truth), np.degrees(angle), atol=1e-9)


def test_ekf_flags_are_mavlinks():
    from pymavlink.dialects.v20 import ardupilotmega as m
    assert sitl_report.EKF_HEALTHY_NEEDS == (m.EKF_ATTITUDE | m.EKF_VELOCITY_HORIZ | m.EKF_VELOCITY_VERT
                                             | m.EKF_POS_HORIZ_ABS | m.EKF_POS_VERT_ABS)
    assert (sitl_report.EKF_CONST_POS_MODE, sitl_report.EKF_UNINITIALIZED) == (m.EKF_CONST_POS_MODE,
                                                                               m.EKF_UNINITIALIZED)
    assert sitl_report.PREARM_CHECK == m.MAV_SYS_STATUS_PREARM_CHECK
    flags = np.array([sitl_report.EKF_HEALTHY_NEEDS, sitl_report.EKF_HEALTHY_NEEDS | m.EKF_CONST_POS_MODE,
                      sitl_report.EKF_HEALTHY_NEEDS & ~m.EKF_POS_HORIZ_ABS])
    assert sitl_report.ekf_healthy(flags).tolist() == [True, False, False]


def test_stack_clock_to_scene_time_by_the_quickest_delivery():
    """Received = boot + 1000 s + a delay >= 0 that is 0 now and then (each 10 s window): scene time = boot + 1000 - start."""
    rng = np.random.default_rng(1)
    boot = np.sort(rng.uniform(0, 60, 600))
    delay = rng.uniform(0.001, 0.08, boot.size)
    delay[::20] = 0.0           # a quickest delivery in every window (about 100 messages each)
    started = 1003.0
    scene_t = sitl_report.wall_to_scene(boot, boot + 1000.0 + delay, started)
    np.testing.assert_allclose(scene_t, boot - 3.0, atol=1e-9)


def test_stream_states_the_wall_clock_of_its_first_deadline(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text('[scene]\nrate_hz = 100\nduration_s = 1.0\n[trajectory]\nshape = "static"\n'
                     'position_m = [0, 0, 0]\n[[imu]]\nname = "a"\n[effects]\ngravity = true\n')
    stats = tmp_path / "stats.json"
    before = time.time_ns()
    result = subprocess.run([sys.executable, "-m", "imu_emulator", "stream", str(scene), "--format", "mavlink-highres",
                             "--to", f"file:{tmp_path / 'out.bin'}", "--quiet", "--realtime", "off",
                             "--stats-json", str(stats)],
                            capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=scaled(300))
    after = time.time_ns()
    assert result.returncode == 0, result.stderr
    started = json.loads(stats.read_text())["started_unix_ns"]
    assert before < started < after
    # paced at 100 Hz for 1 s: the last sample's deadline, 0.99 s after the first, was before the process ended
    assert started + 0.99e9 < after


@pytest.mark.slow
@pytest.mark.skipif(not (os.environ.get("IMU_EMULATOR_ARDUCOPTER") and os.environ.get("IMU_EMULATOR_COPTER_PARM")),
                    reason="needs a built ArduPilot Copter SITL: IMU_EMULATOR_ARDUCOPTER (binary) and "
                           "IMU_EMULATOR_COPTER_PARM (Tools/autotest/default_params/copter.parm)")
@pytest.mark.parametrize("device", ["vn300", "gq7"])
def test_arducopter_sitl_arms_on_the_emulated_unit(tmp_path, device):
    out = tmp_path / "report"
    code = ardupilot_sitl_run.main(["--arducopter", os.environ["IMU_EMULATOR_ARDUCOPTER"],
                                    "--defaults", os.environ["IMU_EMULATOR_COPTER_PARM"], "--device", device,
                                    "--out", str(out)])
    assert code == 0
    text = (out / f"ardupilot-{device}.md").read_text()
    assert "- armed: never" not in text and "EKF healthy (attitude, velocity, absolute position flags; not " \
        "constant-position mode): never" not in text
    assert math.isfinite(float(text.split("| attitude error (rotation angle) | ")[1].split(" deg")[0]))
