"""Barometer: static pressure of the ICAO Standard Atmosphere at the true height, through the part's errors; and
the pitot's differential pressure from the airspeed, for formats that carry one.

Atmosphere: ICAO Doc 7488/3 (= ISO 2533:1975, = U.S. Standard Atmosphere 1976 below 86 km) in closed form:
geopotential height H = r0 h / (r0 + h) (r0 = 6 356 766 m), then per layer with base H_b, T_b, p_b and lapse
rate L: T = T_b + L (H - H_b), p = p_b (T_b / T)^(g0 / (R L)) or, where L = 0, p_b exp(-g0 (H - H_b) / (R T_b));
g0 = 9.80665 m/s^2, R = 287.05287 J/(kg K). The closed form is a dozen lines; a package (ambiance) is used by
the tests as the oracle, beside the standard's own table. The height is the WGS-84 ellipsoidal height (no geoid
model, as the wire formats' "MSL" heights here); below -5 km or above 84.852 km of geopotential height
(the standard's range) the pressure is clipped to the range's end and counted.

Measurement at `rate_hz`, held between updates:
    p = p_ISA(h) + bias + drift t + temperature_coefficient (T - T0) + noise,  rounded to resolution
T is the IMU's temperature profile ([[imu]] temperature_c, warm-up; imu_emulator.effects.temperature) and T0 its
temperature_ref_c; baro_temperature_c reports T. The pitot reads q = rho u |u| / 2 with u the velocity along the
body's forward axis (still air; rho the ISA density) plus its own white noise.
"""
from __future__ import annotations

import numpy as np

from imu_emulator.companions._record import Companion, Held, Runner, param_maker, update_normals
from imu_emulator.errors import SceneError

G0 = 9.80665
R_AIR = 287.05287            # R* / M0 = 8.31432 / 0.0289644
EARTH_RADIUS_M = 6_356_766.0   # r0 of the geopotential height
#: layers: base geopotential height (m), lapse rate (K/m); base temperature and pressure follow from them
_LAYERS = ((-5000.0, -0.0065), (11000.0, 0.0), (20000.0, 0.001), (32000.0, 0.0028), (47000.0, 0.0),
           (51000.0, -0.0028), (71000.0, -0.002))
TOP_M = 84852.0
SEA_LEVEL = (288.15, 101325.0)    # K, Pa at H = 0


def _bases():
    """(H_b, L, T_b, p_b) of each layer, from sea level down to -5 km and then up layer by layer."""
    t0, p0 = SEA_LEVEL
    h_b, lapse = _LAYERS[0]
    t_b = t0 + lapse * (h_b - 0.0)
    p_b = p0 * (t0 / t_b) ** (G0 / (R_AIR * lapse))
    bases = []
    for i, (h_b, lapse) in enumerate(_LAYERS):
        bases.append((h_b, lapse, t_b, p_b))
        top = _LAYERS[i + 1][0] if i + 1 < len(_LAYERS) else TOP_M
        t_b, p_b = _layer(top, h_b, lapse, t_b, p_b)
    return tuple(bases)


def _layer(h, h_b, lapse, t_b, p_b):
    if lapse == 0.0:
        return np.full_like(np.asarray(h, float), t_b), p_b * np.exp(-G0 * (np.asarray(h) - h_b) / (R_AIR * t_b))
    t = t_b + lapse * (np.asarray(h) - h_b)
    return t, p_b * (t_b / t) ** (G0 / (R_AIR * lapse))


_BASES = _bases()


def geopotential(h_m):
    """Geopotential height (m') of a geometric height (m)."""
    h = np.asarray(h_m, dtype=float)
    return EARTH_RADIUS_M * h / (EARTH_RADIUS_M + h)


def isa_geopotential(h_geopotential) -> tuple[np.ndarray, np.ndarray]:
    """(temperature K, pressure Pa) of the standard atmosphere at geopotential heights within [-5000, 84852] m'."""
    h = np.atleast_1d(np.asarray(h_geopotential, dtype=float))
    t, p = np.empty_like(h), np.empty_like(h)
    layer = np.searchsorted([b[0] for b in _BASES], h, side="right") - 1
    for i, (h_b, lapse, t_b, p_b) in enumerate(_BASES):
        at = layer == i
        if at.any():
            t[at], p[at] = _layer(h[at], h_b, lapse, t_b, p_b)
    return t, p


