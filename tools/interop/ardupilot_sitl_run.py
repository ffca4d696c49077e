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
   GLOBAL_POSITION_INT; once the pre-arm checks pass it arms (STABILIZE, throttle low) and stays armed.
4. The report: the stack's estimate against the scene's truth (sitl_report.py), docs/sitl/<stack>-<device>.md/png.

The scene's motion is scripted: SITL's own vehicle is not flown along it. With an external AHRS the attitude and
position ArduPilot reports are the unit's navigation solution as its driver read it (so the report checks the whole
path: wire format, driver, AHRS, telemetry, against the truth); with JSON they are ArduPilot's EKF3 run on the
emulator's IMU samples and the JSON position (SITL's simulated GPS and compass are made from it).
"""
from __future__ import annotations

import argparse
import json
import os
import shlex
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
    _, fmt, options, _ = ardupilot_params.DEVICES[device]
    return base + ["--format", fmt, "--to", "pty", "--link", str(work / "device")] + \
        [arg for option in options for arg in ("--option", option)]


def sitl_command(arducopter: Path, defaults: list[Path], device: str, work: Path, origin) -> list[str]:
    lat, lon, h = origin
    cmd = [str(arducopter), "--wipe", "--speedup", "1", "--home", f"{lat},{lon},{h},0",
           "--defaults", ",".join(str(p) for p in defaults)]
    if device == "json":
        return cmd + ["--model", "JSON:127.0.0.1"]
    return cmd + ["--model", "quad",
                  f"--serial{ardupilot_params.SERIAL_PORT}=uart:{work / 'device'}:{ardupilot_params.BAUD}"]


def scene_truth(scene_path: Path) -> sitl_report.Truth:
    from imu_emulator.runtime.simulation import Simulation
    from imu_emulator.scene.load import load_scene
    scene = load_scene(scene_path)
    if scene.frame != "NED":
        raise SystemExit(f"{scene_path}: the report compares in NED; give the scene frame = \"NED\"")
    block = Simulation(scene, truth=True).block(0, scene.n_samples)
    # time since the scene's first sample, as the stream's started_unix_ns counts (its first sample's deadline)
    return sitl_report.Truth(t=block.t_s - block.t_s[0], position_ned=block.truth["position"],
                             velocity_ned=block.truth["velocity"], euler=block.truth["euler"], origin=scene.origin)


class Recorder:
    """Every message of interest with its wall receive time; STATUSTEXT lines kept as text."""

    KINDS = ("ATTITUDE", "GLOBAL_POSITION_INT", "EKF_STATUS_REPORT", "SYS_STATUS", "STATUSTEXT", "HEARTBEAT")

    def __init__(self):
        self.rows = {k: [] for k in self.KINDS}

    def add(self, msg, received: float) -> None:
        kind = msg.get_type()
        if kind in self.rows:
            self.rows[kind].append((received, msg.to_dict()))


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
    truth = scene_truth(args.scene)
    duration = float(truth.t[-1] - truth.t[0])
    params = {**ardupilot_params.device_params(args.device, sensors=args.sensors), **dict(args.param)}
    parm = ardupilot_params.write_params(work / "emulated.parm", params)
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    emu_cmd = emulator_command(args.scene, args.device, work)
    sitl_cmd = sitl_command(args.arducopter, [args.defaults, parm], args.device, work, truth.origin)
    emu_log, sitl_log = open(work / "stream.log", "w"), open(work / "sitl.log", "w")
    emu = subprocess.Popen(emu_cmd, stdout=emu_log, stderr=subprocess.STDOUT, env=env, cwd=REPO)
    sitl = None
    rec = Recorder()
    armed_at = None
    try:
        if args.device != "json":
            wait_for(work / "device", 120, emu, "imu-emulator stream")
        sitl = subprocess.Popen(sitl_cmd, stdout=sitl_log, stderr=subprocess.STDOUT, cwd=work)
        link = connect(sitl, work)
        for msg_id, hz in ((30, 25), (33, 10), (193, 5), (1, 2)):   # ATTITUDE, GLOBAL_POSITION_INT, EKF_STATUS, SYS
            link.mav.command_long_send(link.target_system, link.target_component,
                                       mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, 1e6 / hz, 0, 0, 0, 0, 0)
        if args.device != "json":
            # The unit's IMU is a new accelerometer to ArduPilot, never calibrated: ArduPilot's own test of these
            # drivers (Tools/autotest/arduplane.py fly_external_AHRS) runs the simple accel cal (param5 = 4)
            # 5 s after boot, before waiting for the pre-arm checks; so does this.
            time.sleep(5.0)
            link.mav.command_long_send(link.target_system, link.target_component,
                                       mavutil.mavlink.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 0, 4, 0, 0)
        end = time.monotonic() + duration + 5
        last_arm_try = 0.0
        while time.monotonic() < end and emu.poll() is None and sitl.poll() is None:
            msg = link.recv_match(blocking=True, timeout=0.5)
            if msg is None:
                continue
            rec.add(msg, time.time())
            if msg.get_type() == "STATUSTEXT":
                print(f"SITL: {msg.text}", flush=True)
            if msg.get_type() == "HEARTBEAT" and msg.get_srcSystem() == link.target_system:
                armed = bool(msg.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                if armed and armed_at is None:
                    armed_at = time.time()
                    print("armed", flush=True)
            prearm = [r for _, r in rec.rows["SYS_STATUS"]
                      if r["onboard_control_sensors_health"] & sitl_report.PREARM_CHECK]
            if args.arm and armed_at is None and prearm and time.monotonic() - last_arm_try > 5:
                last_arm_try = time.monotonic()
                link.set_mode("STABILIZE")
                link.mav.command_long_send(link.target_system, link.target_component,
                                           mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    finally:
        for proc in (sitl, emu):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGINT if proc is emu else signal.SIGTERM)
        for proc in (sitl, emu):
            if proc is not None:
                try:
                    proc.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    proc.kill()
        emu_log.close()
        sitl_log.close()
    stream = json.loads((work / "stream.json").read_text()) if (work / "stream.json").exists() else {}
    return {"work": work, "rec": rec, "stream": stream, "truth": truth, "armed_at": armed_at,
            "commands": [emu_cmd, sitl_cmd], "params": params}


def estimates(rec: Recorder, started_s: float) -> sitl_report.Estimates:
    import numpy as np

    def series(kind, keys):
        rows = rec.rows[kind]
        if not rows:
            return np.zeros(0), np.zeros((0, len(keys)))
        boot = np.array([r["time_boot_ms"] for _, r in rows]) / 1e3
        t = sitl_report.wall_to_scene(boot, np.array([w for w, _ in rows]), started_s)
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

    def when(x):
        return f"{x:.1f} s" if x is not None else "never"
    what = ("the unit's navigation solution as ArduPilot's driver read it (AHRS_EKF_TYPE 11)" if args.device != "json"
            else "ArduPilot's EKF3 on the emulator's IMU samples and JSON position")
    text = f"""# {title}

