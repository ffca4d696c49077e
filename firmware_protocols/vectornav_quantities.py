"""The quantities VectorNav's binary output carries that no Samples field holds as such, computed from the ones
it does (firmware_protocols.wire_formats.vectornav_binary packs them): the INS estimate in ECEF and body axes,
the attitude group's NED vectors, the uncertainties and status words, the GNSS receiver's solution, and the
time fields.

Each function takes a Samples block and returns an (n, width) array in VectorNav's units, or None when the
samples lack what it needs, so the encoder falls back to its documented default (or a caller's constant).

Frames (VectorNav ICD, as the wire format states): vectors in the part's body axes forward-right-down; quat
rotates body -> NED (Samples' own convention, so nothing converts); ECEF from WGS-84 geodetic position in closed
form. Times: time_ns is UTC Unix ns (firmware_protocols.gnss_time's rule), GPS time = time_ns + 18 leap
seconds - the GPS epoch (gnss_time.gps_offset_ns), UTC fields = GPS time - leap seconds, the receiver's PPS
edges and the SyncIn input on whole GPS seconds (the SyncIn pin modelled as wired to the receiver's PPS, the usual
installation).
"""
from __future__ import annotations

import numpy as np

from firmware_protocols.gnss_time import GNSS_DEFAULTS, GPS_EPOCH_UNIX_S, dops
from imu_emulator.native.lazy import jit

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
DEG = 180.0 / np.pi
SECOND_NS = 1_000_000_000
LEAP_SECONDS = GNSS_DEFAULTS["leap_seconds"]


# The device encodes one sample at a time just before its deadline, where numpy's per-call overhead on rows of
# one (40-70 us per rotated quantity, 28 us for a calendar) would eat the serve margin: the per-row arithmetic is
# compiled instead. Inputs are C-contiguous float64 (n, k) blocks; `out` is (n, 3).

@jit(cache=True, nogil=True)
def _rotate(quat, vectors, inverse, out):
    """out[i] = R(quat[i]) vectors[i] (body -> NED), or R^T vectors[i] when `inverse` (NED -> body)."""
    for i in range(out.shape[0]):
        w, x, y, z = quat[i, 0], quat[i, 1], quat[i, 2], quat[i, 3]
        norm = np.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / norm, x / norm, y / norm, z / norm
        r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
        r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
        r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
        a, b, c = vectors[i, 0], vectors[i, 1], vectors[i, 2]
        if inverse:
            out[i, 0] = r00 * a + r10 * b + r20 * c
            out[i, 1] = r01 * a + r11 * b + r21 * c
            out[i, 2] = r02 * a + r12 * b + r22 * c
        else:
            out[i, 0] = r00 * a + r01 * b + r02 * c
            out[i, 1] = r10 * a + r11 * b + r12 * c
            out[i, 2] = r20 * a + r21 * b + r22 * c


@jit(cache=True, nogil=True)
def _ned_to_ecef(llh, ned, out):
    """out[i] = the NED vector ned[i] in ECEF axes at latitude, longitude llh[i, :2] (deg)."""
    for i in range(out.shape[0]):
        lat, lon = np.radians(llh[i, 0]), np.radians(llh[i, 1])
        sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
        n, e, d = ned[i, 0], ned[i, 1], ned[i, 2]
        out[i, 0] = -sl * co * n - so * e - cl * co * d
        out[i, 1] = -sl * so * n + co * e - cl * so * d
        out[i, 2] = cl * n - sl * d


@jit(cache=True, nogil=True)
def _ecef_position(llh, a, e2, out):
    for i in range(out.shape[0]):
        lat, lon, h = np.radians(llh[i, 0]), np.radians(llh[i, 1]), llh[i, 2]
        n = a / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
        out[i, 0] = (n + h) * np.cos(lat) * np.cos(lon)
        out[i, 1] = (n + h) * np.cos(lat) * np.sin(lon)
        out[i, 2] = (n * (1.0 - e2) + h) * np.sin(lat)


