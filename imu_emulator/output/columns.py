"""The columns of `generate`'s outputs: one schema that every format's writer, the size estimates and the
readers (`plot`, `align`) read, so that a column is named, ordered and counted in one place.

A row is one IMU at one sample (sample k of every IMU before sample k + 1): the time stamp "t" (s on the
scene's time base plus the IMU's [[imu]] time_offset_s; Parquet stores it as integer "t_ns"), the IMU's name
"imu", then groups of float64 columns in a fixed order, each present when its option is on (`Layout`).
A group is per IMU (each IMU's own values) or shared by the IMUs of a sample (the truth of the body). The
companion sensors' groups (magnetometer, barometer, GNSS, the unit's INS estimate: imu_emulator.companions) are
per IMU and present when any IMU of the scene carries the sensor; an IMU without it has NaN there.

The Earth truth's columns belong to imu_emulator.motion.earth_truth (KEYS, COLUMNS: what `--truth` adds on
the Earth); they are read from there, and only when a scene is on the Earth (earth_truth imports the frames).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass(frozen=True)
class Column:
    name: str
    unit: str
    what: str           # the quantity and its frame


@dataclass(frozen=True)
class Group:
    """Columns written together: three per key (x, y, z) of `keys`, read from SampleBlock's attribute of that
    name or, for truth groups, from SampleBlock.truth; a per-IMU key is (n_imu, n, 3) (temperature (n_imu, n)),
    a shared one (n, 3)."""
    option: str         # the Layout field that turns it on
    per_imu: bool
    in_truth: bool
    keys: tuple[str, ...]
    columns: tuple[Column, ...]
    in_companion: bool = False     # read from SampleBlock.companion (per IMU {field: values}), NaN where absent
    widths: tuple[int, ...] | None = None      # columns per key when the keys' widths differ (else an equal split)
    #: the companion field each key reads where the file's key differs (INS position_llh -> ins_llh: NPZ's
    #: arrays are named by key, and the Earth truth has a velocity_ned of its own)
    sources: tuple[str, ...] | None = None

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(column.name for column in self.columns)

    def key_columns(self) -> list[tuple[str, tuple[Column, ...]]]:
        """Each key with the columns its array holds, in order."""
        widths = self.widths or (len(self.columns) // len(self.keys),) * len(self.keys)
        bounds = np.cumsum((0,) + tuple(widths)).tolist()
        return [(key, self.columns[bounds[i]:bounds[i + 1]]) for i, key in enumerate(self.keys)]

    def arrays(self, block) -> list[np.ndarray]:
        """The group's values in a block: per IMU (n_imu, n, k), shared (n, k)."""
        if self.in_companion:
            return [_companion_array(block, source) for source in self.sources or self.keys]
        found = [block.truth[key] if self.in_truth else getattr(block, key) for key in self.keys]
        return [a[:, :, None] if self.per_imu and a.ndim == 2 else a for a in found]


def _companion_array(block, key: str) -> np.ndarray:
    """(n_imu, n, k) of a companion field, NaN for the IMUs that do not carry its sensor."""
    n = len(block)
    per_imu = [None if block.companion is None else block.companion[m].get(key) for m in range(block.n_imu)]
    width = next((1 if a.ndim == 1 else a.shape[1] for a in per_imu if a is not None), 1)
    out = np.full((block.n_imu, n, width), np.nan)
    for m, a in enumerate(per_imu):
        if a is not None:
            out[m] = a.reshape(n, width)
    return out


def _xyz(prefix: str, unit: str, what: str, axes: str = "xyz") -> tuple[Column, ...]:
    return tuple(Column(f"{prefix}{axis}", unit, f"{what}, {axis}") for axis in axes)


TIME = Column("t", "s", "sample time on the scene's time base plus the IMU's time_offset_s")
IMU = Column("imu", "", "the IMU's name")

SAMPLES = Group("samples", True, False, ("accel", "gyro"),
                _xyz("a", "m/s^2", "specific force in the sensor frame")
                + _xyz("g", "rad/s", "angular rate in the sensor frame"))
