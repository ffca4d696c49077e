"""Run ArduPilot Copter SITL with the emulator as its external AHRS (VN-300 or 3DM-GQ7 on a pty) or as its JSON
physics backend, watch it over MAVLink, and write a scenario report (issue 26).

    .venv/bin/python tools/interop/ardupilot_sitl_run.py --arducopter PATH/build/sitl/bin/arducopter \\
        --defaults PATH/Tools/autotest/default_params/copter.parm --device vn300 \\
        --scene examples/sitl_flight.toml --out docs/sitl

Build SITL per ArduPilot's own instructions (BUILD.md); this script builds nothing. What runs:
1. `imu-emulator stream SCENE` at wall-clock rate: on a pty (`--link WORK/device`) in the device's format
   (vn300: vectornav-binary model=VN-300-CR, which ArduPilot's driver configures; gq7: microstrain-mip
   preset=ardupilot), or for `json` to the `ardupilot:` target (UDP 9002).
2. arducopter --model quad (external AHRS: SITL still needs a physics model; the AHRS replaces its estimate) or
   --model JSON, --home at the scene's origin, --defaults COPTER_PARM,WORK/emulated.parm (ardupilot_params.py),
   --serialN=uart:WORK/device:BAUD (libraries/AP_HAL_SITL/UARTDriver.cpp: "uart:PATH:BAUD").
3. pymavlink on tcp:127.0.0.1:5760 records STATUSTEXT, SYS_STATUS (pre-arm bit), EKF_STATUS_REPORT, ATTITUDE and
   GLOBAL_POSITION_INT. Once ArduPilot is up ("ArduPilot Ready") it runs the simple accelerometer calibration the
   unit's new IMU needs; from ARM_FROM_S scene time on (or once the pre-arm checks pass) it asks to arm
   (STABILIZE, throttle low) every ARM_EVERY_S until armed: a refused request makes ArduPilot state why, and the
   report lists every pre-arm / arm failure text it gave.
4. The report: the stack's estimate against the scene's truth (sitl_report.py), docs/sitl/<stack>-<device>.md/png.

The scene's motion is scripted: SITL's own vehicle is not flown along it. With an external AHRS the attitude and
position ArduPilot reports are the unit's navigation solution as its driver read it (so the report checks the whole
path: wire format, driver, AHRS, telemetry, against the truth); with JSON they are ArduPilot's EKF3 run on the
emulator's IMU samples and the JSON position (SITL's simulated GPS and compass are made from it).
"""
from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import ardupilot_params  # noqa: E402
import sitl_report  # noqa: E402

REPO = HERE.parent.parent


def emulator_command(scene: Path, device: str, work: Path) -> list[str]:
    base = [sys.executable, "-m", "imu_emulator", "stream", str(scene), "--realtime", "off",
            "--stats-json", str(work / "stream.json")]
    if device == "json":
        return base + ["--format", "ardupilot-json", "--to", f"ardupilot:9002,record={work / 'servos.csv'}"]
    unit = ardupilot_params.DEVICES[device]
    return base + ["--format", unit.format, "--to", "pty", "--link", str(work / "device")] + \
        [arg for option in unit.options for arg in ("--option", option)]


def sitl_command(arducopter: Path, defaults: list[Path], device: str, work: Path, origin) -> list[str]:
    lat, lon, h = origin
    cmd = [str(arducopter), "--wipe", "--speedup", "1", "--home", f"{lat},{lon},{h},0",
           "--defaults", ",".join(str(p) for p in defaults)]
    if device == "json":
        return cmd + ["--model", "JSON:127.0.0.1"]
    return cmd + ["--model", "quad",
                  f"--serial{ardupilot_params.SERIAL_PORT}=uart:{work / 'device'}:{ardupilot_params.BAUD}"]


