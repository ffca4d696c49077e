"""Run PX4 SITL with the emulator as its simulator (HIL_SENSOR + HIL_GPS over simulator_mavlink's TCP link, in
lockstep), watch it over MAVLink, arm it, and write a scenario report (issue 26).

    .venv/bin/python tools/interop/px4_sitl_run.py --px4-build PX4/build/px4_sitl_default \\
        --scene examples/sitl_flight.toml --out docs/sitl --px4-commit bb59c637cd

Build PX4 SITL per PX4's own instructions (`make px4_sitl_default`); this script builds nothing. What runs:
1. The scene rewritten at PX4's IMU rate (rate_hz = 250: px4-rc.simulator sets IMU_INTEG_RATE 250) into the work
   directory, then `imu-emulator stream SCENE --format mavlink-hil-sensor --option also=mavlink-hil-gps
   --to px4:4560,record=WORK/actuators.csv --speed 0` (docs/hil.md): PX4's clock is the HIL_SENSOR stamps.
2. `px4 -d -w WORK/rootfs BUILD/etc` with PX4_SYS_AUTOSTART=10016 (none_iris: rcS starts simulator_mavlink,
   which connects to TCP 4560) and the parameters of PARAMS as PX4_PARAM_<name> (rcS sets each after the airframe).
3. pymavlink on udpin:127.0.0.1:14550 (px4-rc.mavlink's GCS link, UDP 18570 -> 14550) sends a GCS HEARTBEAT each
   second, records STATUSTEXT, SYS_STATUS (pre-arm bit), ESTIMATOR_STATUS, ATTITUDE, GLOBAL_POSITION_INT,
   LOCAL_POSITION_NED, HEARTBEAT and COMMAND_ACK; from ARM_FROM_S scene time on (or once SYS_STATUS says the
   pre-arm checks pass) it asks for Hold (AUTO.LOITER, which needs no stick input) and to arm, every ARM_EVERY_S
   until armed: a refused request makes PX4 state why ("Preflight Fail: ...", "Arming denied: ...").
4. The report: EKF2's estimate against the scene's truth (sitl_report.py), docs/sitl/px4-hil.md and .png.

The scene's motion is scripted: PX4's actuator outputs are recorded, never obeyed. The attitude and position PX4
reports are EKF2 run on the emulator's IMU, magnetometer, barometer and GNSS.
"""
from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import sitl_report  # noqa: E402

REPO = HERE.parent.parent

#: PX4's simulator interface expects IMU data at 250 Hz (px4-rc.simulator: param set-default IMU_INTEG_RATE 250)
PX4_RATE_HZ = 250.0
#: none_iris (ROMFS/px4fmu_common/init.d-posix/airframes/10016_none_iris), as simulator_mavlink's CMakeLists.txt
#: none_iris target launches it (PX4_SYS_AUTOSTART=10016)
AUTOSTART = 10016
SIM_PORT, GCS_PORT = 4560, 14550

# PX4 custom modes (src/modules/commander/px4_custom_mode.h:44-67, PX4 bb59c637cd): main AUTO = 4, sub LOITER = 3
PX4_MAIN_AUTO, PX4_SUB_AUTO_LOITER = 4, 3
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1

#: when the runner starts asking PX4 to arm (scene time, s; take-off is at 40 s) and how often
ARM_FROM_S, ARM_EVERY_S = 20.0, 10.0