#: integrated outputs over (t_k-1, t_k] (imu_emulator.codegen.increments), after the gyro columns
INCREMENTS = Group("increments", True, False, ("dtheta", "dvel"),
                   _xyz("dtheta_", "rad", "integrated angular rate over the sample interval, sensor frame")
                   + _xyz("dvel_", "m/s", "integrated specific force over the sample interval, sensor frame"))
TEMPERATURE = Group("temperature", True, False, ("temperature_c",),
                    (Column("temp_c", "degC", "the IMU's temperature"),))
TRUTH = Group("truth", False, True, ("position", "velocity", "euler", "omega_body"),
              _xyz("p", "m", "position of the reference point S in the navigation frame")
              + _xyz("v", "m/s", "velocity of S in the navigation frame")
              + (Column("roll", "rad", "body attitude w.r.t. the navigation frame, z-y-x"),
                 Column("pitch", "rad", "body attitude w.r.t. the navigation frame, z-y-x"),
                 Column("yaw", "rad", "body attitude w.r.t. the navigation frame, z-y-x"))
              + _xyz("wb", "rad/s", "body rate in the body frame"))
#: realized bias of each IMU (sensor errors on: an effect adds a bias)
BIAS = Group("bias_truth", True, True, ("accel_bias", "gyro_bias"),
             _xyz("ba", "m/s^2", "realized accelerometer bias, sensor frame")
             + _xyz("bg", "rad/s", "realized gyro bias, sensor frame"))


#: the companion sensors' outputs (imu_emulator.companions; the ROS 2 writer reads these names)
MAGNETOMETER = Group("magnetometer", True, False, ("mag", "mag_new"),
                     _xyz("mag_", "gauss", "magnetic field measured in the sensor frame")
                     + (Column("mag_new", "", "1 where a new magnetometer reading arrived at this sample"),),
                     in_companion=True, widths=(3, 1))
BAROMETER = Group("barometer", True, False, ("pressure_pa", "baro_temperature_c", "differential_pressure_pa",
                                             "baro_new"),
                  (Column("pressure_pa", "Pa", "static pressure measured"),
                   Column("baro_temperature_c", "degC", "the barometer's temperature"),
                   Column("differential_pressure_pa", "Pa", "pitot differential pressure measured (still air)"),
                   Column("baro_new", "", "1 where a new barometer reading arrived at this sample")),
                  in_companion=True)
#: the receiver's solution and the quality figures it reports with it (imu_emulator.companions.gnss)
GNSS = Group("gnss", True, False, ("gnss_llh", "gnss_velocity_ned", "gnss_fix", "gnss_new", "gnss_satellites",
                                   "gnss_hdop", "gnss_vdop", "gnss_horizontal_accuracy_m", "gnss_vertical_accuracy_m",
                                   "gnss_speed_accuracy_mps"),
             (Column("gnss_lat_deg", "deg", "GNSS antenna latitude, WGS-84, as last reported"),
              Column("gnss_lon_deg", "deg", "GNSS antenna longitude, WGS-84, as last reported"),
              Column("gnss_h_m", "m", "GNSS antenna height above the WGS-84 ellipsoid, as last reported"),
              Column("gnss_vn", "m/s", "GNSS velocity north"), Column("gnss_ve", "m/s", "GNSS velocity east"),
              Column("gnss_vd", "m/s", "GNSS velocity down"),
              Column("gnss_fix", "", "fix type: 0 none, 3 3D"),
              Column("gnss_new", "", "1 where a new solution arrived at this sample"),
              Column("gnss_satellites", "", "satellites used (0 without a fix)"),
              Column("gnss_hdop", "", "horizontal dilution of precision (99.99 without a fix)"),
              Column("gnss_vdop", "", "vertical dilution of precision (99.99 without a fix)"),
              Column("gnss_horizontal_accuracy_m", "m", "1-sigma horizontal position accuracy reported (0 without "
                     "a fix)"),
              Column("gnss_vertical_accuracy_m", "m", "1-sigma vertical position accuracy reported (0 without a fix)"),
              Column("gnss_speed_accuracy_mps", "m/s", "1-sigma speed accuracy reported (0 without a fix)")),
             in_companion=True, widths=(3, 3, 1, 1, 1, 1, 1, 1, 1, 1))
