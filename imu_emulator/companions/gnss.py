"""GNSS receiver: the position and velocity of its antenna with white noise plus a first-order Gauss-Markov
error per axis, reported `latency_s` after its time of validity, at `rate_hz`, with the quality figures a
receiver gives (fix type, satellites, DOP, 1-sigma accuracies); outages named in the scene.

Timing: solution j is valid at run time j / rate_hz (the first sample at or after it: the truth is the
simulation's, at its sample instants) and reaches the output at the first sample at or after j / rate_hz +
latency_s, where gnss_new is 1; the output holds it until the next (Samples.gnss_*). gnss_age_s is the time from
the solution's time of validity to the sample (0 before the first solution), so a format's GPS week and time of
week (firmware_protocols.gnss_time) of time_ns - gnss_age_s name the epoch the solution belongs to. Before the
first solution, and for solutions valid inside an outage ([start, stop) in scene seconds), the fix is 0, the
satellites 0 and the last position is held (zeros before any).

Errors, in local north, east, down: e_j = white_j + markov_j, white ~ N(0, position_noise^2) per update and
markov a Gauss-Markov process of standard deviation position_markov and time constant markov_time_s, sampled
at the solution rate; the same for velocity. The accuracies reported are sqrt(noise^2 + markov^2) (horizontal:
of north and east together, the receivers' hAcc), what a healthy receiver's filter would state.

Antenna: lever_arm_m in the scene's body axes from the reference point S; position S + C_nb r, velocity
v + C_nb (omega_b x r) (the Earth's rate times r, < 1e-3 m/s for r under 10 m, is left out). The offset is
added to latitude, longitude, height through the local radii: exact to r^2 / R (2e-5 m at 10 m).
"""
from __future__ import annotations

import math

import numpy as np

from imu_emulator.companions._record import (Companion, Markov, Runner, changes, check_sigmas, hold, param_maker,
                                             update_index, update_normals)
from imu_emulator.errors import SceneError

RATE_RANGE_HZ = (1.0, 20.0)
MAX_LATENCY_S = 2.0
MAX_OUTAGES = 1000

FIELDS = {"gnss_llh": 3, "gnss_velocity_ned": 3, "gnss_fix": 0, "gnss_satellites": 0, "gnss_hdop": 0,
          "gnss_vdop": 0, "gnss_horizontal_accuracy_m": 0, "gnss_vertical_accuracy_m": 0,
          "gnss_speed_accuracy_mps": 0, "gnss_new": 0, "gnss_age_s": 0}


def offset_llh(llh: np.ndarray, d_ned: np.ndarray) -> np.ndarray:
    """Geodetic positions moved by small north, east, down offsets (m), through the local radii of curvature."""
    from imu_emulator.geo import wgs84
    lat = np.radians(llh[:, 0])
    r_n, r_e = wgs84.radii(lat)
    h = llh[:, 2]
    return np.column_stack([llh[:, 0] + np.degrees(d_ned[:, 0] / (r_n + h)),
                            llh[:, 1] + np.degrees(d_ned[:, 1] / ((r_e + h) * np.cos(lat))),
                            h - d_ned[:, 2]])


def antenna(truth, at: np.ndarray, lever_arm) -> tuple[np.ndarray, np.ndarray]:
    """(llh, v_ned) of a point at `lever_arm` (scene body axes) from S, at samples `at`."""
    r = np.asarray(lever_arm, dtype=float)
    if not r.any():
        return truth.llh[at], truth.v_ned[at]
    c_nb = truth.c_nb[at]
    d_ned = c_nb @ r
    v_ned = truth.v_ned[at] + np.einsum("nij,nj->ni", c_nb, np.cross(truth.omega_b[at], r))
    return offset_llh(truth.llh[at], d_ned), v_ned