#: when the runner starts asking ArduPilot to arm (scene time, s; the scene's take-off is at 40 s) and how often
ARM_FROM_S, ARM_EVERY_S = 20.0, 10.0
#: the STATUSTEXT AP_Vehicle::setup sends once init_ardupilot is done (AP_Vehicle.cpp:529, 265753db8b)
READY_TEXT = "ArduPilot Ready"


load = sitl_report.load_ned_scene


def compass_offsets_mgauss(scene) -> tuple[float, float, float]:
    """The unit's compass calibration as ArduPilot's COMPASS_OFS_X/Y/Z: minus the first IMU's magnetometer hard
    iron (gauss -> milligauss); ArduPilot adds the offsets to the field (AP_Compass_Backend.cpp:84-85). The
    scene's sensor axes are the vehicle's (a mounting rotation would turn them: refused)."""
    imu = scene.imus[0]
    if any(imu.mounting_rpy_deg):
        raise SystemExit(f"IMU {imu.name!r}: mounted rotated {imu.mounting_rpy_deg} deg; the compass calibration "
                         "written for ArduPilot assumes sensor axes = body axes")
    hard_iron = imu.companions.get("magnetometer", {}).get("hard_iron", (0.0, 0.0, 0.0))
    return tuple(-1000.0 * float(h) for h in hard_iron)


scene_truth = sitl_report.scene_truth


class Recorder(sitl_report.Recorder):
    KINDS = ("ATTITUDE", "GLOBAL_POSITION_INT", "EKF_STATUS_REPORT", "SYS_STATUS", "STATUSTEXT", "HEARTBEAT",
             "COMMAND_ACK")


#: the windows the stack's clock is mapped to the wall clock in (sitl_report.wall_to_scene): short, since SITL's
#: clock drifts from the wall clock as fast as the machine's load changes; long enough to hold many ATTITUDE and
#: GLOBAL_POSITION_INT messages (25 and 10 Hz requested below), some of them delivered at once
CLOCK_WINDOW_S = 2.0

#: how many times the simple accel cal is asked for when ArduPilot does not accept it, how long after a refusal,
#: and how long an unanswered request may hold arming back (the calibration itself takes ~1-10 s,
#: AP_InertialSensor.cpp:2593-2596)
CAL_TRIES, CAL_RETRY_S, CAL_SETTLE_S = 3, 6.0, 30.0


def calibrate(link, requests: list) -> None:
    """The simple accelerometer calibration (MAV_CMD_PREFLIGHT_CALIBRATION param5 = 4, GCS_Common.cpp:4873-4875)."""
    from pymavlink import mavutil
    requests.append(time.time())
    link.mav.command_long_send(link.target_system, link.target_component,
                               mavutil.mavlink.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 0, 4, 0, 0)


class Sequence:
    """When the runner asks for the accel cal again and when it asks to arm (times in seconds, one clock).

    A refused calibration is asked for again CAL_RETRY_S later (simple_accel_cal refuses a request within 5 s of
    the last, AP_InertialSensor.cpp:2535), at most CAL_TRIES requests. Arming waits until the calibration is
    settled: taken, refused CAL_TRIES times, or unanswered for CAL_SETTLE_S (an armed vehicle refuses it:
    GCS_Common.cpp:4903-4906). Then it is asked for once the pre-arm checks pass or from ARM_FROM_S after the
    stream started, every ARM_EVERY_S until armed."""

    def __init__(self, calibrating: bool, stream_started: float):
        self.settled, self.stream_started = not calibrating, stream_started
        self.cal_sent, self.retry_at, self.last_arm = [], None, None

    def calibration_sent(self, now: float) -> None:
        self.cal_sent.append(now)
        self.retry_at = None

    def calibration_answer(self, accepted: bool, now: float) -> None:
        if accepted or len(self.cal_sent) >= CAL_TRIES:
            self.settled, self.retry_at = True, None
        else:
            self.retry_at = now + CAL_RETRY_S

    def calibration_due(self, now: float) -> bool:
        return self.retry_at is not None and now >= self.retry_at

    def arm_due(self, now: float, prearm_passed: bool) -> bool:
        if not self.settled and self.retry_at is None and self.cal_sent and now - self.cal_sent[-1] > CAL_SETTLE_S:
            self.settled = True
        if not self.settled or not (prearm_passed or now - self.stream_started >= ARM_FROM_S):
            return False
        return self.last_arm is None or now - self.last_arm >= ARM_EVERY_S

    def arm_sent(self, now: float) -> None:
        self.last_arm = now


