"""The record every effect module declares, and what the code generator hands its emit function.

An effect is one module in this package holding `EFFECT = Effect(...)`. Everything else reads the records:
scene validation (which [effects] names, which [[imu]] / [imu.gyro] / [imu.accel] keys, their units), the
"parameter given but effect off" warnings, the kernel's stages, the cache key (the modules' bytes) and the
documentation table (`imu-emulator kernel --effects`, docs/sensor-errors.md). Records import nothing of the scene.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, Callable


class Stage(IntEnum):
    """Where in the per-sample code an effect acts; stages run in this order, effects within a stage by
    their `order`. Every stage carries specific force and angular rate (variables in STAGE_CONTRACT)."""
    NAVIGATION = 1   # navigation frame, once per sample for the whole body
    BODY = 2         # body frame at the IMU, per IMU
    SENSOR = 3       # sensor frame, per IMU (mounting, then the sensor's errors)
    OUTPUT = 4       # sensor output, per IMU (what leaves the part: range, resolution)


STAGE_TITLES = {Stage.NAVIGATION: "navigation frame", Stage.BODY: "body frame at the IMU",
                Stage.SENSOR: "sensor frame", Stage.OUTPUT: "sensor output"}

#: The variables each stage may read and update (the generated kernel's contract, see codegen.template.KERNEL_TEMPLATE).
STAGE_CONTRACT = {
    Stage.NAVIGATION: (
        "reads  t (s), k (scene sample), s (run sample), px py pz, vx vy vz, ax ay az (navigation frame), "
        "r00..r22 (body -> navigation), wx wy wz, alx aly alz (body rate and its derivative, body axes); "
        "updates fnx fny fnz (specific force, navigation axes; starts as ax ay az) and, for an effect declared "
        "with nav_rate=True, wnx wny wnz (rate of the navigation frame w.r.t. inertial space, navigation axes; "
        "starts at 0, added to the gyros in body axes) and dwnx dwny dwnz (the rate of change of those "
        "components, for the inertial angular acceleration)"),
    Stage.BODY: (
        "reads  everything above, fbx fby fbz (specific force at the reference point, body axes); "
        "updates fax fay faz (specific force at this IMU, body axes; starts as fbx..) and gwx gwy gwz "
        "(inertial angular rate, body axes; starts as the body rate plus the navigation stage's rate); its "
        "derivative, the inertial angular acceleration, is the variables EmitContext.alpha names"),
    Stage.SENSOR: (
        "updates ox oy oz (accelerometer triad) and gx gy gz (gyro triad) in sensor axes; they start as the "
        "body-stage values; effects of order < FRAME_ORDERS (mounting) change axes, after them the kernel keeps "
        "the true sensor-frame values in tfx tfy tfz, twx twy twz for the error effects to read; bias terms are "
        "added through EmitContext.add_bias so --truth can report the realized bias"),
    Stage.OUTPUT: (
        "updates ox oy oz, gx gy gz as the part outputs them (saturation, rounding); counters go through "
        "EmitContext.count"),
}
#: Sensor-stage effects with an order below this change axes (mounting); the error effects come after.
FRAME_ORDERS = 10

#: The sensor triads: scene table, output variables in the sensor stage, bias accumulator prefix.
TRIADS = {"gyro": ("imu.gyro", "g", "bg"), "accel": ("imu.accel", "o", "ba")}
AXES = "xyz"


@dataclass(frozen=True)
class Param:
    """One parameter: `key` in `table` ("imu", "imu.gyro", "imu.accel"); plain numbers are in `unit`, strings
    carry their own units (imu_emulator.scene.units). `aliases` are other keys of the same dimension that datasheets
    use for the same figure (e.g. arw for a gyro's noise density); at most one of them may be given."""
    key: str
    table: str
    unit: str
    description: str
    shape: str = "vector3"      # "scalar", "vector3" (one value broadcast), "triple" (exactly 3), "matrix3"
    default: Any = 0.0
    aliases: tuple[str, ...] = ()
    datasheet: str = ""          # how datasheets print it, for the documentation table
    example: Any = None          # a valid nonzero value (docs, and the tests that vary every parameter)

    @property
    def path(self) -> str:
        return f"{self.table}.{self.key}"


@dataclass(frozen=True)
class Effect:
    name: str                    # the [effects] key (an identifier)
    description: str             # one line
    stage: Stage
    order: int                   # position within the stage; lower runs first
    emit: Callable[["EmitContext"], list[str]] = field(repr=False)
    params: tuple[Param, ...] = ()
    state: tuple[str, ...] = ()  # what the per-IMU state slots hold (carried across blocks)
    random: bool = False         # draws random numbers (needs [scene] seed for a chosen realization)
    #: its state is a cache of values that are a pure function of (seed, run sample) (vibration's filtered noise,
    #: filled a chunk at a time): the quadrature's reruns at the nodes read the same values
    cached_state: bool = False
    nav_rate: bool = False       # navigation-stage effect that adds a rate of the navigation frame
    #: navigation-stage effect whose lines define `clk`, the actual sampling instant's offset from sample k in
    #: samples (t = t0 + (k + clk) dt); they run before the motion, which is evaluated at that instant
    sample_clock: bool = False
    #: checks that need several parameters (validate(values, where) raises SceneError naming the key); run by
    #: scene validation for each IMU when the effect is on
    validate: Callable[[dict, str], None] | None = field(default=None, repr=False)
    #: warnings that need the sample rate (warn(values, where, rate_hz) -> lines); run by scene validation for
    #: each IMU when the effect is on
    warn: Callable[[dict, str, float], list[str]] | None = field(default=None, repr=False)


def triad_params(key: str, gyro_unit: str, accel_unit: str, description: str, shape: str = "vector3",
                 gyro_aliases=(), accel_aliases=(), gyro_datasheet="", accel_datasheet="") -> tuple[Param, Param]:
    """The same parameter for both triads, [imu.gyro] and [imu.accel]."""
    return (Param(key, "imu.gyro", gyro_unit, f"gyro {description}", shape, aliases=tuple(gyro_aliases),
                  datasheet=gyro_datasheet),
            Param(key, "imu.accel", accel_unit, f"accelerometer {description}", shape,
                  aliases=tuple(accel_aliases), datasheet=accel_datasheet))


class EmitContext:
    """What an effect's emit function sees: the scene, the IMU (None in the navigation stage), its index, its
    parameter values in SI, and helpers that allocate state slots, random streams and counters so that the
    kernel, the Simulation and --truth agree on their layout."""

    def __init__(self, plan, effect: Effect, scene, imu, m: int | None):
        self.plan = plan
        self.effect = effect
        self.scene = scene
        self.imu = imu
        self.m = m

    @property
    def dt(self) -> float:
        return 1.0 / self.scene.rate_hz

    @property
    def alpha(self) -> tuple[str, str, str]:
        """The inertial angular acceleration d/dt gw.. in body axes, for the body stage: the body's alx.., or
        gal.. when the navigation stage adds its frame's rate (imu_emulator.motion.earth.inertial_rate_lines)."""
        return ("galx", "galy", "galz") if self.plan.nav_rate else ("alx", "aly", "alz")

    def value(self, path: str):
        """A parameter of this effect by its path ("imu.lever_arm_m", "imu.gyro.noise_density")."""
        if not any(p.path == path for p in self.effect.params):
            raise KeyError(f"{self.effect.name} did not declare {path}")
        return self.imu.values[path]

    def var(self, name: str) -> str:
        """A local variable name private to this effect and IMU."""
        return f"{self.effect.name}_{self.m}_{name}"

    def state(self, name: str, initial: Callable[[Callable[[str, int], float]], float]) -> str:
        """A state slot carried across blocks: returns its local variable; `initial(draw)` gives its value at
        the run's start, where draw(stream, counter) is a standard normal of this IMU's named stream."""
        if name.split("[")[0] not in self.effect.state:
            raise KeyError(f"{self.effect.name} did not declare state {name!r}")
        prefix = self.effect.name
        var = self.var("".join(c if c.isalnum() else "_" for c in name))
        return self.plan.add_state(var, self.m, lambda draw: initial(lambda s, c: draw(f"{prefix}.{s}", c)))

    def state_block(self, name: str, initials) -> int:
        """Slots carried in the state array that the kernel reads as state[base + i] inside a loop (no local
        variable each): returns base. initials[i](draw) gives slot i's value at the run's start."""
        if name not in self.effect.state:
            raise KeyError(f"{self.effect.name} did not declare state {name!r}")
        prefix = f"{self.effect.name}.{name}"
        return self.plan.add_state_block(self.m, [
            lambda draw, initial=initial: initial(lambda s, c: draw(f"{prefix}.{s}", c)) for initial in initials])

    def frd_sign(self, axis: int) -> float:
        """The sign that takes a draw on axis `axis` of the part's own forward-right-down axes into this scene's
        body and sensor axes: -1.0 for y and z in an ENU scene (forward-left-up axes, a half turn about x), else 1.0
        (NED, ECEF and ECI scenes' are FRD). Random terms are drawn in FRD and turned by it, so one motion written
        as an ENU and as a NED scene carries the same noise to the wire (issue 24), as the magnetometer's does.
        Per-axis magnitudes (noise densities, standard deviations) keep their axis: x, y, z are the same axes of
        the part in both habits, only their direction differs."""
        return -1.0 if axis and self.scene.frame == "ENU" else 1.0

    def number(self, value: float) -> str:
        """Source for a number of the scene (a parameter, or one computed from parameters and the rate): a
        run-time parameter of the kernel, never a literal, so that scenes differing only in it share a kernel.
        Test the value (`if value:`) before asking when a zero should remove the line."""
        return self.plan.add_param(value)

    def constant(self, name: str, values) -> str:
        """A float array of this effect and IMU, passed at run time in the parameters: returns the index of its
        first element, read in the source as prm[base + i] (its length is structure, its values are not)."""
        return str(self.plan.add_constant(f"{self.effect.name.upper()}_{self.m}_{name}", values))

    def normal(self, stream: str, counter: str = "s") -> str:
        """Source for the standard normal number `counter` of this IMU's stream `stream` (default: this run
        sample's)."""
        if not self.effect.random:
            raise KeyError(f"{self.effect.name} is not declared random")
        index = self.plan.add_stream(self.m, f"{self.effect.name}.{stream}")
        return f"normal(keys[{index}], {counter})"

    def stream_key(self, stream: str) -> str:
        """Source for the key of this IMU's stream `stream` (for a helper that draws normal(key, counter) itself)."""
        if not self.effect.random:
            raise KeyError(f"{self.effect.name} is not declared random")
        return f"keys[{self.plan.add_stream(self.m, f'{self.effect.name}.{stream}')}]"

    def count(self, label: str) -> str:
        """A counter of this IMU carried across blocks (a state slot from 0, exact up to 2**53): returns its
        local variable; Simulation.counts() reports it as "<effect>.<label>" of this IMU."""
        var = self.var("count_" + "".join(c if c.isalnum() else "_" for c in label))
        self.plan.add_counter(var, self.m, f"{self.effect.name}.{label}")
        return var

    def turn_axes(self, lines: list[str], quaternion: tuple[str, str, str, str]) -> None:
        """This IMU's axes are turned against the body's by the unit quaternion (w, x, y, z variables) that
        `lines` compute from this effect's body-stage variables: the attitude output composes it (body, then
        this, then mounting). The lines run only where the attitude is output."""
        self.plan.add_axes_turn(self.m, lines, quaternion)

    def add_bias(self, triad: str, axis: int, expr: str) -> list[str]:
        """Add a bias term to an output (and to the realized bias that --truth reports)."""
        _, out, acc = TRIADS[triad]
        return [f"{out}{AXES[axis]} += {expr}", f"{acc}{AXES[axis]} += {expr}"]
