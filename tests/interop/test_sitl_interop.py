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

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

ORIGIN = (-35.363262, 149.165237, 584.0)


OFFSETS = (-40.0, 25.0, -60.0)


@pytest.mark.parametrize("device", ["vn300", "gq7", "json"])
def test_defaults_file_reads_back_with_pymavlink(tmp_path, device):
    params = ardupilot_params.device_params(device, compass_offsets_mgauss=None if device == "json" else OFFSETS,
                                            json_imu_hz=200.0)
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
        # the unit's sensors the only ones: SITL.cpp SIM_IMU_COUNT / SIM_BARO_COUNT, SIM_MAG1..6_DEVID (the
        # simulated compasses with non-zero default dev ids, SITL.cpp:777-809)
        assert params["SIM_IMU_COUNT"] == 0 and params["SIM_BARO_COUNT"] == 0
        assert [params[f"SIM_MAG{i}_DEVID"] for i in range(1, 7)] == [0] * 6
        assert (params["COMPASS_OFS_X"], params["COMPASS_OFS_Y"], params["COMPASS_OFS_Z"]) == OFFSETS
        assert params["COMPASS_DEV_ID"] == params["COMPASS_PRIO1_ID"] == _bus_id_by_c_layout(6, 4, 0, 0)
        # the main loop waits for the unit's IMU: half its rate, at least ArduPilot's 50 Hz floor; VN-300 at
        # 100 Hz as EAHRS_RATE asks it (400 / divisor 4), GQ7 at the preset's 50 Hz
        assert params["SCHED_LOOP_RATE"] == 50
        assert [params[f"INS_ACC{n}{k}_{a}"] for n in (2, 3) for k in ("OFFS", "SCAL") for a in "XYZ"] == [0] * 12
        assert params.get("EAHRS_RATE") == {"vn300": 100, "gq7": None}[device]


def test_json_backend_has_one_sitl_imu_paced_by_the_scene_without_sitl_drift():
    """The parameters the 2026-12-02 JSON run needed by hand (docs/sitl/README.md), now the runner's: a 200 Hz
    scene gives a 100 Hz loop (ArduPilot wants 1.8 gyro samples per loop, AP_InertialSensor.cpp:1480), one SITL
    IMU, no calibration values for IMUs 2 and 3, SITL's gyro drift off (AP_InertialSensor_SITL.cpp:215-219)."""
    params = ardupilot_params.device_params("json", json_imu_hz=200.0)
    assert params["SCHED_LOOP_RATE"] == 100 and params["SCHED_LOOP_RATE"] * 1.8 <= 200
    assert params["SIM_IMU_COUNT"] == 1 and params["SIM_DRIFT_SPEED"] == 0
    assert [params[f"INS_ACC{n}{k}_{a}"] for n in (2, 3) for k in ("OFFS", "SCAL") for a in "XYZ"] == [0] * 12
    assert "EAHRS_TYPE" not in params and "AHRS_EKF_TYPE" not in params      # SITL's own EKF3
    assert ardupilot_params.device_params("json", json_imu_hz=1000.0)["SCHED_LOOP_RATE"] == 500
    for rate, says in ((None, "json_imu_hz"), (90.0, "100 Hz or more"), (9000.0, "50-2000 Hz")):
        with pytest.raises(ValueError, match=says):
            ardupilot_params.device_params("json", json_imu_hz=rate)


def _bus_id_by_c_layout(bus_type, bus, address, devtype):
    """AP_HAL::Device's DeviceId union (libraries/AP_HAL/Device.h:371-381, ArduPilot 265753db8b) laid out by ctypes
    as the C compiler lays out the bitfields: enum BusType bus_type:3; uint8_t bus:5; uint8_t address, devtype."""
    import ctypes

    class DeviceStructure(ctypes.LittleEndianStructure):
        _fields_ = [("bus_type", ctypes.c_uint8, 3), ("bus", ctypes.c_uint8, 5), ("address", ctypes.c_uint8),
                    ("devtype", ctypes.c_uint8)]

    class DeviceId(ctypes.Union):
        _fields_ = [("devid_s", DeviceStructure), ("devid", ctypes.c_uint32)]
    d = DeviceId()
    d.devid_s.bus_type, d.devid_s.bus, d.devid_s.address, d.devid_s.devtype = bus_type, bus, address, devtype
    return d.devid


