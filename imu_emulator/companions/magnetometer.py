"""Magnetometer: the Earth's main field from the World Magnetic Model at the body's position, in the sensor's axes,
through the part's errors.

The model is NOAA/NCEI's WMM2025 (valid 2025.0-2030.0) as pygeomag evaluates it: a pure-Python package (no
compiled code to build), MIT licence, carrying NOAA's own WMM2025.COF coefficients and reproducing NOAA's test
value table (tests/companions/test_companions.py). geomaglib is NOAA's reference port but needs its own wheels; ppigrf is
IGRF (a different model, fine for science, not what navigation parts compensate with). The field is evaluated
at `date_year` (secular variation over a run, ~100 nT a year, is far below a part's noise) and memoised per
cell of CELL_DEG x CELL_DEG x CELL_M around the position: the main field changes by less than 0.02 nT
across a cell (its gradient is below ~20 nT/km at the surface), some 1e-7 gauss, so a moving vehicle costs
a model evaluation (~0.2 ms) per cell it enters, not per sample.

Measurement, in the sensor's axes, at `rate_hz` and held between updates:
    m = S (C_sn^T B_ned) + hard_iron + b_turn_on + noise,   then clipped to +-range, rounded to resolution
where S is the soft-iron matrix (identity when none), b_turn_on is drawn once per run (turn_on_bias, 1 sigma) and
the noise is white with density noise_density (sigma = density sqrt(rate_hz) per update). Gauss: 1 G = 1e-4 T,
the unit Samples.mag and the wire formats' fields start from. The random draws (noise, turn-on bias) belong to the
part's own forward-right-down axes: an ENU scene's sensor axes are forward-left-up, so its y and z draws are
negated, and the same motion written as an ENU or a NED scene reads the same field, noise included (the
parameters themselves, hard_iron, soft_iron, are in the scene's sensor axes, as every vector of the scene).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from imu_emulator.companions._record import Companion, Held, Runner, normals, param_maker, update_normals
from imu_emulator.errors import SceneError

CELL_DEG = 1e-4          # ~11 m of latitude
CELL_M = 10.0
NT_PER_GAUSS = 1e5
MODEL_YEARS = (2025.0, 2030.0)     # WMM2025's life span


@lru_cache(maxsize=1)
def _model():
    from pygeomag import GeoMag
    return GeoMag(coefficients_file="wmm/WMM_2025.COF", high_resolution=False)


@lru_cache(maxsize=65536)
def _cell_field(lat_cell: int, lon_cell: int, h_cell: int, year: float) -> tuple[float, float, float]:
    result = _model().calculate(glat=lat_cell * CELL_DEG, glon=lon_cell * CELL_DEG, alt=h_cell * CELL_M / 1000.0,
                                time=year)
    return (result.x / NT_PER_GAUSS, result.y / NT_PER_GAUSS, result.z / NT_PER_GAUSS)


def field_ned(llh: np.ndarray, year: float) -> np.ndarray:
    """(n, 3) the main field north, east, down in gauss at geodetic (lat deg, lon deg, height m) positions,
    WMM2025 at the decimal year `year` (evaluated at the centre of each position's memoised cell)."""
    llh = np.asarray(llh, dtype=float).reshape(-1, 3)
    lon = (llh[:, 1] + 180.0) % 360.0 - 180.0
    cells = np.column_stack([np.rint(llh[:, 0] / CELL_DEG), np.rint(lon / CELL_DEG),
                             np.rint(llh[:, 2] / CELL_M)]).astype(np.int64)
    unique, inverse = np.unique(cells, axis=0, return_inverse=True)
    values = np.array([_cell_field(int(a), int(b), int(c), float(year)) for a, b, c in unique])
    return values[inverse.reshape(-1)]


class _Magnetometer(Runner):
    def __init__(self, scene, m: int, values: dict):
        super().__init__()
        self.seed, self.m, self.v = scene.seed, m, values
        # the draws' signs in the scene's sensor axes: forward-right-down draws seen in forward-left-up axes
        self.frd = np.array([1.0, -1.0, -1.0]) if scene.frame == "ENU" else np.ones(3)
        self.soft = np.asarray(values["soft_iron"], dtype=float)
        self.offset = np.asarray(values["hard_iron"], dtype=float) + np.asarray(values["turn_on_bias"]) * self.frd * (
            np.array([normals(scene.seed, m, f"magnetometer.turn_on.{axis}", 0, 1)[0] for axis in range(3)]))
        self.held = Held(values["rate_hz"], 3)

    def block(self, truth) -> dict[str, np.ndarray]:
        mag, new = self.held.block(truth, lambda at, ids: self._measure(truth, at, ids))
        return {"mag": mag, "mag_new": new}     # 1 where a reading arrives (Samples.mag_new)

    def _measure(self, truth, at: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """(len(at), 3) the readings of the updates ids at samples at, sensor axes."""
        v = self.v
        b_ned = field_ned(truth.llh[at], v["date_year"])
        b_sensor = np.einsum("nji,nj->ni", truth.c_ns[at], b_ned)          # C_sn = C_ns^T
        measured = b_sensor @ self.soft.T + self.offset
        sigma = np.asarray(v["noise_density"]) * np.sqrt(v["rate_hz"])
        for axis in range(3):
            if sigma[axis]:
                draws = update_normals(self.seed, self.m, f"magnetometer.noise.{axis}", ids)
                measured[:, axis] += self.frd[axis] * sigma[axis] * draws
        full_scale = np.asarray(v["range"])
        if full_scale.any():
            limit = np.where(full_scale > 0, full_scale, np.inf)
            self.count("magnetometer.range", int((np.abs(measured) > limit).sum()))
            measured = np.clip(measured, -limit, limit)
        step = np.asarray(v["resolution"])
        return np.where(step > 0, np.round(measured / np.where(step > 0, step, 1.0)) * step, measured)


def validate(values: dict, where: str) -> None:
    if not 0 < values["rate_hz"] <= 1e5:
        raise SceneError(f"{where}.magnetometer.rate_hz: a rate in (0, 100000] Hz, got {values['rate_hz']!r}")
    if not MODEL_YEARS[0] <= values["date_year"] <= MODEL_YEARS[1]:
        raise SceneError(f"{where}.magnetometer.date_year: WMM2025 holds from {MODEL_YEARS[0]:g} to "
                         f"{MODEL_YEARS[1]:g}, got {values['date_year']!r}")
    for key in ("noise_density", "turn_on_bias", "resolution", "range"):
        if min(values[key]) < 0:
            raise SceneError(f"{where}.magnetometer.{key}: values are >= 0")


_param = param_maker("magnetometer", "vector3")


COMPANION = Companion(
    name="magnetometer",
    description="the Earth's field (WMM2025) in the sensor's axes, with hard and soft iron, noise, resolution, range",
    fields={"mag": 3, "mag_new": 0},
    start=_Magnetometer, validate=validate,
    params=(_param("rate_hz", "Hz", "output data rate; held between updates", "scalar", 100.0, "`100 Hz`"),
            _param("date_year", "1", "decimal year the field model is evaluated at (WMM2025: 2025-2030)", "scalar",
                   2025.0, "`2026.5`"),
            _param("noise_density", "gauss/sqrt(Hz)", "white noise density per axis",
                   datasheet="`140 ugauss/sqrt(Hz)`, `0.014 uT/sqrt(Hz)`"),
            _param("hard_iron", "gauss", "constant offset per axis (hard iron, sensor axes)", "triple", (0.0, 0.0, 0.0),
                   "`[0.05, -0.02, 0.01]`, `[\"20 uT\", 0, 0]`"),
            _param("soft_iron", "1", "3x3 matrix applied to the true field (soft iron, scale, cross-axis)", "matrix3",
                   ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), "`[[1.02, 0.01, 0], [0.01, 0.98, 0], ...]`"),
            _param("turn_on_bias", "gauss", "offset drawn once per run (1 sigma per axis)", datasheet="`2 mgauss`"),
            _param("resolution", "gauss", "output step (0: none)", datasheet="`0.1 mgauss`, `1.5 mG`"),
            _param("range", "gauss", "full scale +-range; beyond it is clipped and counted (0: none)",
                   datasheet="`8 gauss`, `2.5 G`")))
