"""What GNSS-carrying formats report besides position and velocity: UTC and GPS time from the sample time,
receiver quality figures, and the records built from them (Xsens UtcTime and GnssPvtData).

Time, the one rule of every wire format and file: Samples.time_ns is UTC nanoseconds since the Unix epoch, the
run's start (`generate`/`stream --start-time ISO8601|now`, default 2024-01-01T00:00:00Z,
imu_emulator.output.ros2.conventions.DEFAULT_START) plus the scene time. Every format derives GPS time, GPS
week / time of week, UTC calendar fields and leap seconds from it here: GPS time = UTC + leap seconds (18 since
2017-01-01, the `leap_seconds` setting) - 315 964 800 s (the GPS epoch, 1980-01-06, in Unix time). Leap seconds
are one constant for the run (no table: a run crossing a leap second is off by it from then on).

Quality: a healthy receiver under open sky by default (GNSS_DEFAULTS); DOPs follow from their north, east,
vertical and time parts (h^2 = n^2 + e^2, p^2 = h^2 + v^2, g^2 = p^2 + t^2), so a reader that checks their
consistency finds it.
"""
from __future__ import annotations

import math

import numpy as np

GPS_EPOCH_UNIX_S = 315_964_800
WEEK_MS = 7 * 86_400_000
WEEK_NS = WEEK_MS * 1_000_000
#: The one-line answer to an encoder or device option that used to shift GPS time by whole weeks.
GPS_WEEK_OFFSET_RETIRED = ("gps_week_offset: retired; GPS time now follows the run's start: "
                           "--start-time ISO8601|now (UTC) plus the scene time")
GNSS_DEFAULTS = {
    "leap_seconds": 18,
    "num_sats": 12,
    "fix_type": 3,            # 3D fix (u-blox / Xsens fixType)
    "h_acc_m": 1.0, "v_acc_m": 1.5, "s_acc_mps": 0.05, "t_acc_ns": 20.0, "head_acc_deg": 1.0,
    "dop_n": 0.6, "dop_e": 0.6, "dop_v": 1.0, "dop_t": 0.8,
}
_INTEGERS = {"leap_seconds": (0, 100), "num_sats": (0, 255), "fix_type": (0, 5)}


def dops(north: float, east: float, vertical: float, time: float) -> tuple:
    """The seven DOPs in the order receivers list them: g, p, t, v, h, n, e."""
    h = math.hypot(north, east)
    p = math.hypot(h, vertical)
    return (math.hypot(p, time), p, time, vertical, h, north, east)


def gnss_settings(overrides: dict | None) -> dict:
    """GNSS_DEFAULTS updated by `overrides`, validated (names, integer ranges, finite non-negative values)."""
    settings = dict(GNSS_DEFAULTS)
    for name, value in (overrides or {}).items():
        if name not in GNSS_DEFAULTS:
            raise ValueError(f"gnss: unknown setting {name!r} (known: {', '.join(GNSS_DEFAULTS)})")
        if name in _INTEGERS:
            lo, hi = _INTEGERS[name]
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
                raise ValueError(f"gnss.{name}: an integer {lo}..{hi}, got {value!r}")
        elif isinstance(value, bool) or not isinstance(value, (int, float)) or not (0 <= value < math.inf):
            raise ValueError(f"gnss.{name}: a finite number >= 0, got {value!r}")
        settings[name] = value
    return settings


def gps_offset_ns(leap_seconds: int = GNSS_DEFAULTS["leap_seconds"]) -> int:
    """GPS time - time_ns, ns: leap seconds - the GPS epoch's Unix time (negative: GPS time counts from 1980)."""
    return (int(leap_seconds) - GPS_EPOCH_UNIX_S) * 1_000_000_000


def gps_ns(time_ns, leap_seconds: int = GNSS_DEFAULTS["leap_seconds"]) -> np.ndarray:
    """GPS time in ns since the GPS epoch (1980-01-06 00:00:00 GPS) of Unix-epoch UTC nanoseconds."""
    return np.asarray(time_ns, dtype=np.int64) + np.int64(gps_offset_ns(leap_seconds))


def gps_week_tow_ns(time_ns, leap_seconds: int = GNSS_DEFAULTS["leap_seconds"]) -> tuple:
    """(GPS week, ns into the week) of Unix-epoch UTC nanoseconds; weeks count from 1980-01-06 without the
    1024-week rollover."""
    return np.divmod(gps_ns(time_ns, leap_seconds), np.int64(WEEK_NS))