@jit(cache=True, nogil=True)
def _utc(unix_ns, out):
    """out[i] = year - 2000, month, day, hour, minute, second, millisecond of Unix-epoch ns (UTC, no leap second
    inside): the proleptic Gregorian calendar from days since 1970 (H. Hinnant's civil_from_days)."""
    for i in range(out.shape[0]):
        t = unix_ns[i]
        days = t // 86_400_000_000_000
        of_day = t - days * 86_400_000_000_000
        z = days + 719_468
        era = z // 146_097
        doe = z - era * 146_097
        yoe = (doe - doe // 1460 + doe // 36_524 - doe // 146_096) // 365
        doy = doe - (365 * yoe + yoe // 4 - yoe // 100)
        mp = (5 * doy + 2) // 153
        day = doy - (153 * mp + 2) // 5 + 1
        month = mp + 3 if mp < 10 else mp - 9
        year = yoe + era * 400 + (1 if month <= 2 else 0)
        seconds = of_day // 1_000_000_000
        out[i, 0] = year - 2000
        out[i, 1] = month
        out[i, 2] = day
        out[i, 3] = seconds // 3600
        out[i, 4] = seconds // 60 % 60
        out[i, 5] = seconds % 60
        out[i, 6] = of_day % 1_000_000_000 // 1_000_000


def _rows(values, width: int) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64).reshape(-1, width)


def ecef_position(position_llh: np.ndarray) -> np.ndarray:
    """(n, 3) WGS-84 geodetic latitude, longitude (deg), ellipsoidal height (m) -> ECEF x, y, z (m)."""
    llh = _rows(position_llh, 3)
    out = np.empty_like(llh)
    _ecef_position(llh, WGS84_A, WGS84_E2, out)
    return out


def ned_to_ecef(position_llh: np.ndarray, ned: np.ndarray) -> np.ndarray:
    ned = _rows(ned, 3)
    out = np.empty_like(ned)
    _ned_to_ecef(_rows(position_llh, 3), ned, out)
    return out


def rotate(quat: np.ndarray, vectors: np.ndarray, inverse: bool = False) -> np.ndarray:
    """(n, 3) vectors rotated body -> NED by the (n, 4) quaternions, or NED -> body when `inverse`."""
    vectors = _rows(vectors, 3)
    out = np.empty_like(vectors)
    _rotate(_rows(quat, 4), vectors, bool(inverse), out)
    return out


def gps_time_ns(time_ns: np.ndarray, gps_offset_ns: int) -> np.ndarray:
    """GPS time of time_ns (UTC Unix ns; negative: 0) + `gps_offset_ns` (gnss_time.gps_offset_ns, <= 0), before the
    GPS epoch 0, as the packing kernel's GPS time is (the wire fields built from it then saturate, counted)."""
    t = np.maximum(np.asarray(time_ns, dtype=np.int64), 0)
    return np.maximum(t + np.int64(gps_offset_ns), 0)


def utc_fields(time_ns: np.ndarray, gps_offset_ns: int) -> np.ndarray:
    """(n, 7) VectorNav TimeUtc: year - 2000 (int8), month, day, hour, minute, second, millisecond."""
    shift = (GPS_EPOCH_UNIX_S - LEAP_SECONDS) * SECOND_NS
    unix_ns = gps_time_ns(time_ns, gps_offset_ns) + np.int64(shift)
    out = np.empty((len(unix_ns), 7))
    _utc(np.ascontiguousarray(unix_ns), out)
    return out


def since_pps(time_ns: np.ndarray, gps_offset_ns: int) -> np.ndarray:
    """(n, 1) ns since the last PPS edge (whole GPS seconds): TimeGpsPps, and TimeSyncIn (SyncIn on the PPS)."""
    return (gps_time_ns(time_ns, gps_offset_ns) % SECOND_NS).astype(np.float64).reshape(-1, 1)


def sync_in_count(time_ns: np.ndarray) -> np.ndarray:
    """(n, 1) SyncIn edges since start-up: the whole seconds elapsed on the sample clock (u32 on the wire;
    the PPS edges fall on whole seconds of time_ns too, since GPS - UTC is whole seconds)."""
    return (np.maximum(np.asarray(time_ns, dtype=np.int64), 0) // SECOND_NS).astype(np.float64).reshape(-1, 1)


def ins_status(samples, fix_default: float) -> np.ndarray:
    """(n, 1) InsStatus: bits 0-1 the filter mode (Samples.ins_mode: 0 not tracking, 1 aligning, 2 tracking;
    tracking when the samples carry none), bit 2 GNSS fix (a 3D fix; `fix_default` when the samples carry no
    gnss_fix)."""
    mode = samples.field_or("ins_mode", 2.0)
    fix = samples.field_or("gnss_fix", fix_default)
    return (np.clip(np.rint(mode), 0, 3) + 4.0 * (fix >= 3)).reshape(-1, 1)


def gnss_dops(samples) -> np.ndarray | None:
    """(n, 7) g, p, t, v, h, n, e from the receiver's HDOP / VDOP (north = east = HDOP / sqrt 2, the time
    part the default's), so the seven stay consistent; None when the samples carry neither."""
    if samples.gnss_hdop is None and samples.gnss_vdop is None:
        return None
    d = GNSS_DEFAULTS
    h = samples.field_or("gnss_hdop", float(np.hypot(d["dop_n"], d["dop_e"])))
    v = samples.field_or("gnss_vdop", float(d["dop_v"]))
    t = np.full_like(h, float(d["dop_t"]))
    p = np.hypot(h, v)
    return np.column_stack((np.hypot(p, t), p, t, v, h, h / np.sqrt(2.0), h / np.sqrt(2.0)))


def time_valid(samples, fix_default: float) -> np.ndarray:
    """(n,) 7 (time of week, week and UTC valid) while the receiver has any fix, else 0: TimeStatus, TimeInfo."""
    return 7.0 * (samples.field_or("gnss_fix", fix_default) >= 1)


def sigma_norm(values: np.ndarray | None) -> np.ndarray | None:
    """(n, 1) the 3-D 1-sigma (root sum of squares of north, east, down): VectorNav's scalar PosU / VelU."""
    return None if values is None else np.sqrt(np.sum(values ** 2, axis=1, keepdims=True))


def ypr_uncertainty(samples) -> np.ndarray | None:
    """(n, 3) YprU: yaw, pitch, roll 1-sigma in degrees from Samples.attitude_sigma_rad (roll, pitch, yaw)."""
    sigma = samples.attitude_sigma_rad
    return None if sigma is None else sigma[:, ::-1] * DEG


def gnss_position_uncertainty(samples) -> np.ndarray | None:
    """(n, 3) GPS PosU north, east, down: the horizontal accuracy on both horizontal axes, the vertical down."""
    if samples.gnss_horizontal_accuracy_m is None and samples.gnss_vertical_accuracy_m is None:
        return None
    h = samples.field_or("gnss_horizontal_accuracy_m", 1.0)
    v = samples.field_or("gnss_vertical_accuracy_m", 1.5)
    return np.column_stack((h, h, v))


def rotated(samples, vector: str, default, to: str) -> np.ndarray:
    """A body vector (`vector`, e.g. "accel") in NED (`to` "ned") or ECEF ("ecef"); or an NED vector in body
    axes ("body"). The attitude and position are the samples' own, else the encoder's defaults (`default`:
    name -> one row)."""
    n = len(samples)
    quat = samples.quat if samples.quat is not None else np.broadcast_to(default("quat"), (n, 4))
    value = getattr(samples, vector)
    value = np.broadcast_to(default(vector), (n, 3)) if value is None else value
    if to == "body":
        return rotate(quat, value, inverse=True)
    ned = rotate(quat, value)
    return ned if to == "ned" else ecef_vector(samples, ned, default)


def ecef_vector(samples, ned: np.ndarray, default, position_name: str = "position_llh") -> np.ndarray:
    """NED vectors in ECEF axes at the samples' position (`position_name`, falling back as `position` does)."""
    return ned_to_ecef(position(samples, default, position_name), ned)


def position(samples, default, name: str = "position_llh") -> np.ndarray:
    """(n, 3) the named position (gnss_llh falls back on the INS position_llh, then the default)."""
    llh = getattr(samples, name)
    if llh is None and name != "position_llh":
        llh = samples.position_llh
    return np.broadcast_to(default("position_llh"), (len(samples), 3)) if llh is None else llh


def velocity(samples, default, name: str = "velocity_ned") -> np.ndarray:
    vel = getattr(samples, name)
    if vel is None and name != "velocity_ned":
        vel = samples.velocity_ned
    return np.broadcast_to(default("velocity_ned"), (len(samples), 3)) if vel is None else vel


__all__ = ["dops", "ecef_position", "ned_to_ecef", "rotate", "utc_fields", "since_pps", "sync_in_count",
           "ins_status", "time_valid", "gnss_dops", "sigma_norm", "ypr_uncertainty", "gnss_position_uncertainty",
           "rotated", "ecef_vector", "position", "velocity"]
