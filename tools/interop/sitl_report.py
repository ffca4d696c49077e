"""A flight stack's estimate against the scene's truth: the errors, their statistics after convergence, and the
report (markdown table + matplotlib figure) tools/interop/ardupilot_sitl_run.py writes.

What is compared with what: the stack's ATTITUDE (roll, pitch, yaw) and GLOBAL_POSITION_INT (lat, lon, alt, vx, vy,
vz) against the scene's truth at the same scene time; attitude error = the angle of the rotation between the two
attitudes, position error = north/east/down of the estimate w.r.t. the truth (pymap3d, about the scene's origin).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# MAVLink ardupilotmega.xml EKF_STATUS_FLAGS (what EKF_STATUS_REPORT.flags carries)
EKF_ATTITUDE, EKF_VELOCITY_HORIZ, EKF_VELOCITY_VERT = 1, 2, 4
EKF_POS_HORIZ_ABS, EKF_POS_VERT_ABS = 16, 32
EKF_CONST_POS_MODE, EKF_UNINITIALIZED = 128, 1024
#: what "EKF healthy" means here: attitude, velocity and absolute position all valid, not in constant-position mode
EKF_HEALTHY_NEEDS = EKF_ATTITUDE | EKF_VELOCITY_HORIZ | EKF_VELOCITY_VERT | EKF_POS_HORIZ_ABS | EKF_POS_VERT_ABS
EKF_HEALTHY_FORBIDS = EKF_CONST_POS_MODE | EKF_UNINITIALIZED
#: MAV_SYS_STATUS_SENSOR bit of SYS_STATUS: set in onboard_control_sensors_health when the pre-arm checks pass
PREARM_CHECK = 0x10000000

# MAVLink common.xml ESTIMATOR_STATUS_FLAGS (what PX4's ESTIMATOR_STATUS.flags carries: EKF2's solution status,
# src/modules/ekf2/EKF/ekf_helper.cpp:678-689 at PX4 bb59c637cd): the same low bits as EKF_STATUS_FLAGS, but bit 10
# is GPS_GLITCH there (not "uninitialised") and bit 11 ACCEL_ERROR. PX4 sets CONST_POS_MODE also whenever it
# thinks the vehicle is at rest (const_pos_mode = fake_pos || valid_fake_pos || vehicle_at_rest,
# ekf_helper.cpp:718-719), GNSS fused or not: not a fault there; a fake position leaves POS_HORIZ_ABS unset
# (isGlobalHorizontalPositionValid), which the needs catch.
ESTIMATOR_GPS_GLITCH, ESTIMATOR_ACCEL_ERROR = 1024, 2048
ESTIMATOR_HEALTHY_FORBIDS = ESTIMATOR_GPS_GLITCH | ESTIMATOR_ACCEL_ERROR


def ekf_healthy(flags, forbids: int = EKF_HEALTHY_FORBIDS) -> np.ndarray:
    """EKF_HEALTHY_NEEDS all set and none of `forbids` (ArduPilot's EKF_STATUS_REPORT by default; PX4's
    ESTIMATOR_STATUS with ESTIMATOR_HEALTHY_FORBIDS)."""
    flags = np.asarray(flags, dtype=np.int64)
    return ((flags & EKF_HEALTHY_NEEDS) == EKF_HEALTHY_NEEDS) & ((flags & forbids) == 0)


def outages(t, condition, after: float | None) -> list[tuple[float, float | None]]:
    """The spans (start, end) from `after` on where `condition` does not hold: start = the first time stamp without
    it, end = the next one with it again (None: never again). None for `after`: no spans."""
    if after is None:
        return []
    t, ok = np.asarray(t, float), np.asarray(condition, dtype=bool)
    keep = t >= after
    t, ok = t[keep], ok[keep]
    spans, start = [], None
    for when, good in zip(t, ok):
        if not good and start is None:
            start = float(when)
        elif good and start is not None:
            spans.append((start, float(when)))
            start = None
    if start is not None:
        spans.append((start, None))
    return spans


def first_time(t, condition) -> float | None:
    """The first time stamp where `condition` holds (None: never)."""
    hit = np.flatnonzero(np.asarray(condition, dtype=bool))
    return float(np.asarray(t)[hit[0]]) if hit.size else None


def wall_to_scene(boot_s, received_s, started_s, window_s: float = 10.0) -> np.ndarray:
    """Scene time of messages stamped `boot_s` (the stack's time since boot) and received at wall time `received_s`.

    The stack's clock is mapped to the wall clock by the lower envelope of lag = received - boot: in each window
    of `window_s` the quickest delivery is the least delayed, and the envelope is interpolated between those
    messages at their own boot times. A stack whose clock runs slow (SITL on a loaded machine: its simulated time
    falls behind the wall clock) makes the lag grow within a window; anchoring each window's minimum where it
    occurs, not at the window's middle, follows that drift (exactly, while it is linear between anchors). Scene
    time = that wall time - `started_s` (the stream's first sample deadline, the emulator's `started_unix_ns`)."""
    boot_s, received_s = np.asarray(boot_s, float), np.asarray(received_s, float)
    lag = received_s - boot_s
    edges = np.arange(boot_s.min(), boot_s.max() + window_s, window_s)
    anchors, floors = [], []
    for lo in edges:
        inside = np.flatnonzero((boot_s >= lo) & (boot_s < lo + window_s))
        if inside.size:
            quickest = inside[np.argmin(lag[inside])]
            anchors.append(float(boot_s[quickest]))
            floors.append(float(lag[quickest]))
    anchors, floors = np.asarray(anchors), np.asarray(floors)
    lag_at = np.interp(boot_s, anchors, floors)
    if anchors.size > 1:        # beyond the first / last anchor the drift goes on as between the two nearest
        before, after = boot_s < anchors[0], boot_s > anchors[-1]
        first = (floors[1] - floors[0]) / (anchors[1] - anchors[0])
        last = (floors[-1] - floors[-2]) / (anchors[-1] - anchors[-2])
        lag_at[before] = floors[0] + (boot_s[before] - anchors[0]) * first
        lag_at[after] = floors[-1] + (boot_s[after] - anchors[-1]) * last
    return boot_s + lag_at - started_s


@dataclass
class Truth:
    """The scene's truth sampled at `t` (s): NED position (m from the origin), NED velocity, roll/pitch/yaw (rad,
    body FRD -> NED), and the origin (lat, lon deg, height m) the NED frame is tangent at."""
    t: np.ndarray
    position_ned: np.ndarray
    velocity_ned: np.ndarray
    euler: np.ndarray
    origin: tuple

    def at(self, t):
        """Truth at times `t` inside the sampled span: positions and velocities linear, attitude slerped."""
        from scipy.spatial.transform import Rotation, Slerp
        t = np.asarray(t, float)
        pos = np.stack([np.interp(t, self.t, self.position_ned[:, i]) for i in range(3)], axis=1)
        vel = np.stack([np.interp(t, self.t, self.velocity_ned[:, i]) for i in range(3)], axis=1)
        rot = Slerp(self.t, Rotation.from_euler("ZYX", self.euler[:, ::-1]))(np.clip(t, self.t[0], self.t[-1]))
        return pos, vel, rot


def attitude_error_deg(euler_est, truth_rot) -> np.ndarray:
    """Angle (deg) of the rotation from the true attitude to the estimated one (roll, pitch, yaw in rad)."""
    from scipy.spatial.transform import Rotation
    est = Rotation.from_euler("ZYX", np.asarray(euler_est, float)[:, ::-1])
    return np.degrees((truth_rot.inv() * est).magnitude())


def position_error_ned(lat_deg, lon_deg, alt_m, truth_ned, origin) -> np.ndarray:
    """Estimated minus true position, north/east/down metres, the estimate placed about the scene's origin."""
    import pymap3d
    n, e, d = pymap3d.geodetic2ned(np.asarray(lat_deg, float), np.asarray(lon_deg, float), np.asarray(alt_m, float),
                                   *origin)
    return np.stack([n, e, d], axis=1) - truth_ned