def _calendar(time_ns: np.ndarray) -> tuple:
    """UTC calendar fields of Unix-epoch nanoseconds: year, month, day, hour, minute, second, nanosecond."""
    t = np.asarray(time_ns, dtype=np.int64)
    days = t.astype("datetime64[ns]").astype("datetime64[D]")
    months = days.astype("datetime64[M]")
    year = months.astype("datetime64[Y]").astype(np.int64) + 1970
    month = months.astype(np.int64) % 12 + 1
    day = (days - months).astype(np.int64) + 1
    of_day = t - days.astype(np.int64) * 86_400_000_000_000
    second, nano = np.divmod(of_day, 1_000_000_000)
    hour, second = np.divmod(second, 3600)
    minute, second = np.divmod(second, 60)
    return year, month, day, hour, minute, second, nano


def utc_rows(time_ns: np.ndarray, settings: dict) -> np.ndarray:
    """(n, 8) Xsens UtcTime: nano, year, month, day, hour, minute, second, flags (0x07: time of week, week
    number and UTC valid)."""
    year, month, day, hour, minute, second, nano = _calendar(time_ns)
    flags = np.full(len(year), 0x07)
    return np.column_stack((nano, year, month, day, hour, minute, second, flags)).astype(np.float64)


def gnss_pvt_rows(time_ns: np.ndarray, position_llh: np.ndarray, velocity_ned: np.ndarray,
                  settings: dict) -> np.ndarray:
    """(n, 35) Xsens GnssPvtData in wire units (see firmware_protocols.wire_formats.xsens for the layout)."""
    n = len(time_ns)
    year, month, day, hour, minute, second, nano = _calendar(time_ns)
    itow = gps_week_tow_ns(time_ns, settings["leap_seconds"])[1] // 1_000_000
    lat, lon, height = position_llh[:, 0], position_llh[:, 1], position_llh[:, 2]
    vn, ve, vd = velocity_ned[:, 0], velocity_ned[:, 1], velocity_ned[:, 2]
    heading = np.degrees(np.arctan2(ve, vn)) % 360.0
    s = settings
    dop = dops(s["dop_n"], s["dop_e"], s["dop_v"], s["dop_t"])

    def const(value):
        return np.full(n, float(value))

    columns = [itow, year, month, day, hour, minute, second, const(0x07),       # valid: date, time, resolved
               const(s["t_acc_ns"]), nano, const(s["fix_type"]), const(0x01 if s["fix_type"] >= 2 else 0),
               const(s["num_sats"]), const(0),
               lon * 1e7, lat * 1e7, height * 1e3, height * 1e3,     # no geoid model: hMSL = ellipsoid height
               const(s["h_acc_m"] * 1e3), const(s["v_acc_m"] * 1e3),
               vn * 1e3, ve * 1e3, vd * 1e3, np.hypot(vn, ve) * 1e3, heading * 1e5,
               const(s["s_acc_mps"] * 1e3), const(s["head_acc_deg"] * 1e5), const(0)]   # headVeh: not valid
    columns += [const(d * 100.0) for d in dop]
    return np.column_stack(columns).astype(np.float64)


def receiver_solution(samples) -> dict:
    """The GNSS receiver's solution of a Samples block in SI, for formats that send a fix: its gnss_* fields; without
    gnss_llh, the block's position_llh / velocity_ned with a 3D fix; without either, zeros and fix 0. Each quality
    figure that is None takes its GNSS_DEFAULTS value (HDOP = hypot(dop_n, dop_e), VDOP = dop_v). Keys: llh, vel,
    fix (0 no fix, 2 2D, 3 3D), sats, hdop, vdop, h_acc, v_acc, s_acc (1-sigma, m and m/s)."""
    n, d = len(samples), GNSS_DEFAULTS
    if samples.gnss_llh is not None:
        llh, vel = samples.gnss_llh, samples.field_or("gnss_velocity_ned", (0.0, 0.0, 0.0))
        fix = samples.field_or("gnss_fix", d["fix_type"])
    elif samples.position_llh is not None:
        llh, vel = samples.position_llh, samples.field_or("velocity_ned", (0.0, 0.0, 0.0))
        fix = np.full(n, float(d["fix_type"]))
    else:
        llh, vel, fix = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)
    return {"llh": llh, "vel": vel, "fix": fix, "sats": samples.field_or("gnss_satellites", d["num_sats"]),
            "hdop": samples.field_or("gnss_hdop", math.hypot(d["dop_n"], d["dop_e"])),
            "vdop": samples.field_or("gnss_vdop", d["dop_v"]),
            "h_acc": samples.field_or("gnss_horizontal_accuracy_m", d["h_acc_m"]),
            "v_acc": samples.field_or("gnss_vertical_accuracy_m", d["v_acc_m"]),
            "s_acc": samples.field_or("gnss_speed_accuracy_mps", d["s_acc_mps"])}