#: the unit's own navigation estimate (imu_emulator.companions.ins) as the wire formats send it: attitude of the
#: part's forward-right-down axes w.r.t. local NED whatever the scene's frame, position, velocity, stated sigmas
INS = Group("ins", True, False, ("ins_quat", "ins_euler", "ins_llh", "ins_velocity_ned", "ins_attitude_sigma_rad",
                                 "ins_position_sigma_m", "ins_velocity_sigma_mps", "ins_mode"),
            tuple(Column(f"ins_q{c}", "", f"estimated attitude quaternion, {c}: the part's forward-right-down axes "
                         "-> local NED, scalar first, w >= 0") for c in "wxyz")
            + tuple(Column(f"ins_{angle}", "rad", f"estimated {angle} of the part's forward-right-down axes w.r.t. "
                           "local NED, z-y-x") for angle in ("roll", "pitch", "yaw"))
            + (Column("ins_lat_deg", "deg", "estimated latitude of S, WGS-84"),
               Column("ins_lon_deg", "deg", "estimated longitude of S, WGS-84"),
               Column("ins_h_m", "m", "estimated height of S above the WGS-84 ellipsoid"))
            + _xyz("ins_v", "m/s", "estimated velocity of S", ("n", "e", "d"))
            + tuple(Column(f"ins_{angle}_sigma_rad", "rad", f"stated 1-sigma {angle} uncertainty")
                    for angle in ("roll", "pitch", "yaw"))
            + _xyz("ins_pos_", "m", "stated 1-sigma position uncertainty", ("n_sigma_m", "e_sigma_m", "d_sigma_m"))
            + _xyz("ins_vel_", "m/s", "stated 1-sigma velocity uncertainty", ("n_sigma_mps", "e_sigma_mps",
                                                                         "d_sigma_mps"))
            + (Column("ins_mode", "", "filter mode: 0 not tracking, 1 aligning, 2 tracking"),),
            in_companion=True, widths=(4, 3, 3, 3, 3, 3, 3, 1),
            sources=("ins_quat", "ins_euler", "position_llh", "velocity_ned", "attitude_sigma_rad", "position_sigma_m",
                     "velocity_sigma_mps", "ins_mode"))
COMPANION_GROUPS = (MAGNETOMETER, BAROMETER, GNSS, INS)


@lru_cache(maxsize=1)
def earth_group() -> Group:
    """The Earth truth (a scene on the Earth, --truth): imu_emulator.motion.earth_truth's keys and columns (its
    docstring gives their units and frames)."""
    from imu_emulator.motion.earth_truth import COLUMNS
    return Group("earth", False, True, tuple(COLUMNS),
                 tuple(Column(name, unit, f"Earth truth {key}") for key, names in COLUMNS.items()
                       for name, unit in zip(names, _EARTH_UNITS.get(key, ("",) * len(names)))))


#: the Earth truth's units, as imu_emulator.motion.earth_truth's docstring gives them
_EARTH_UNITS = {"geodetic": ("deg", "deg", "m"), "position_ecef": ("m",) * 3, "velocity_ned": ("m/s",) * 3,
                "velocity_ecef": ("m/s",) * 3, "euler_ned": ("rad",) * 3, "earth_rate_ned": ("rad/s",) * 3,
                "transport_rate_ned": ("rad/s",) * 3, "coriolis_ned": ("m/s^2",) * 3, "gravity_ned": ("m/s^2",) * 3}


#: the column names of each group (the writers' and readers' spelling of today's constants)
LEADING_COLUMNS = (TIME.name, IMU.name) + SAMPLES.names      # every row starts with these
INCREMENT_COLUMNS = INCREMENTS.names
TRUTH_COLUMNS = TRUTH.names
BIAS_COLUMNS = BIAS.names


