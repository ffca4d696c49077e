"""The validated scene: frozen dataclasses (Scene, its trajectory and attitude as Expressions or SampledData, one
ImuSpec per IMU) and the bounds its numbers are checked against.

A Scene is built once by imu_emulator.scene.load (from_dict, load_scene), which checks every value against these
bounds; everything downstream trusts it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

FRAMES = ("ENU", "NED", "ECEF", "ECI")
ATTITUDE_MODES = ("euler", "tangent", "file")
DEFAULT_DERIVATIVE = "spline5c"   # see docs/performance.md, "Accuracy"
SEED_LIMIT = 2 ** 64      # [scene] seed: an integer 0 <= seed < 2**64

# Ranges of the scene's numbers; errors state the bound. Wide enough for any vehicle, narrow enough that no
# product the kernel forms (w x (w x r), R * g) overflows and no inf or nan reaches generated code.
RATE_RANGE_HZ = (1e-3, 1e7)
MAX_DURATION_S = 1e9           # 32 years
MAX_GRAVITY_MPS2 = 1e3
MAX_POSITION_M = 1e8           # positions, radii, centres, heights (ECEF is 6.4e6 m)
MAX_LEVER_ARM_M = 1e3
MAX_ANGLE_DEG = 1e4            # mounting angles, initial heading
MAX_TRACK_ANGLE_RAD = 1e9      # track angles may be unwrapped over long runs
MAX_FREQUENCY_HZ = 1e6         # circle shape
SPEED_RANGE_MPS = (1e-6, 1e5)   # shapes' speed_mps: a radius or a duration divides by it, so no subnormal speeds
MAX_TIME_OFFSET_S = 1e6        # [[imu]] time_offset_s: a clock offset, not a second epoch
MAX_IMUS = 256                 # beyond codegen.generate.INLINE_IMUS, an IMU is a kernel function: ~0.3 s CPU each

#: plain-number limits of IMU parameters (the records' units), so no huge value reaches the kernel's literals
BOUNDS = {"imu.lever_arm_m": (MAX_LEVER_ARM_M, " m"), "imu.mounting_rpy_deg": (MAX_ANGLE_DEG, " deg")}


@dataclass(frozen=True)
class Expressions:
    """Three expressions as validated text (x, y, z or roll, pitch, yaw)."""
    texts: tuple[str, str, str]
    keys: tuple[str, str, str] = ("x", "y", "z")   # ("lat_deg", "lon_deg", "height_m"): a geodetic trajectory


@dataclass(frozen=True)
class SampledData:
    """Sampled input: time stamps and columns, with the derivative method chosen for them."""
    t: np.ndarray = field(repr=False)
    values: np.ndarray = field(repr=False)   # (n, 3)
    derivative: str
    source: str                               # file path or "<array>", for messages
    kind: str = "euler"                       # attitude only: "euler" (roll, pitch, yaw) or "quaternion" (qw..qz)
    noise: float = 0.0                        # stated noise (m or rad, 1 sigma), for derivative = "smooth"
    geodetic: bool = False                    # trajectory only: ECEF metres converted from lat/lon/height columns


@dataclass(frozen=True)
class ImuSpec:
    """One IMU: its name (never in generated source) and the value of every parameter every effect declares
    (imu_emulator.effects), keyed by the parameter's path ("imu.lever_arm_m", "imu.gyro.noise_density"), in
    the parameter's unit; parameters not given hold their defaults, so the kernel key sees all of them."""
    name: str
    values: Mapping[str, Any] = field(default_factory=dict)
    # added to this IMU's time stamps in every output (its own clock's offset; not a kernel parameter: the
    # samples are taken at the scene's instants, only their stamps move)
    time_offset_s: float = 0.0
    #: the companion sensors it carries ([imu.magnetometer], ...: imu_emulator.companions), name -> {key: value}
    companions: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    @property
    def lever_arm_m(self) -> tuple[float, float, float]:
        return self.values["imu.lever_arm_m"]

    @property
    def mounting_rpy_deg(self) -> tuple[float, float, float]:
        return self.values["imu.mounting_rpy_deg"]


@dataclass(frozen=True)
class Scene:
    rate_hz: float
    duration_s: float
    frame: str
    gravity_mps2: float
    t0_s: float
    params: Mapping[str, float]
    trajectory: Expressions | SampledData       # position of S, navigation frame, metres
    attitude_mode: str                           # "euler", "tangent" or "file"
    attitude: Expressions | SampledData | None   # None in tangent mode
    initial_heading_rad: float
    imus: tuple[ImuSpec, ...]
    effects: frozenset[str]
    streams: tuple[dict, ...] = ()
    path: str | None = None
    warnings: tuple[str, ...] = ()
    seed: int = 0                                # root of every random stream (imu_emulator.numerics.counter_rng)
    origin: tuple[float, float, float] | None = None   # lat deg, lon deg, height m where ENU/NED is tangent
    gravity_model: str = "constant"              # "constant" (gravity_mps2) or "wgs84" (normal gravity)
    attitude_reference: str = "local_level"      # what roll, pitch, yaw are relative to (scene.earth.REFERENCES)

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def n_samples(self) -> int:
        """Samples at t0, t0 + dt, ... up to but excluding t0 + duration (so a looped periodic scene is seamless)."""
        return max(1, int(round(self.duration_s * self.rate_hz)))

    @property
    def imu_names(self) -> tuple[str, ...]:
        return tuple(imu.name for imu in self.imus)

    @property
    def earth_model(self) -> bool:
        """Whether the navigation stage follows the Earth (imu_emulator.scene.earth.model_on): the effects ask
        it of the scene they are given, as they import nothing of the scene."""
        from imu_emulator.scene.earth import model_on
        return model_on(self)