@pytest.mark.parametrize("port, address, devtype", [(4, 0, 0), (4, 1, 0x31), (31, 255, 255), (0, 0, 0)])
def test_serial_bus_id_is_make_bus_id(port, address, devtype):
    """AP_HAL::Device::make_bus_id (Device.cpp:222-229) with BUS_TYPE_SERIAL = 6 (Device.h:42)."""
    assert ardupilot_params.serial_bus_id(port, address, devtype) == _bus_id_by_c_layout(6, port, address, devtype)
    with pytest.raises(ValueError, match="out of range"):
        ardupilot_params.serial_bus_id(32)


def test_only_the_units_registered_sensors_replace_sitls():
    """A sensor the unit does not register (EAHRS_SENSORS) stays SITL's simulated one: removing it would leave
    ArduPilot without any."""
    gps_only = ardupilot_params.device_params("vn300", sensors="gps")
    assert not {"SIM_IMU_COUNT", "SIM_BARO_COUNT", "SIM_MAG1_DEVID", "SCHED_LOOP_RATE", "COMPASS_OFS_X"} & set(gps_only)
    imu_baro = ardupilot_params.device_params("gq7", sensors="imu,baro")
    assert imu_baro["SIM_IMU_COUNT"] == 0 and imu_baro["SIM_BARO_COUNT"] == 0 and "SIM_MAG1_DEVID" not in imu_baro
    with pytest.raises(ValueError, match="uncalibrated"):
        ardupilot_params.device_params("vn300", compass_offsets_mgauss=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="compass_offsets_mgauss"):
        ardupilot_params.device_params("vn300")
    with pytest.raises(ValueError, match="SCHED_LOOP_RATE"):
        ardupilot_params.sole_sensor_params(2, 4, 25.0, OFFSETS)
    assert ardupilot_params.sole_sensor_params(2, 4, 400.0, OFFSETS)["SCHED_LOOP_RATE"] == 200


def test_compass_calibration_is_minus_the_scenes_hard_iron():
    import tomllib
    path = ROOT / "examples" / "sitl_flight.toml"
    hard_iron = tomllib.loads(path.read_text())["imu"][0]["magnetometer"]["hard_iron"]
    offsets = ardupilot_sitl_run.compass_offsets_mgauss(ardupilot_sitl_run.load(path))
    assert offsets == pytest.approx([-1000.0 * h for h in hard_iron], abs=1e-9)


def test_the_flight_scene_is_at_rest_where_it_says_and_follows_its_curves():
    """The emulator's own truth of examples/sitl_flight.toml: at rest on the ground (0-40 s) and at the end (290-300
    s), holding 10 m in the hovers, and on the closed-form figure eight and climb between the waypoints (its first
    version's spline rang: 2.9 m up and 0.7 m/s on the ground, which PX4's EKF2 took for a drifting GNSS)."""
    import importlib.util
    truth = ardupilot_sitl_run.scene_truth(ardupilot_sitl_run.load(ROOT / "examples" / "sitl_flight.toml"))
    t, pos, vel = truth.t, truth.position_ned, truth.velocity_ned
    for lo, hi, down in ((0, 40, 0.0), (52.5, 60, -10.0), (270.5, 274, -10.0), (290, 300.1, 0.0)):
        held = (t >= lo) & (t < hi)
        assert np.abs(pos[held] - [0.0, 0.0, down]).max() < 0.005, (lo, hi)
        assert np.abs(vel[held]).max() < 0.005, (lo, hi)
    # between the waypoints (every 0.5 s) the truth stays on the curves they were sampled from
    spec = importlib.util.spec_from_file_location("sitl_flight_waypoints",
                                                  ROOT / "tools" / "interop" / "sitl_flight_waypoints.py")
    curves = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(curves)
    between = np.arange(40.25, 290, 0.5)
    at = np.searchsorted(t, between)
    expected = np.array([curves.position(x) for x in t[at]])
    assert np.abs(pos[at] - expected).max() < 0.02
    # and the scene holds what the generator writes
    import tomllib
    written = tomllib.loads((ROOT / "examples" / "sitl_flight.toml").read_text())["trajectory"]
    times, positions, attitudes, _ = curves.waypoints()
    assert np.array_equal(written["times_s"], times)
    assert np.abs(np.array(written["positions_m"]) - positions).max() < 1e-3
    assert np.abs(np.array(written["attitudes_deg"]) - attitudes).max() < 1e-2


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