What is compared: ArduPilot's ATTITUDE and GLOBAL_POSITION_INT, i.e. {what}, against the scene's truth at the
same scene time (ATTITUDE / GLOBAL_POSITION_INT time_boot_ms mapped to the wall clock by the quickest delivery in
each 10 s window, then to scene time by the stream's `started_unix_ns`). SITL's own vehicle is not flown along the
scene: the motion is scripted. Statistics count from the first healthy EKF_STATUS_REPORT on.

- pre-arm checks passed (SYS_STATUS pre-arm bit first set): {when(result['prearm_passed_s'])} scene time
- EKF healthy (attitude, velocity, absolute position flags; not constant-position mode): {when(result['ekf_healthy_s'])}
- armed: {armed}
- emulator stream: {outcome['stream'].get('samples', 0)} samples, dropped {outcome['stream'].get('dropped', '?')}

{sitl_report.markdown_table(result)}

![errors]({name}.png)

Commands (ArduPilot at {ardupilot_commit}, its Copter SITL built per its own BUILD.md):

```sh
{chr(10).join(shlex.join(str(a) for a in c) for c in outcome['commands'])}
```

Parameters written for SITL: {', '.join(f'{k}={v}' for k, v in outcome['params'].items())}

STATUSTEXT ({len(texts)}):

```
{chr(10).join(texts[:80])}
```
"""
    write_text(out / f"{name}.md", text)
    return out / f"{name}.md"


def _param(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"{text!r}: NAME=VALUE")
    try:
        ardupilot_params.param_text({name: float(value)})        # the name and value checks of the file
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return name, float(value)


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