def params(scene) -> dict[str, float]:
    """What PX4 is given, and why (paths in PX4-Autopilot at bb59c637cd).

    - CAL_MAG0_XOFF/YOFF/ZOFF: the installation's hard iron. PX4 corrects a magnetometer as
      scale * (raw - offset) (src/lib/sensor_calibration/Magnetometer.hpp:100), so offset = +hard iron, gauss
      (CAL_MAG${i}_XOFF, src/modules/sensors/module.yaml:455); rcS already sets CAL_MAG0_ID 197388, the id of
      simulator_mavlink's first magnetometer (SimulatorMavlink.hpp:197-200).
    - SENS_GPS0_DELAY: the scene's GNSS latency, ms (SENS_GPS${i}_DELAY, src/modules/sensors/vehicle_gps_position/
      module.yaml:114; px4-rc.mavlinksim sets 10 by default, a simulator's).
    - COM_DISARM_PRFLT = -1: no disarm for not taking off within 10 s of arming (commander_params.yaml:105-118):
      the runner arms about 20 s before the scene's take-off. COM_DISARM_LAND = -1: no disarm on a detected
      landing (commander_params.yaml:92-104): the vehicle is not flown by PX4, its land detector may say landed.
    - COM_RCL_EXCEPT = 2 (bit 1, auto modes; commander_params.yaml:446-462): no manual-control-loss failsafe in
      Hold, the mode the runner arms in; there is no RC and no joystick on the bench.
    - NAV_DLL_ACT = 0 (disabled, its default; commander_params.yaml:409-424): stated, so that a GCS heartbeat gap
      under load is no failsafe.
    """
    imu = scene.imus[0]
    if any(imu.mounting_rpy_deg):
        raise SystemExit(f"IMU {imu.name!r}: mounted rotated {imu.mounting_rpy_deg} deg; the calibration written "
                         "for PX4 assumes sensor axes = body axes")
    hard_iron = imu.companions.get("magnetometer", {}).get("hard_iron", (0.0, 0.0, 0.0))
    latency_s = float(imu.companions.get("gnss", {}).get("latency_s", 0.0) or 0.0)
    out = {f"CAL_MAG0_{axis}OFF": float(h) for axis, h in zip("XYZ", hard_iron)}
    out.update(SENS_GPS0_DELAY=round(latency_s * 1000.0), COM_DISARM_PRFLT=-1.0, COM_DISARM_LAND=-1.0,
               COM_RCL_EXCEPT=2, NAV_DLL_ACT=0)
    return out


def param_env(values: dict[str, float]) -> dict[str, str]:
    """PX4_PARAM_<name>=<value>: rcS sets each with `param set` after the airframe file (init.d-posix/rcS, "Allow
    overriding parameters via env variables"). Integers as integers (`param set` parses by the parameter's type)."""
    env = {}
    for name, value in values.items():
        if not re.fullmatch(r"[A-Z][A-Z0-9_]{0,15}", name):
            raise ValueError(f"{name!r}: not a PX4 parameter name (upper case, at most 16 characters)")
        v = float(value)
        env[f"PX4_PARAM_{name}"] = str(int(v)) if v.is_integer() else repr(v)
    return env


def scene_at_rate(text: str, rate_hz: float) -> str:
    """The scene file's text with its [scene] rate_hz replaced (the other tables' rate_hz kept)."""
    out, section, done = [], None, False
    for line in text.splitlines(keepends=True):
        header = re.match(r"\s*\[+\s*([^\]]+?)\s*\]+", line)
        if header:
            section = header.group(1)
        elif section == "scene" and not done and re.match(r"\s*rate_hz\s*=", line):
            line = re.sub(r"(rate_hz\s*=\s*)[^#\n]*?(\s*(#.*)?)$", lambda m: f"{m.group(1)}{rate_hz:g}{m.group(2)}",
                          line.rstrip("\n")) + "\n"
            done = True
        out.append(line)
    if not done:
        raise ValueError("no rate_hz in the scene's [scene] table")
    return "".join(out)


def boot_to_scene(boot_s, rate_hz: float):
    """Scene time of PX4's time since boot: PX4's clock is the HIL_SENSOR stamps (SimulatorMavlink.cpp
    handle_message_hil_sensor: px4_clock_settime to time_usec), and the stream stamps sample k at
    t_k - t_0 + one period (px4_sim.Px4SimTransport.power_up_lead_periods)."""
    import numpy as np
    return np.asarray(boot_s, float) - 1.0 / rate_hz


def wall_to_boot(wall_s, ref_wall_s, ref_boot_s):
    """PX4's boot time at wall times `wall_s`, from messages received at `ref_wall_s` stamped `ref_boot_s`
    (for SYS_STATUS and STATUSTEXT, which carry no time): linear between them, held beyond."""
    import numpy as np
    ref_wall_s, ref_boot_s = np.asarray(ref_wall_s, float), np.asarray(ref_boot_s, float)
    if ref_wall_s.size == 0:
        return np.full(np.shape(wall_s), np.nan)
    order = np.argsort(ref_wall_s, kind="stable")
    return np.interp(np.asarray(wall_s, float), ref_wall_s[order], np.maximum.accumulate(ref_boot_s[order]))


load = sitl_report.load_ned_scene
scene_truth = sitl_report.scene_truth


def emulator_command(scene: Path, work: Path) -> list[str]:
    return [sys.executable, "-m", "imu_emulator", "stream", str(scene), "--format", "mavlink-hil-sensor",
            "--option", "also=mavlink-hil-gps", "--to", f"px4:{SIM_PORT},record={work / 'actuators.csv'},timeout=60",
            "--speed", "0", "--realtime", "off", "--stats-json", str(work / "stream.json")]