def receive(link, rec: Recorder):
    """The next message (None after half a second without one) and its wall receive time, recorded; STATUSTEXT
    printed as it comes."""
    msg = link.recv_match(blocking=True, timeout=0.5)
    received = time.time()
    if msg is not None:
        rec.add(msg, received)
        if msg.get_type() == "STATUSTEXT":
            print(f"SITL: {msg.text}", flush=True)
    return msg, received


def wait_until_ready(link, rec: Recorder, seconds: float = 120.0) -> float:
    """Record messages until ArduPilot has finished initialising; returns the wall time it said so.

    Until then a command may run inside init: MAVLink is served from the delay callback of whatever init step
    is waiting (AP_Vehicle::scheduler_delay_callback -> GCS::update_receive), e.g. AP_Baro::calibrate's delays
    (AP_Baro.cpp:330), before ins.init (ArduCopter/system.cpp:138 then 219). A simple accel cal taken there waits
    in AP_InertialSensor::wait_for_sample for a sample no IMU can give yet (AP_InertialSensor.cpp:2109-2117), and
    ArduPilot stays at "Calibrating barometer" for good: the GQ7 run of 2026-12-01, whose driver spends 5 s in
    its constructor first (AP_ExternalAHRS_MicroStrain7.cpp:75), took the runner's calibration request (sent a
    fixed 5 s after connecting) there. Ready = the READY_TEXT STATUSTEXT, or an ATTITUDE, which is sent only
    from the main loop (GCS_MAVLINK::should_send_message_in_delay_callback, GCS_Common.cpp:1218-1233)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        msg, received = receive(link, rec)
        if msg is None:
            continue
        if (msg.get_type() == "STATUSTEXT" and msg.text == READY_TEXT) or msg.get_type() == "ATTITUDE":
            return received
    last = rec.texts()[-1][1] if rec.rows["STATUSTEXT"] else "no STATUSTEXT at all"
    raise SystemExit(f"ArduPilot did not finish initialising within {seconds:.0f} s (last text: {last!r})")


def wait_for(path: Path, seconds: float, proc: subprocess.Popen, what: str) -> None:
    end = time.monotonic() + seconds
    while not path.exists():
        if proc.poll() is not None:
            raise SystemExit(f"{what} ended (exit {proc.returncode}) before {path} appeared")
        if time.monotonic() > end:
            raise SystemExit(f"{what}: {path} did not appear within {seconds:.0f} s")
        time.sleep(0.1)


def connect(sitl: subprocess.Popen, work: Path, seconds: float = 90.0):
    """SITL's MAVLink on TCP 5760 (SERIAL0), once it listens; a SITL that exits first is named with its log."""
    from pymavlink import mavutil
    end = time.monotonic() + seconds
    while True:
        if sitl.poll() is not None:
            raise SystemExit(f"arducopter exited (code {sitl.returncode}) before its MAVLink port came up: "
                             f"see {work / 'sitl.log'}")
        try:
            link = mavutil.mavlink_connection("tcp:127.0.0.1:5760", source_system=255, retries=0)
            if link.wait_heartbeat(timeout=30) is not None:
                return link
        except OSError:
            pass
        if time.monotonic() > end:
            raise SystemExit(f"no MAVLink heartbeat on tcp:127.0.0.1:5760 within {seconds:.0f} s: see "
                             f"{work / 'sitl.log'}")
        time.sleep(1.0)