class _Receiver(Runner):
    def __init__(self, scene, m: int, values: dict):
        super().__init__()
        self.seed, self.m, self.v = scene.seed, m, values
        step, tau = 1.0 / values["rate_hz"], values["markov_time_s"]
        self.position_markov = Markov(scene.seed, m, "gnss.position_markov", values["position_markov"], step, tau)
        self.velocity_markov = Markov(scene.seed, m, "gnss.velocity_markov", values["velocity_markov"], step, tau)
        self.t0 = scene.t0_s
        self.epoch_j = -1            # the last solution computed (at its time of validity)
        self.report_j = -1           # the last solution reported
        self.pending: dict[int, np.ndarray] = {}    # computed, not yet reported: j -> row of _ROW
        self.held = _empty_row()       # what the output holds (no fix before the first)
        self.last_valid = np.zeros(6)  # the last valid position and velocity

    def _solutions(self, truth) -> None:
        """Compute the solutions whose time of validity falls in this block."""
        v = self.v
        j = update_index(truth.s, truth.rate_hz, v["rate_hz"])
        new = changes(j, self.epoch_j) & (j >= 0)
        at = np.flatnonzero(new)
        self.epoch_j = int(j[-1])
        if not len(at):
            return
        ids = j[at]
        llh, vel = antenna(truth, at, v["lever_arm_m"])

        def white(stream, sigma):
            sigma = np.asarray(sigma, dtype=float)
            return np.column_stack([sigma[a] * update_normals(self.seed, self.m, f"{stream}.{a}", ids)
                                    if sigma[a] else np.zeros(len(ids)) for a in range(3)])
        d_pos = white("gnss.position_noise", v["position_noise"]) + self.position_markov.at(ids)
        d_vel = white("gnss.velocity_noise", v["velocity_noise"]) + self.velocity_markov.at(ids)
        valid_time = self.t0 + ids / v["rate_hz"]        # scene time of each solution's validity
        in_outage = np.zeros(len(ids), dtype=bool)
        for start, stop in v["outages_s"]:
            in_outage |= (valid_time >= start) & (valid_time < stop)
        self.count("gnss.outage_solutions", int(in_outage.sum()))
        position = offset_llh(llh, d_pos)
        velocity = vel + d_vel
        for k, jj in enumerate(ids.tolist()):
            self.pending[jj] = np.concatenate([position[k], velocity[k], [0.0 if in_outage[k] else 1.0]])

    def block(self, truth) -> dict[str, np.ndarray]:
        v = self.v
        self._solutions(truth)
        n = len(truth.s)
        r = update_index(truth.s, truth.rate_hz, v["rate_hz"], v["latency_s"])
        new = changes(r, self.report_j) & (r >= 0)
        reports = np.zeros((n, len(self.held)))
        for i in np.flatnonzero(new):       # a few a block (20 Hz at most); the rest hold them
            reports[i] = self._report(int(r[i]))
        rows = hold(new, reports, self.held)
        self.held = rows[-1].copy()
        self.report_j = int(r[-1])
        for jj in [k for k in self.pending if k <= self.report_j]:
            del self.pending[jj]
        out = {name: rows[:, _ROW[name]] for name in FIELDS if name not in ("gnss_new", "gnss_age_s")}
        out["gnss_new"] = new.astype(float)
        # age: from the time of validity of the solution held to the sample (0 before any solution)
        valid_j = rows[:, _ROW["solution"]]
        out["gnss_age_s"] = np.where(valid_j >= 0, truth.s / truth.rate_hz - valid_j / v["rate_hz"], 0.0)
        return out

    def _report(self, j: int) -> np.ndarray:
        v = self.v
        row = _empty_row()
        row[_ROW["solution"]] = j
        solution = self.pending.get(j)
        if solution is None:       # computed before a jump the run replays over: cannot happen in order
            raise RuntimeError(f"GNSS solution {j} was not computed")
        if solution[6]:
            self.last_valid = solution[:6]
            row[_ROW["gnss_llh"]] = solution[:3]
            row[_ROW["gnss_velocity_ned"]] = solution[3:6]
            row[_ROW["gnss_fix"]] = 3.0
            row[_ROW["gnss_satellites"]] = v["satellites"]
            row[_ROW["gnss_hdop"]], row[_ROW["gnss_vdop"]] = v["hdop"], v["vdop"]
            pos = np.hypot(np.asarray(v["position_noise"]), np.asarray(v["position_markov"]))
            vel = np.hypot(np.asarray(v["velocity_noise"]), np.asarray(v["velocity_markov"]))
            row[_ROW["gnss_horizontal_accuracy_m"]] = math.hypot(pos[0], pos[1])
            row[_ROW["gnss_vertical_accuracy_m"]] = pos[2]
            row[_ROW["gnss_speed_accuracy_mps"]] = float(np.linalg.norm(vel))
        else:
            row[_ROW["gnss_llh"]] = self.last_valid[:3]
            row[_ROW["gnss_velocity_ned"]] = self.last_valid[3:]
            row[_ROW["gnss_hdop"]] = row[_ROW["gnss_vdop"]] = 99.99
        return row


def _slots():
    slots, at = {}, 0
    for name, width in {**{k: w for k, w in FIELDS.items() if k not in ("gnss_new", "gnss_age_s")},
                        "solution": 0}.items():
        slots[name] = at if width == 0 else slice(at, at + width)
        at += max(width, 1)
    return slots