def px4_command(build: Path, work: Path) -> list[str]:
    return [str(build / "bin" / "px4"), "-d", "-w", str(work / "rootfs"), str(build / "etc")]


class Recorder(sitl_report.Recorder):
    KINDS = ("ATTITUDE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "ESTIMATOR_STATUS", "SYS_STATUS", "STATUSTEXT",
             "HEARTBEAT", "COMMAND_ACK")


def run(args) -> dict:
    from pymavlink import mavutil
    work = Path(tempfile.mkdtemp(prefix="sitl-px4-"))
    (work / "rootfs").mkdir()
    scene_file = work / "scene_px4.toml"
    scene_file.write_text(scene_at_rate(args.scene.read_text(), PX4_RATE_HZ))
    scene = load(scene_file)
    truth = scene_truth(scene)
    duration = float(truth.t[-1] - truth.t[0])
    values = {**params(scene), **dict(args.param)}
    env_params = param_env(values)
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    emu_cmd = emulator_command(scene_file, work)
    px4_cmd = px4_command(args.px4_build, work)
    px4_env = dict(os.environ, PX4_SYS_AUTOSTART=str(AUTOSTART), PX4_SIM_MODEL="none_iris", **env_params)
    emu_log, px4_log = open(work / "stream.log", "w"), open(work / "px4.log", "w")
    link = mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT}", source_system=255, source_component=190)
    emu = subprocess.Popen(emu_cmd, stdout=emu_log, stderr=subprocess.STDOUT, env=env, cwd=REPO)
    time.sleep(3.0)                # the stream listens on 4560 once its scene is loaded
    px4 = subprocess.Popen(px4_cmd, stdout=px4_log, stderr=subprocess.STDOUT, env=px4_env, cwd=work,
                           start_new_session=True)
    rec = Recorder()
    armed_at = disarmed_at = None
    arm_requests = []
    boot_now = 0.0
    last_hb = last_arm = 0.0
    requested = False
    wall_limit = time.monotonic() + args.wall_limit
    try:
        while emu.poll() is None and px4.poll() is None and time.monotonic() < wall_limit:
            now = time.time()
            if now - last_hb >= 1.0:
                link.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                last_hb = now
            msg = link.recv_match(blocking=True, timeout=0.5)
            received = time.time()
            if msg is None or msg.get_srcSystem() == 255:
                continue
            rec.add(msg, received)
            kind = msg.get_type()
            if hasattr(msg, "time_boot_ms"):
                boot_now = max(boot_now, msg.time_boot_ms / 1e3)
            if kind == "STATUSTEXT":
                print(f"PX4 [{boot_now:7.1f}]: {msg.text}", flush=True)
            elif kind == "COMMAND_ACK":
                print(f"PX4 [{boot_now:7.1f}]: COMMAND_ACK {msg.command} result {msg.result}", flush=True)
            elif kind == "HEARTBEAT" and not requested and msg.get_srcComponent() == 1:
                link.target_system, link.target_component = msg.get_srcSystem(), 1
                for msg_id, hz in ((30, 25), (33, 10), (32, 10), (230, 5), (1, 2)):
                    # ATTITUDE, GLOBAL_POSITION_INT, LOCAL_POSITION_NED, ESTIMATOR_STATUS, SYS_STATUS
                    link.mav.command_long_send(link.target_system, 1, mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                                               0, msg_id, 1e6 / hz, 0, 0, 0, 0, 0)
                requested = True
            if kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
                armed = bool(msg.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                if armed and armed_at is None:
                    armed_at = received
                    print(f"armed at boot {boot_now:.1f} s", flush=True)
                elif not armed and armed_at is not None and disarmed_at is None:
                    disarmed_at = received
                    print(f"disarmed at boot {boot_now:.1f} s", flush=True)
            if boot_now > duration + 2.0:
                break
            prearm = any(r["onboard_control_sensors_health"] & sitl_report.PREARM_CHECK
                         for _, r in rec.rows["SYS_STATUS"][-1:])
            scene_now = boot_now - 1.0 / PX4_RATE_HZ
            if (args.arm and requested and armed_at is None and (prearm or scene_now >= ARM_FROM_S)
                    and received - last_arm >= ARM_EVERY_S):
                last_arm = received
                arm_requests.append(received)
                link.mav.command_long_send(link.target_system, 1, mavutil.mavlink.MAV_CMD_DO_SET_MODE, 0,
                                           MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PX4_MAIN_AUTO, PX4_SUB_AUTO_LOITER,
                                           0, 0, 0, 0)
                link.mav.command_long_send(link.target_system, 1, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                           1, 0, 0, 0, 0, 0, 0)
    finally:
        px4_stopped = px4.poll() is None
        if px4_stopped:
            os.killpg(px4.pid, signal.SIGTERM)
        if emu.poll() is None:
            emu.send_signal(signal.SIGINT)
        sitl_report.reap((px4, emu))
        emu_log.close()
        px4_log.close()
        link.close()
    stream = sitl_report.keep_records(work, rec.rows)
    return {"work": work, "rec": rec, "stream": stream, "truth": truth, "armed_at": armed_at,
            "disarmed_at": disarmed_at, "arm_requests": arm_requests, "params": values,
            "px4_exit": px4.returncode, "px4_stopped": px4_stopped,
            "commands": [emu_cmd, [f"{k}={v}" for k, v in sorted(env_params.items())]
                         + [f"PX4_SYS_AUTOSTART={AUTOSTART}", "PX4_SIM_MODEL=none_iris"] + px4_cmd]}


def estimates(rec: Recorder) -> tuple[sitl_report.Estimates, callable]:
    """The estimate series at scene time, and the wall -> scene time map for the messages without a stamp."""
    import numpy as np

    def series(kind, keys):
        rows = rec.rows[kind]
        if not rows:
            return np.zeros(0), np.zeros((0, len(keys)))
        boot = np.array([r["time_boot_ms"] for _, r in rows]) / 1e3
        return boot_to_scene(boot, PX4_RATE_HZ), np.array([[r[k] for k in keys] for _, r in rows], dtype=float)

    ta, att = series("ATTITUDE", ("roll", "pitch", "yaw"))
    tp, pos = series("GLOBAL_POSITION_INT", ("lat", "lon", "alt", "vx", "vy", "vz"))
    stamped = [(w, r["time_boot_ms"] / 1e3) for k in ("ATTITUDE", "GLOBAL_POSITION_INT") for w, r in rec.rows[k]]
    ref_wall = np.array([w for w, _ in stamped])
    ref_boot = np.array([b for _, b in stamped])

    def wall_scene(wall):
        return boot_to_scene(wall_to_boot(wall, ref_wall, ref_boot), PX4_RATE_HZ)

    ekf = rec.rows["ESTIMATOR_STATUS"]
    sys_status = rec.rows["SYS_STATUS"]
    est = sitl_report.Estimates(
        attitude_t=ta, euler=att, position_t=tp,
        lat_lon_alt=np.column_stack([pos[:, 0] / 1e7, pos[:, 1] / 1e7, pos[:, 2] / 1e3]) if len(tp) else
        np.zeros((0, 3)),
        velocity_ned=pos[:, 3:6] / 100.0 if len(tp) else np.zeros((0, 3)),
        # ESTIMATOR_STATUS.time_usec is EKF2's estimator_status.timestamp (ESTIMATOR_STATUS.hpp), PX4's clock
        ekf_t=boot_to_scene(np.array([r["time_usec"] for _, r in ekf]) / 1e6, PX4_RATE_HZ),
        ekf_flags=np.array([r["flags"] for _, r in ekf], dtype=np.int64),
        prearm_t=wall_scene(np.array([w for w, _ in sys_status])),
        prearm_ok=np.array([bool(r["onboard_control_sensors_health"] & sitl_report.PREARM_CHECK)
                            for _, r in sys_status]))
    return est, wall_scene


def write_report(out: Path, args, outcome: dict, px4_commit: str) -> Path:
    import numpy as np
    from imu_emulator.output.atomic import save_figure, write_text
    from pymavlink.dialects.v20 import common as mav
    rec, truth = outcome["rec"], outcome["truth"]
    est, wall_scene = estimates(rec)
    result = sitl_report.compare(est, truth, forbids=sitl_report.ESTIMATOR_HEALTHY_FORBIDS)
    name = args.name
    title = f"PX4 SITL ({px4_commit}) on HIL_SENSOR + HIL_GPS: {args.scene.name} at {PX4_RATE_HZ:g} Hz"
    fig = sitl_report.plot(result, title)
    out.mkdir(parents=True, exist_ok=True)
    save_figure(fig, out / f"{name}.png", dpi=90)
    text_rows = rec.rows["STATUSTEXT"]
    text_t = wall_scene(np.array([w for w, _ in text_rows])) if text_rows else []
    texts = [r["text"].strip() for _, r in text_rows]
    failures = sitl_report.failure_summary(text_t, texts, prefixes=sitl_report.PX4_FAILURE_PREFIXES)

    def when(x):
        return f"{x:.1f} s" if x is not None and np.isfinite(x) else "never"

    def spans(rows):
        return ", ".join(f"{a:.1f}-{when(b)}" for a, b in rows) or "never"

    def at(wall):
        return float(wall_scene(np.array([wall]))[0]) if wall is not None else None
    armed = when(at(outcome["armed_at"]))
    if outcome.get("disarmed_at"):
        armed += f", disarmed at {when(at(outcome['disarmed_at']))}"
    requests = outcome["arm_requests"]

    def answers(command):
        return ", ".join(mav.enums["MAV_RESULT"][r["result"]].name for _, r in rec.rows["COMMAND_ACK"]
                         if r["command"] == command) or "none"
    stream = outcome["stream"]
    text = f"""# {title}

What is compared: PX4's ATTITUDE and GLOBAL_POSITION_INT, i.e. EKF2 run on the emulator's IMU, magnetometer,
barometer (HIL_SENSOR) and GNSS (HIL_GPS), against the scene's truth at the same scene time. Lockstep: PX4's clock is
the HIL_SENSOR stamps, so time_boot_ms - one sample period is scene time exactly. The vehicle is not flown by PX4:
the motion is scripted, the actuator outputs recorded. Statistics count from the first healthy ESTIMATOR_STATUS
(attitude, horizontal and vertical velocity, absolute horizontal and vertical position flags; no
GPS glitch or accel error; PX4 also sets the const-position flag whenever it thinks the vehicle is at rest,
ekf_helper.cpp:718-719, so that one is not held against it) on.

- pre-arm checks passed (SYS_STATUS pre-arm bit first set): {when(result['prearm_passed_s'])} scene time
- EKF healthy: {when(result['ekf_healthy_s'])}; unhealthy again after that: {spans(result['ekf_unhealthy_spans'])}
- armed (Hold mode): {armed}
- arm requests: {len(requests)}{' (first at ' + when(at(requests[0])) + ')' if requests else ''}; answers: \
{answers(mav.MAV_CMD_COMPONENT_ARM_DISARM)}; mode requests answered: {answers(mav.MAV_CMD_DO_SET_MODE)}
- emulator stream: {stream.get('samples', 0)} samples, dropped {stream.get('dropped', '?')}; PX4 exit code \
{outcome.get('px4_exit')} ({'ended by the runner' if outcome.get('px4_stopped') else 'ended by itself'})

{sitl_report.markdown_table(result)}

Pre-arm and arm failures PX4 stated (scene time):

{sitl_report.failure_table(failures)}

![errors]({name}.png)

Commands (PX4-Autopilot at {px4_commit}, `make px4_sitl_default`):

"""
    said = "Parameters given to PX4 (px4_sitl_run.params says why): " + \
        ", ".join(f"{k}={v:g}" for k, v in outcome["params"].items())
    text += sitl_report.report_tail(outcome["commands"], said, texts)
    write_text(out / f"{name}.md", text)
    return out / f"{name}.md"


_param = sitl_report.param_option(param_env)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--px4-build", type=Path, required=True, help="PX4's build/px4_sitl_default")
    p.add_argument("--scene", type=Path, default=REPO / "examples" / "sitl_flight.toml")
    p.add_argument("--out", type=Path, default=REPO / "docs" / "sitl")
    p.add_argument("--name", default="px4-hil", help="the report's file name, without .md / .png")
    p.add_argument("--no-arm", dest="arm", action="store_false", help="only watch, never arm")
    p.add_argument("--px4-commit", default="unknown", help="written in the report")
    p.add_argument("--wall-limit", type=float, default=1800.0, help="stop after this many wall-clock seconds")
    p.add_argument("--param", action="append", default=[], type=_param, metavar="NAME=VALUE",
                   help="one more PX4 parameter (after the runner's), repeatable")
    args = p.parse_args(argv)
    if not (args.px4_build / "bin" / "px4").is_file():
        p.error(f"{args.px4_build / 'bin' / 'px4'}: no such file")
    outcome = run(args)
    report = write_report(args.out, args, outcome, args.px4_commit)
    print(f"report: {report} (work files in {outcome['work']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