def stats(t, values, t_from: float | None) -> dict:
    """Max and RMS of `values` at t >= t_from (None: no convergence, nothing counted)."""
    values = np.asarray(values, float)
    if t_from is None:
        return {"n": 0, "max": float("nan"), "rms": float("nan")}
    keep = np.asarray(t) >= t_from
    if not keep.any():
        return {"n": 0, "max": float("nan"), "rms": float("nan")}
    v = values[keep]
    return {"n": int(v.size), "max": float(np.max(np.abs(v))), "rms": float(np.sqrt(np.mean(v * v)))}


@dataclass
class Estimates:
    """The stack's messages, each series with its scene time stamps (s)."""
    attitude_t: np.ndarray
    euler: np.ndarray                       # (n, 3) rad
    position_t: np.ndarray
    lat_lon_alt: np.ndarray                 # (n, 3) deg, deg, m
    velocity_ned: np.ndarray                # (n, 3) m/s
    ekf_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ekf_flags: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    prearm_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    prearm_ok: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))


def compare(est: Estimates, truth: Truth, forbids: int = EKF_HEALTHY_FORBIDS) -> dict:
    """Every error series and the summary the report prints. Convergence = the first EKF status that is
    healthy (ekf_healthy with `forbids`); the statistics count from there on, inside the scene's span."""
    inside_a = (est.attitude_t >= truth.t[0]) & (est.attitude_t <= truth.t[-1])
    inside_p = (est.position_t >= truth.t[0]) & (est.position_t <= truth.t[-1])
    ta, tp = est.attitude_t[inside_a], est.position_t[inside_p]
    _, _, rot = truth.at(ta)
    att = attitude_error_deg(est.euler[inside_a], rot)
    pos_true, vel_true, _ = truth.at(tp)
    dpos = position_error_ned(*est.lat_lon_alt[inside_p].T, pos_true, truth.origin)
    dvel = est.velocity_ned[inside_p] - vel_true
    healthy = ekf_healthy(est.ekf_flags, forbids) if len(est.ekf_t) else np.zeros(0, dtype=bool)
    healthy_at = first_time(est.ekf_t, healthy) if len(est.ekf_t) else None
    prearm_at = first_time(est.prearm_t, est.prearm_ok) if len(est.prearm_t) else None
    series = {"attitude_deg": (ta, att), "horizontal_m": (tp, np.hypot(dpos[:, 0], dpos[:, 1])),
              "vertical_m": (tp, dpos[:, 2]), "velocity_mps": (tp, np.linalg.norm(dvel, axis=1))}
    return {"series": series, "ekf_healthy_s": healthy_at, "prearm_passed_s": prearm_at,
            "ekf_unhealthy_spans": outages(est.ekf_t, healthy, healthy_at),
            "stats": {k: stats(t, v, healthy_at) for k, (t, v) in series.items()},
            "truth_position": pos_true, "estimate_position": pos_true + dpos, "position_t": tp}