def isa(h_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(temperature K, pressure Pa, density kg/m^3) at geometric heights h_m, clipped to the standard's range."""
    h = np.clip(geopotential(h_m), _LAYERS[0][0], TOP_M)
    t, p = isa_geopotential(h)
    return t, p, p / (R_AIR * t)


class _Barometer(Runner):
    def __init__(self, scene, m: int, values: dict):
        super().__init__()
        self.seed, self.m, self.v = scene.seed, m, values
        self.held = Held(values["rate_hz"], 3)

    def block(self, truth) -> dict[str, np.ndarray]:
        out, new = self.held.block(truth, lambda at, ids: self._measure(truth, at, ids))
        return {"pressure_pa": out[:, 0], "baro_temperature_c": out[:, 1], "differential_pressure_pa": out[:, 2],
                "baro_new": new}        # 1 where a reading arrives (Samples.baro_new)

    def _measure(self, truth, at: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """(len(at), 3) pressure, temperature and differential pressure of the updates ids at samples at."""
        from imu_emulator.effects.temperature import profile
        v = self.v
        h = truth.llh[at, 2]
        outside = (geopotential(h) < _LAYERS[0][0]) | (geopotential(h) > TOP_M)
        self.count("barometer.range", int(outside.sum()))
        _, p, rho = isa(h)
        temperature = np.broadcast_to(profile(truth.values, truth.t[at]), (len(at),))
        p = (p + v["bias"] + v["drift"] * truth.t[at]
             + v["temperature_coefficient"] * (temperature - truth.values["imu.temperature_ref_c"]))
        if v["noise"]:
            p = p + v["noise"] * update_normals(self.seed, self.m, "barometer.noise", ids)
        if v["resolution"]:
            p = np.round(p / v["resolution"]) * v["resolution"]
        forward = np.einsum("ni,ni->n", truth.c_nb[at, :, 0], truth.v_ned[at])    # body x in NED . v
        q = 0.5 * rho * forward * np.abs(forward)
        if v["differential_noise"]:
            q = q + v["differential_noise"] * update_normals(self.seed, self.m, "barometer.differential_noise", ids)
        return np.column_stack([p, temperature, q])


def validate(values: dict, where: str) -> None:
    if not 0 < values["rate_hz"] <= 1e5:
        raise SceneError(f"{where}.barometer.rate_hz: a rate in (0, 100000] Hz, got {values['rate_hz']!r}")
    for key in ("noise", "resolution", "differential_noise"):
        if values[key] < 0:
            raise SceneError(f"{where}.barometer.{key}: a value >= 0, got {values[key]!r}")


_scalar = param_maker("barometer")


def _param(key, unit, description, default=0.0, datasheet=""):
    return _scalar(key, unit, description, default=default, datasheet=datasheet)


COMPANION = Companion(
    name="barometer",
    description="static pressure of the ICAO standard atmosphere at the true height, with its errors; pitot "
                "differential pressure",
    fields={"pressure_pa": 0, "baro_temperature_c": 0, "differential_pressure_pa": 0, "baro_new": 0},
    start=_Barometer, validate=validate,
    params=(_param("rate_hz", "Hz", "output data rate; held between updates", 50.0, "`50 Hz`"),
            _param("noise", "Pa", "white noise, 1 sigma per update (the datasheet's RMS noise)", 0.0,
                   "`1.2 Pa`, `0.012 hPa`, `0.03 mbar`"),
            _param("bias", "Pa", "constant offset (absolute accuracy)", 0.0, "`-50 Pa`, `0.5 hPa`"),
            _param("drift", "Pa/s", "offset growing linearly with the scene time", 0.0, "`1 hPa/year`, `0.1 Pa/h`"),
            _param("temperature_coefficient", "Pa/K", "offset per kelvin from the IMU's temperature_ref_c", 0.0,
                   "`1.5 Pa/K`"),
            _param("resolution", "Pa", "output step (0: none)", 0.0, "`0.016 Pa`, `0.01 hPa`"),
            _param("differential_noise", "Pa", "pitot (differential pressure) white noise, 1 sigma per update", 0.0,
                   "`0.5 Pa`")))