@dataclass(frozen=True)
class Layout:
    """Which groups an output carries: generate's options (--truth, --increments) and the scene's (temperature
    effect, an effect adding a bias, on the Earth)."""
    truth: bool = False
    bias_truth: bool = False
    temperature: bool = False
    increments: bool = False
    earth: bool = False
    companions: tuple[str, ...] = ()     # the companion groups carried (COMPANION_GROUPS' options)

    def __post_init__(self):    # the realized biases and the Earth truth are parts of the truth
        object.__setattr__(self, "bias_truth", self.truth and self.bias_truth)
        object.__setattr__(self, "earth", self.truth and self.earth)

    def groups(self) -> list[Group]:
        """The float64 groups after t and imu, in the order every format writes them."""
        groups = [SAMPLES, INCREMENTS, TEMPERATURE, TRUTH, BIAS]
        if self.earth:
            groups.append(earth_group())
        return ([g for g in groups if g.option == "samples" or getattr(self, g.option)]
                + [g for g in COMPANION_GROUPS if g.option in self.companions])

    def names(self) -> tuple[str, ...]:
        """The float64 columns after t and imu."""
        return tuple(name for group in self.groups() for name in group.names)

    def counts(self) -> tuple[int, int]:
        """Numbers of a row besides its time: (per IMU, shared by the IMUs of a sample)."""
        groups = self.groups()
        return (sum(len(g.columns) for g in groups if g.per_imu), sum(len(g.columns) for g in groups if not g.per_imu))


def scene_layout(scene, truth: bool, increments: bool = False) -> Layout:
    """The layout of `generate`'s output of a scene (known before compiling: the size estimates use it)."""
    from imu_emulator.codegen.plan import EffectPlan
    from imu_emulator.scene.earth import model_on
    return Layout(truth=truth, bias_truth=truth and EffectPlan(scene).bias_truth,
                  temperature="temperature" in scene.effects, increments=increments,
                  earth=truth and model_on(scene), companions=scene_companions(scene))


def scene_companions(scene) -> tuple[str, ...]:
    """The companion groups a scene's output carries: those of the sensors any of its IMUs names."""
    named = {name for imu in scene.imus for name in imu.companions}
    return tuple(group.option for group in COMPANION_GROUPS if group.option in named)


def all_names() -> set[str]:
    """Every column any output may carry (a reader refuses others)."""
    return set(LEADING_COLUMNS) | set(Layout(True, True, True, True, True,
                                             tuple(g.option for g in COMPANION_GROUPS)).names())


def block_columns(block, imu_names, layout: Layout, time_ns: bool = False) -> dict:
    """The columns of one block, one row per IMU per sample (sample k of every IMU before sample k+1): "t" in
    seconds (or "t_ns", integer nanoseconds), "imu" (a pyarrow dictionary of the names), then float64 columns."""
    import pyarrow as pa

    n_imu, n = len(imu_names), len(block)

    def interleaved(per_imu):      # (n_imu, n, k) -> (n * n_imu, k), IMU index fastest
        return np.ascontiguousarray(per_imu.transpose(1, 0, 2)).reshape(n * n_imu, -1)

    stamps = (np.stack([block.time_ns(block.imu_offset_ns(m)) for m in range(n_imu)]) if time_ns
              else block.imu_t_s())   # (n_imu, n): each IMU's own stamps ([[imu]] time_offset_s)
    columns = {"t_ns" if time_ns else TIME.name: stamps.T.ravel(),
               IMU.name: pa.DictionaryArray.from_arrays(np.tile(np.arange(n_imu, dtype=np.int32), n),
                                                        pa.array(list(imu_names)))}
    numeric = [interleaved(a) if group.per_imu else np.repeat(a, n_imu, axis=0)
               for group in layout.groups() for a in group.arrays(block)]
    values = np.hstack(numeric)
    for i, name in enumerate(layout.names()):
        columns[name] = values[:, i]
    return columns


def named_columns(block, layout: Layout) -> dict[str, tuple[bool, np.ndarray]]:
    """Each float64 column of a block by name: (per_imu, its values), (n_imu, n) per IMU or (n,) shared; views
    where the block's arrays allow (a writer that wants some columns by name, as MCAP's companion topics)."""
    found = {}
    for group in layout.groups():
        names = iter(group.names)
        for values in group.arrays(block):
            if not group.per_imu and values.ndim == 1:       # a shared scalar: (n,)
                values = values[:, None]
            for i in range(values.shape[-1]):
                found[next(names)] = (group.per_imu, values[..., i])
    return found


def described(layout: Layout) -> list[Column]:
    """Every column of an output in order, with its unit and what it is (the files state them)."""
    return [TIME, IMU] + [column for group in layout.groups() for column in group.columns]