ROWS = (("attitude_deg", "attitude error (rotation angle)", "deg"),
        ("horizontal_m", "horizontal position error", "m"),
        ("vertical_m", "vertical position error (down)", "m"),
        ("velocity_mps", "velocity error (3D)", "m/s"))


def markdown_table(result: dict) -> str:
    lines = ["| quantity | max | RMS | samples |", "|---|---|---|---|"]
    for key, label, unit in ROWS:
        s = result["stats"][key]
        lines.append(f"| {label} | {s['max']:.3f} {unit} | {s['rms']:.3f} {unit} | {s['n']} |")
    return "\n".join(lines)


def plot(result: dict, title: str):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(3, 2, figsize=(12, 9), constrained_layout=True)
    fig.suptitle(title)
    for ax, (key, label, unit) in zip(axes.flat, ROWS):
        t, v = result["series"][key]
        ax.plot(t, v, lw=0.8)
        ax.set_title(label)
        ax.set_xlabel("scene time, s")
        ax.set_ylabel(unit)
        if result["ekf_healthy_s"] is not None:
            ax.axvline(result["ekf_healthy_s"], color="g", ls="--", lw=0.8, label="EKF healthy")
            ax.legend(loc="upper right", fontsize=8)
    ax = axes.flat[4]
    truth, est = result["truth_position"], result["estimate_position"]
    ax.plot(truth[:, 1], truth[:, 0], "k", lw=1.0, label="truth")
    ax.plot(est[:, 1], est[:, 0], "r", lw=0.6, label="estimate")
    ax.set_xlabel("east, m")
    ax.set_ylabel("north, m")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=8)
    ax.set_title("track")
    ax = axes.flat[5]
    t = result["position_t"]
    ax.plot(t, -truth[:, 2], "k", lw=1.0, label="truth")
    ax.plot(t, -est[:, 2], "r", lw=0.6, label="estimate")
    ax.set_xlabel("scene time, s")
    ax.set_ylabel("height above origin, m")
    ax.legend(fontsize=8)
    ax.set_title("height")
    return fig


#: how ArduPilot's arming checks word a failure: "PreArm: " from the periodic pre-arm display, "Arm: " when an
#: arming request is refused (AP_Arming::check_failed, libraries/AP_Arming/AP_Arming.cpp:301-308, 265753db8b)
FAILURE_PREFIXES = ("PreArm: ", "Arm: ")
#: how PX4's commander words them: "Preflight Fail: " from a health check reporting to the GCS (e.g.
#: HealthAndArmingChecks/checks/accelerometerCheck.cpp:78), "Arming denied: " when a request is refused
#: (Commander.cpp:674, 721), PX4 bb59c637cd
PX4_FAILURE_PREFIXES = ("Preflight Fail: ", "Arming denied: ")