class _ScriptedLink:
    """pymavlink messages in the order a SITL sends them, then nothing (recv_match's timeout answer)."""

    def __init__(self, messages):
        self.messages = list(messages)
        self.taken = 0

    def recv_match(self, blocking=True, timeout=None):
        if self.taken < len(self.messages):
            self.taken += 1
            return self.messages[self.taken - 1]
        return None


def _statustext(text):
    from pymavlink.dialects.v20 import ardupilotmega as m
    return m.MAVLink_statustext_message(6, text.encode())


def test_calibration_waits_for_the_end_of_ardupilots_init():
    """The GQ7 run of 2026-12-01 hung at "Calibrating barometer": the accel-cal request, sent during init, ran from
    AP_Baro::calibrate's delay callback before any IMU existed. The runner now waits for the text AP_Vehicle::setup
    sends when init is over ("ArduPilot Ready", AP_Vehicle.cpp:529 at 265753db8b) or an ATTITUDE (main loop only,
    GCS_Common.cpp:1218-1233); the messages before it are kept."""
    from pymavlink.dialects.v20 import ardupilotmega as m
    boot = [_statustext("MicroStrain7 ExternalAHRS: initialised."), _statustext("Calibrating barometer"),
            m.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3), _statustext("Barometer 1 calibration complete")]
    after = [_statustext("GPS 1: detected ExternalAHRS"), m.MAVLink_attitude_message(1, 0, 0, 0, 0, 0, 0)]
    link = _ScriptedLink(boot + [_statustext("ArduPilot Ready")] + after)
    rec = ardupilot_sitl_run.Recorder()
    ardupilot_sitl_run.wait_until_ready(link, rec, seconds=5)
    assert link.taken == len(boot) + 1
    assert [t for _, t in rec.texts()] == ["MicroStrain7 ExternalAHRS: initialised.", "Calibrating barometer",
                                           "Barometer 1 calibration complete", "ArduPilot Ready"]
    link = _ScriptedLink(boot + after)                      # the text missed: the first ATTITUDE ends the wait
    ardupilot_sitl_run.wait_until_ready(link, ardupilot_sitl_run.Recorder(), seconds=5)
    assert link.taken == len(boot) + 2
    with pytest.raises(SystemExit, match="'Calibrating barometer'"):
        ardupilot_sitl_run.wait_until_ready(_ScriptedLink(boot[:3]), ardupilot_sitl_run.Recorder(), seconds=1.5)


def test_calibration_is_retried_and_settled_before_arming():
    """The VN-300 run of 2026-12-02 had its first accel-cal request refused (TEMPORARILY_REJECTED) and armed before
    the retry, which the armed vehicle then refused ("Disarm to allow calibration", GCS_Common.cpp:4903-4906).
    Now: a refusal is retried CAL_RETRY_S later, arming waits until the calibration is taken, refused CAL_TRIES
    times or unanswered for CAL_SETTLE_S, then comes once the pre-arm checks pass (or from ARM_FROM_S) every
    ARM_EVERY_S."""
    run = ardupilot_sitl_run
    steps = run.Sequence(calibrating=True, stream_started=0.0)
    steps.calibration_sent(10.0)
    steps.calibration_answer(False, 10.5)                       # refused
    assert not steps.calibration_due(10.5 + run.CAL_RETRY_S - 0.01) and steps.calibration_due(10.5 + run.CAL_RETRY_S)
    assert not steps.arm_due(12.0, prearm_passed=True)           # the pre-arm checks pass: still not before the cal
    steps.calibration_sent(16.5)
    steps.calibration_answer(True, 18.0)                        # taken
    assert not steps.calibration_due(100.0)
    assert not steps.arm_due(18.0, prearm_passed=False)          # neither pre-arm nor ARM_FROM_S yet
    assert steps.arm_due(18.0, prearm_passed=True)
    steps.arm_sent(18.0)
    assert not steps.arm_due(18.0 + run.ARM_EVERY_S - 0.01, prearm_passed=True)
    assert steps.arm_due(18.0 + run.ARM_EVERY_S, prearm_passed=False)   # past ARM_FROM_S: asked anyway

    refused = run.Sequence(calibrating=True, stream_started=0.0)
    for k in range(run.CAL_TRIES):
        refused.calibration_sent(10.0 * k)
        refused.calibration_answer(False, 10.0 * k + 1)
    assert not refused.calibration_due(1000.0) and refused.arm_due(run.ARM_FROM_S + 30, prearm_passed=False)

    silent = run.Sequence(calibrating=True, stream_started=0.0)
    silent.calibration_sent(5.0)
    assert not silent.arm_due(5.0 + run.CAL_SETTLE_S, prearm_passed=True)
    assert silent.arm_due(5.0 + run.CAL_SETTLE_S + 0.01, prearm_passed=True)
    assert run.Sequence(calibrating=False, stream_started=0.0).arm_due(run.ARM_FROM_S, prearm_passed=False)