def run(args) -> dict:
    from pymavlink import mavutil
    work = Path(tempfile.mkdtemp(prefix=f"sitl-{args.device}-"))
    scene = load(args.scene)
    truth = scene_truth(scene)
    duration = float(truth.t[-1] - truth.t[0])
    offsets = compass_offsets_mgauss(scene) if args.device != "json" else None
    try:
        params = {**ardupilot_params.device_params(args.device, sensors=args.sensors, compass_offsets_mgauss=offsets,
                                                   json_imu_hz=scene.rate_hz),
                  **dict(args.param)}
    except ValueError as exc:
        raise SystemExit(f"{args.scene}: {exc}") from None
    parm = ardupilot_params.write_params(work / "emulated.parm", params)
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    emu_cmd = emulator_command(args.scene, args.device, work)
    sitl_cmd = sitl_command(args.arducopter, [args.defaults, parm], args.device, work, truth.origin)
    emu_log, sitl_log = open(work / "stream.log", "w"), open(work / "sitl.log", "w")
    emu = subprocess.Popen(emu_cmd, stdout=emu_log, stderr=subprocess.STDOUT, env=env, cwd=REPO)
    emu_started = time.time()      # ARM_FROM_S counts from here (the stream's own first deadline comes a bit later)
    sitl = None
    rec = Recorder()
    armed_at = disarmed_at = None
    arm_requests, cal_requests = [], []
    try:
        if args.device != "json":
            wait_for(work / "device", 120, emu, "imu-emulator stream")
        sitl = subprocess.Popen(sitl_cmd, stdout=sitl_log, stderr=subprocess.STDOUT, cwd=work)
        link = connect(sitl, work)
        for msg_id, hz in ((30, 25), (33, 10), (193, 5), (1, 2)):   # ATTITUDE, GLOBAL_POSITION_INT, EKF_STATUS, SYS
            link.mav.command_long_send(link.target_system, link.target_component,
                                       mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, 1e6 / hz, 0, 0, 0, 0, 0)
        wait_until_ready(link, rec)
        steps = Sequence(calibrating=args.device != "json", stream_started=emu_started)
        if args.device != "json":
            # The unit's IMU is a new accelerometer to ArduPilot, never calibrated: ArduPilot's own test of these
            # drivers (Tools/autotest/arduplane.py fly_external_AHRS) runs the simple accel cal (param5 = 4)
            # once the vehicle is up, before waiting for the pre-arm checks; so does this.
            calibrate(link, cal_requests)
            steps.calibration_sent(cal_requests[-1])
        end = time.monotonic() + duration + 5
        while time.monotonic() < end and emu.poll() is None and sitl.poll() is None:
            msg, now = receive(link, rec)
            if msg is None:
                continue
            if msg.get_type() == "COMMAND_ACK":
                print(f"COMMAND_ACK {msg.command} result {msg.result}", flush=True)
                if msg.command == mavutil.mavlink.MAV_CMD_PREFLIGHT_CALIBRATION:
                    steps.calibration_answer(msg.result == mavutil.mavlink.MAV_RESULT_ACCEPTED, now)
            if steps.calibration_due(now):
                calibrate(link, cal_requests)
                steps.calibration_sent(cal_requests[-1])
            if msg.get_type() == "HEARTBEAT" and msg.get_srcSystem() == link.target_system:
                armed = bool(msg.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                if armed and armed_at is None:
                    armed_at = now
                    print("armed", flush=True)
                elif not armed and armed_at is not None and disarmed_at is None:
                    disarmed_at = now
                    print("disarmed", flush=True)
            prearm = any(r["onboard_control_sensors_health"] & sitl_report.PREARM_CHECK
                         for _, r in rec.rows["SYS_STATUS"][-1:])
            if args.arm and armed_at is None and steps.arm_due(now, prearm):
                steps.arm_sent(now)
                arm_requests.append(now)
                link.set_mode("STABILIZE")
                link.mav.command_long_send(link.target_system, link.target_component,
                                           mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    finally:
        for proc in (sitl, emu):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGINT if proc is emu else signal.SIGTERM)
        sitl_report.reap((sitl, emu))
        emu_log.close()
        sitl_log.close()
    stream = sitl_report.keep_records(work, rec.rows)
    return {"work": work, "rec": rec, "stream": stream, "truth": truth, "armed_at": armed_at,
            "disarmed_at": disarmed_at, "arm_requests": arm_requests, "cal_requests": cal_requests,
            "commands": [emu_cmd, sitl_cmd],
            "params": params}


def estimates(rec: Recorder, started_s: float) -> sitl_report.Estimates:
    import numpy as np

    def series(kind, keys):
        rows = rec.rows[kind]
        if not rows:
            return np.zeros(0), np.zeros((0, len(keys)))
        boot = np.array([r["time_boot_ms"] for _, r in rows]) / 1e3
        t = sitl_report.wall_to_scene(boot, np.array([w for w, _ in rows]), started_s, window_s=CLOCK_WINDOW_S)
        return t, np.array([[r[k] for k in keys] for _, r in rows], dtype=float)

    ta, att = series("ATTITUDE", ("roll", "pitch", "yaw"))
    tp, pos = series("GLOBAL_POSITION_INT", ("lat", "lon", "alt", "vx", "vy", "vz"))
    ekf = rec.rows["EKF_STATUS_REPORT"]
    sys_status = rec.rows["SYS_STATUS"]
    return sitl_report.Estimates(
        attitude_t=ta, euler=att, position_t=tp,
        lat_lon_alt=np.column_stack([pos[:, 0] / 1e7, pos[:, 1] / 1e7, pos[:, 2] / 1e3]) if len(tp) else
        np.zeros((0, 3)),
        velocity_ned=pos[:, 3:6] / 100.0 if len(tp) else np.zeros((0, 3)),
        # these carry no time stamp of their own: their receive time (a delay of milliseconds is no matter here)
        ekf_t=np.array([w for w, _ in ekf]) - started_s, ekf_flags=np.array([r["flags"] for _, r in ekf]),
        prearm_t=np.array([w for w, _ in sys_status]) - started_s,
        prearm_ok=np.array([bool(r["onboard_control_sensors_health"] & sitl_report.PREARM_CHECK)
                            for _, r in sys_status]))


def write_report(out: Path, args, outcome: dict, ardupilot_commit: str) -> Path:
    from imu_emulator.output.atomic import save_figure, write_text
    rec, truth = outcome["rec"], outcome["truth"]
    started_ns = outcome["stream"].get("started_unix_ns")
    if not started_ns:
        raise SystemExit(f"the stream wrote no started_unix_ns (see {outcome['work'] / 'stream.log'})")
    started = started_ns / 1e9
    est = estimates(rec, started)
    result = sitl_report.compare(est, truth)
    name = f"ardupilot-{args.device}"
    title = f"ArduPilot Copter SITL ({ardupilot_commit}) with {args.device}: {args.scene.name}"
    fig = sitl_report.plot(result, title)
    out.mkdir(parents=True, exist_ok=True)
    save_figure(fig, out / f"{name}.png", dpi=90)
    texts = [r["text"] for _, r in rec.rows["STATUSTEXT"]]
    armed = f"{outcome['armed_at'] - started:.1f} s" if outcome["armed_at"] else "never"
    if outcome.get("disarmed_at"):
        armed += f", disarmed at {outcome['disarmed_at'] - started:.1f} s"
    failures = sitl_report.failure_summary([w - started for w, _ in rec.texts()], texts)
    requests = outcome.get("arm_requests", [])
    # the answers to the arm requests, named by pymavlink's MAV_RESULT table
    from pymavlink.dialects.v20 import ardupilotmega as mav
    def answers(command):
        return ", ".join(mav.enums["MAV_RESULT"][r["result"]].name for _, r in rec.rows["COMMAND_ACK"]
                         if r["command"] == command) or "none"

    def when(x):
        return f"{x:.1f} s" if x is not None else "never"
    what = ("the unit's navigation solution as ArduPilot's driver read it (AHRS_EKF_TYPE 11)" if args.device != "json"
            else "ArduPilot's EKF3 on the emulator's IMU samples and JSON position")
    text = f"""# {title}

What is compared: ArduPilot's ATTITUDE and GLOBAL_POSITION_INT, i.e. {what}, against the scene's truth at the
same scene time (ATTITUDE / GLOBAL_POSITION_INT time_boot_ms mapped to the wall clock by the quickest delivery in
each {CLOCK_WINDOW_S:g} s window, then to scene time by the stream's `started_unix_ns`). SITL's own vehicle is not
flown along the scene: the motion is scripted. Statistics count from the first healthy EKF_STATUS_REPORT on.

- pre-arm checks passed (SYS_STATUS pre-arm bit first set): {when(result['prearm_passed_s'])} scene time
- EKF healthy (attitude, velocity, absolute position flags; not constant-position mode): {when(result['ekf_healthy_s'])}
- armed: {armed}
- simple accelerometer calibration requests: {len(outcome.get('cal_requests', []))}; answers: \
{answers(mav.MAV_CMD_PREFLIGHT_CALIBRATION)}
- arm requests: {len(requests)}{' (first at ' + when(requests[0] - started) + ')' if requests else ''}; \
answers: {answers(mav.MAV_CMD_COMPONENT_ARM_DISARM)}
- emulator stream: {outcome['stream'].get('samples', 0)} samples, dropped {outcome['stream'].get('dropped', '?')}

{sitl_report.markdown_table(result)}

Pre-arm and arm failures ArduPilot stated (scene time):

{sitl_report.failure_table(failures)}

![errors]({name}.png)

Commands (ArduPilot at {ardupilot_commit}, its Copter SITL built per its own BUILD.md):

"""
    said = "Parameters written for SITL: " + ", ".join(f"{k}={v}" for k, v in outcome["params"].items())
    text += sitl_report.report_tail(outcome["commands"], said, texts)
    write_text(out / f"{name}.md", text)
    return out / f"{name}.md"


_param = sitl_report.param_option(ardupilot_params.param_text)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--arducopter", type=Path, required=True, help="a built Copter SITL binary")
    p.add_argument("--defaults", type=Path, required=True,
                   help="ArduPilot's Tools/autotest/default_params/copter.parm (or your own defaults)")
    p.add_argument("--device", choices=sorted(ardupilot_params.DEVICES) + ["json"], required=True)
    p.add_argument("--scene", type=Path, default=REPO / "examples" / "sitl_flight.toml")
    p.add_argument("--out", type=Path, default=REPO / "docs" / "sitl")
    p.add_argument("--no-arm", dest="arm", action="store_false", help="only watch, never arm")
    p.add_argument("--ardupilot-commit", default="unknown", help="written in the report")
    p.add_argument("--sensors", default="all",
                   help="the unit's sensors ArduPilot registers (EAHRS_SENSORS): all, or some of gps,imu,baro,compass; "
                        "the others stay SITL's own simulated ones")
    p.add_argument("--param", action="append", default=[], type=_param, metavar="NAME=VALUE",
                   help="one more SITL parameter (after the device's), repeatable")
    args = p.parse_args(argv)
    for path in (args.arducopter, args.defaults, args.scene):
        if not path.is_file():
            p.error(f"{path}: no such file")
    outcome = run(args)
    report = write_report(args.out, args, outcome, args.ardupilot_commit)
    print(f"report: {report} (work files in {outcome['work']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