def failure_summary(t, texts, prefixes=FAILURE_PREFIXES) -> list[dict]:
    """Every distinct arming-check failure among STATUSTEXT `texts` (stamped `t`), in order of first appearance:
    {"check": the text without its prefix, numbers as '#' (one row for "Main loop slow (284Hz < 400Hz)" and
    "(281Hz < 400Hz)"), "example": its last wording, "count", "first", "last": the times}."""
    import re
    rows: dict[str, dict] = {}
    for when, text in zip(t, texts):
        prefix = next((p for p in prefixes if text.startswith(p)), None)
        if prefix is None:
            continue
        body = text[len(prefix):]
        row = rows.setdefault(re.sub(r"\d+(\.\d+)?", "#", body),
                              {"count": 0, "first": float(when), "last": float(when)})
        row.update(count=row["count"] + 1, last=float(when), example=text)
    return [{"check": key, **row} for key, row in rows.items()]


def failure_table(rows: list[dict]) -> str:
    if not rows:
        return "No pre-arm or arm failure was reported."
    lines = ["| check failed (last wording) | times | first, s | last, s |", "|---|---|---|---|"]
    lines += [f"| {r['example']} | {r['count']} | {r['first']:.1f} | {r['last']:.1f} |" for r in rows]
    return "\n".join(lines)


def report_tail(commands: list, params_said: str, texts: list[str]) -> str:
    """The end every report shares: the exact commands, the parameters given (`params_said`, one line) and the
    first 80 STATUSTEXT lines."""
    import shlex
    lines = "\n".join(shlex.join(str(a) for a in c) for c in commands)
    shown = "\n".join(texts[:80])
    return f"""```sh
{lines}
```

{params_said}

STATUSTEXT ({len(texts)}):

```
{shown}
```
"""


def param_option(check):
    """An argparse type for `--param NAME=VALUE`: `check({name: value})` raises ValueError on what the stack
    would not take (its message becomes the option's error)."""
    import argparse

    def parse(text: str) -> tuple[str, float]:
        name, sep, value = text.partition("=")
        if not sep:
            raise argparse.ArgumentTypeError(f"{text!r}: NAME=VALUE")
        try:
            number = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: the value {value!r} is not a number") from None
        try:
            check({name: number})
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return name, number
    return parse


def reap(procs, timeout_s: float = 20.0) -> None:
    """Wait for each process (already asked to stop) up to timeout_s, then kill it."""
    import subprocess
    for proc in procs:
        if proc is None:
            continue
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()


def keep_records(work, rows: dict) -> dict:
    """Every message kept in WORK/mavlink.json, for a report made again later (write_report reads only these and
    the stream's figures); returns the stream's figures (its --stats-json), {} when it wrote none."""
    import json
    from pathlib import Path
    work = Path(work)
    (work / "mavlink.json").write_text(json.dumps(rows))
    return json.loads((work / "stream.json").read_text()) if (work / "stream.json").exists() else {}


def load_ned_scene(scene_path):
    """The scene, which must be in NED: the reports compare in NED."""
    from imu_emulator.scene.load import load_scene
    scene = load_scene(scene_path)
    if scene.frame != "NED":
        raise SystemExit(f"{scene_path}: the report compares in NED; give the scene frame = \"NED\"")
    return scene


def scene_truth(scene) -> Truth:
    """The scene's truth, timed from its first sample (as the stream counts: its first sample's deadline)."""
    from imu_emulator.runtime.simulation import Simulation
    block = Simulation(scene, truth=True).block(0, scene.n_samples)
    return Truth(t=block.t_s - block.t_s[0], position_ned=block.truth["position"],
                 velocity_ned=block.truth["velocity"], euler=block.truth["euler"], origin=scene.origin)


class Recorder:
    """Every message of the KINDS a runner watches, with its wall receive time (a subclass names its KINDS)."""

    KINDS: tuple = ()

    def __init__(self):
        self.rows = {k: [] for k in self.KINDS}

    def add(self, msg, received: float) -> None:
        kind = msg.get_type()
        if kind in self.rows:
            self.rows[kind].append((received, msg.to_dict()))

    def texts(self) -> list[tuple[float, str]]:
        return [(w, r["text"]) for w, r in self.rows.get("STATUSTEXT", [])]