def test_failure_summary_groups_each_check_across_its_numbers():
    texts = ["EKF3 IMU0 initialised", "PreArm: Gyros not healthy", "PreArm: Main loop slow (284Hz < 400Hz)",
             "PreArm: Gyros not healthy", "Arm: Gyros not healthy", "PreArm: Main loop slow (281Hz < 400Hz)",
             "PreArm: Compass not calibrated", "Barometer 1 calibration complete"]
    rows = sitl_report.failure_summary([1.0, 2.0, 2.5, 32.0, 35.0, 62.5, 63.0, 70.0], texts)
    assert [(r["check"], r["count"], r["first"], r["last"], r["example"]) for r in rows] == [
        ("Gyros not healthy", 3, 2.0, 35.0, "Arm: Gyros not healthy"),
        ("Main loop slow (#Hz < #Hz)", 2, 2.5, 62.5, "PreArm: Main loop slow (281Hz < 400Hz)"),
        ("Compass not calibrated", 1, 63.0, 63.0, "PreArm: Compass not calibrated")]
    assert sitl_report.failure_table([]) == "No pre-arm or arm failure was reported."


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
    rec.add(m.MAVLink_statustext_message(3, b"PreArm: Compass not calibrated"), started + 2)
    rec.add(m.MAVLink_command_ack_message(m.MAV_CMD_COMPONENT_ARM_DISARM, m.MAV_RESULT_FAILED), started + 4)
    rec.add(m.MAVLink_command_ack_message(m.MAV_CMD_COMPONENT_ARM_DISARM, m.MAV_RESULT_ACCEPTED), started + 6.9)
    outcome = {"work": tmp_path, "rec": rec, "truth": truth, "armed_at": started + 7.0,
               "arm_requests": [started + 4, started + 6.9],
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
    assert "- arm requests: 2 (first at 4.0 s); answers: MAV_RESULT_FAILED, MAV_RESULT_ACCEPTED" in text
    assert "| PreArm: Compass not calibrated | 1 | 2.0 | 2.0 |" in text


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


def test_stack_clock_running_slow_maps_to_the_wall_clock():
    """SITL on a loaded machine: its clock runs at 80 % of the wall clock (received = 1000 + boot / 0.8 + delay),
    the delay zero now and then (every 5th message at 25 Hz, several per 2 s window). Lag is linear in boot time,
    so the envelope through each window's quickest message, anchored where it occurs, is exact: scene time =
    boot / 0.8 + 1000 - start. (Anchored at window middles it would be up to 0.25 s off: a quarter of the lag's
    growth over a window.)"""
    rng = np.random.default_rng(2)
    boot = np.arange(0.0, 60.0, 0.04)
    delay = rng.uniform(0.002, 0.05, boot.size)
    delay[::5] = 0.0
    started = 1003.0
    scene_t = sitl_report.wall_to_scene(boot, 1000.0 + boot / 0.8 + delay, started, window_s=2.0)
    np.testing.assert_allclose(scene_t, boot / 0.8 + 1000.0 - started, atol=1e-9)


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