_ROW = _slots()


def _empty_row() -> np.ndarray:
    row = np.zeros(max(s.stop if isinstance(s, slice) else s + 1 for s in _ROW.values()))
    row[_ROW["solution"]] = -1
    row[_ROW["gnss_hdop"]] = row[_ROW["gnss_vdop"]] = 99.99     # no fix: the receivers' "unknown" DOP
    return row


def parse_outages(value, where: str):
    """outage intervals [[start_s, stop_s], ...] in scene seconds: no fix for solutions valid inside each"""
    if not isinstance(value, list) or len(value) > MAX_OUTAGES:
        raise SceneError(f"{where}: expected a list of [start_s, stop_s] pairs (at most {MAX_OUTAGES}), got "
                         f"{value!r}"[:200])
    outages = []
    for i, pair in enumerate(value):
        if (not isinstance(pair, list) or len(pair) != 2
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                           for x in pair) or not pair[0] < pair[1]):
            raise SceneError(f"{where}[{i}]: expected [start_s, stop_s] with start < stop, got {pair!r}"[:200])
        outages.append((float(pair[0]), float(pair[1])))
    return tuple(outages)


def validate(values: dict, where: str) -> None:
    lo, hi = RATE_RANGE_HZ
    if not lo <= values["rate_hz"] <= hi:
        raise SceneError(f"{where}.gnss.rate_hz: receivers give {lo:g} to {hi:g} solutions a second, got "
                         f"{values['rate_hz']!r}")
    if not 0 <= values["latency_s"] <= MAX_LATENCY_S:
        raise SceneError(f"{where}.gnss.latency_s: 0 to {MAX_LATENCY_S:g} s, got {values['latency_s']!r}")
    if not values["markov_time_s"] > 0:
        raise SceneError(f"{where}.gnss.markov_time_s: a time constant > 0 s, got {values['markov_time_s']!r}")
    check_sigmas(values, ("position_noise", "position_markov", "velocity_noise", "velocity_markov"), where, "gnss")
    if not (0 <= values["satellites"] <= 255 and float(values["satellites"]).is_integer()):
        raise SceneError(f"{where}.gnss.satellites: an integer 0..255, got {values['satellites']!r}")
    for key in ("hdop", "vdop"):
        if not 0 <= values[key] <= 99.99:
            raise SceneError(f"{where}.gnss.{key}: 0 to 99.99, got {values[key]!r}")
    if max(abs(x) for x in values["lever_arm_m"]) > 1e3:
        raise SceneError(f"{where}.gnss.lever_arm_m: each |value| <= 1000 m")


_param = param_maker("gnss")


COMPANION = Companion(
    name="gnss",
    description="GNSS receiver: antenna position and velocity with white and Gauss-Markov errors, latency, "
                "rate, fix, satellites, DOP, outages",
    fields=FIELDS, start=_Receiver, validate=validate, extra={"outages_s": parse_outages},
    params=(_param("rate_hz", "Hz", "solutions a second (1 to 20)", default=5.0, datasheet="`10 Hz`"),
            _param("latency_s", "s", "from a solution's time of validity to its output", default=0.0,
                   datasheet="`50 ms`"),
            _param("lever_arm_m", "m", "antenna position from the reference point S, scene body axes", "triple",
                   (0.0, 0.0, 0.0), "`[0.5, 0, -0.3]`"),
            _param("position_noise", "m", "white position error, 1 sigma north, east, down", "vector3",
                   datasheet="`[0.3, 0.3, 0.6]`"),
            _param("position_markov", "m", "Gauss-Markov position error, 1 sigma north, east, down", "vector3",
                   datasheet="`[1.0, 1.0, 2.0]`, `2.5 m` (CEP-like)"),
            _param("velocity_noise", "m/s", "white velocity error, 1 sigma north, east, down", "vector3",
                   datasheet="`0.05 m/s`"),
            _param("velocity_markov", "m/s", "Gauss-Markov velocity error, 1 sigma north, east, down", "vector3",
                   datasheet="`0.02 m/s`"),
            _param("markov_time_s", "s", "time constant of the Gauss-Markov errors", default=100.0,
                   datasheet="`100 s`, `2 min`"),
            _param("satellites", "1", "satellites used, reported with a fix", default=12.0, datasheet="`12`"),
            _param("hdop", "1", "horizontal dilution of precision reported with a fix", default=0.8),
            _param("vdop", "1", "vertical dilution of precision reported with a fix", default=1.2)))
