"""What a scene's effects contribute to its kernel: their lines per stage, the state slots carried across blocks,
the random streams and the run-time parameters. The generator (imu_emulator.codegen.generate) writes the source
from it; the Simulation builds it too, to lay out the state array, the stream keys and the parameter array the
same way.

Parameters: every number of a scene that shapes no line (a noise density, a lever arm, a mounting, t0 and the
sample interval) is a slot of the float64 array `prm` the kernel takes as an argument, not a literal in its source:
the effects write `ctx.number(x)` where they wrote repr(x). The lines then hold the scene's structure only (which
effects, which axes are nonzero, how many IMUs), so two scenes differing only in such numbers share one kernel
(imu_emulator.runtime.cache keys on `structure()`). A zero still removes its line (the key keeps which values are
zero): a switched-off term costs nothing, as before."""
from __future__ import annotations

import numpy as np

from imu_emulator.codegen.explain import effect_comment
from imu_emulator.effects import EFFECTS, FRAME_ORDERS, EmitContext, Stage
from imu_emulator.effects.mounting import rotation as mounting_rotation
from imu_emulator.geo.rotations import matrix_to_quat
from imu_emulator.motion.code import lifted_numbers
from imu_emulator.scene.earth import model_on
from imu_emulator.scene.model import Scene


class EffectPlan:
    """What the scene's effects contribute, built without sympy: the Simulation builds it too, to lay out the
    state array and the stream keys the same way the source does."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.active = [e for e in EFFECTS.values() if e.name in scene.effects]
        self.slots: list[tuple[str, int, object]] = []    # (variable, imu, initial(draw))
        self.streams: list[tuple[int, str]] = []          # (imu, name)
        self.counters: list[tuple[int, int, str]] = []    # (state slot, imu, label)
        self.constants: dict[str, tuple[float, ...]] = {}  # arrays of parameters, read as prm[base + i]
        self.constant_bases: dict[str, int] = {}
        self.params: list[float] = []                      # the run-time parameters, prm[i]
        self.param_effects: list[str | None] = []          # which effect asked for each ("(...)": the kernel's own)
        self.axes_turns: dict[int, list[tuple[list[str], tuple]]] = {}  # imu -> [(lines, quaternion)], body stage
        # which effect asked for each slot, stream and constant, and which emitted lines (the source's glossary)
        self.slot_effects: list[str] = []
        self.stream_effects: list[str] = []
        self.constant_effects: dict[str, str] = {}
        self.emitted: set[str] = set()
        self._effect = None     # the effect whose emit is running
        # the time of scene sample k, t = t0 + k dt: the kernel's own parameters, first in prm
        self.t0 = self.add_param(scene.t0_s)
        self.dt = self.add_param(1.0 / scene.rate_hz)
        # the tangent frame's origin in ECEF (r0, C) where the Earth model is on: parameters, less its exact 0s and 1s
        self.origin = None
        if model_on(scene):
            from imu_emulator.motion.earth import origin_terms
            self._effect = "(the origin: ECEF position r0 and axes C of the navigation frame)"
            self.origin = origin_terms(scene, self.add_param)
            self._effect = None
        # the numbers of the motion's expressions (motion.code.lifted_numbers): parameters too, less those that stay
        # in the source (phases, exponents, zeros); the structures stand for the expressions in the cache key
        self._effect = "(the numbers of the motion's expressions)"
        lifted = lifted_numbers(scene)
        self.expression_structures = {key: structure for key, (structure, _) in lifted.items()}
        self.expression_slots = {key: [self.add_param(v) for v in values] for key, (_, values) in lifted.items()}
        self._effect = None
        navigation = [e for e in self.active if e.stage == Stage.NAVIGATION]
        self.clock = self._emit([e for e in navigation if e.sample_clock], None, None)
        self.navigation = self._emit([e for e in navigation if not e.sample_clock], None, None)
        self.nav_rate = any(e.nav_rate for e in self.active if e.stage == Stage.NAVIGATION)
        self.per_imu = []
        for m, imu in enumerate(scene.imus):
            sensor = [e for e in self.active if e.stage == Stage.SENSOR]
            self.per_imu.append({
                "body": self._lines(Stage.BODY, imu, m),
                "frame": self._emit([e for e in sensor if e.order < FRAME_ORDERS], imu, m),
                "sensor": self._emit([e for e in sensor if e.order >= FRAME_ORDERS], imu, m),
                "output": self._lines(Stage.OUTPUT, imu, m),
            })
        # each IMU's mounting as a quaternion, for the attitude output (its axes turned after the body's)
        self.mounting_quat: dict[int, tuple[str, ...]] = {}
        self._effect = "(mounting quaternions, for the attitude output)"
        for m, imu in enumerate(scene.imus):
            M = mounting_rotation(EmitContext(self, EFFECTS["mounting"], scene, imu, m))
            if M is not None:
                self.mounting_quat[m] = tuple(self.add_param(v) for v in matrix_to_quat(M))
        self._effect = None
        self.bias_truth = any("bgx +=" in line or "bax +=" in line
                              for stages in self.per_imu for line in stages["sensor"])

    def _lines(self, stage: Stage, imu, m) -> list[str]:
        return self._emit([e for e in self.active if e.stage == stage], imu, m)

    def _emit(self, effects, imu, m) -> list[str]:
        lines = []
        for effect in effects:
            self._effect = effect.name
            emitted = effect.emit(EmitContext(self, effect, self.scene, imu, m))
            if emitted:
                self.emitted.add(effect.name)
                lines += [effect_comment(effect)] + emitted
        self._effect = None
        return lines

    def add_state(self, var: str, m: int, initial) -> str:
        self.slots.append((var, m, initial))
        self.slot_effects.append(self._effect)
        return var

    def add_state_block(self, m: int, initials) -> int:
        """Slots the kernel reads as state[base + i] (no local variable): returns base."""
        base = len(self.slots)
        self.slots += [(None, m, initial) for initial in initials]
        self.slot_effects += [self._effect] * (len(self.slots) - base)
        return base

    def add_param(self, value) -> str:
        """A run-time parameter: its value goes to prm[i], the source reads the local prm_i (loaded once per
        call, before the sample loop)."""
        self.params.append(float(value))
        self.param_effects.append(self._effect)
        return f"prm_{len(self.params) - 1}"

    def add_constant(self, name: str, values) -> int:
        """An array of parameters, read in the source as prm[base + i]: returns base."""
        self.constants[name] = tuple(float(v) for v in values)
        self.constant_effects[name] = self._effect
        base = self.constant_bases[name] = len(self.params)
        self.params += self.constants[name]
        self.param_effects += [self._effect] * len(self.constants[name])
        return base

    def param_values(self) -> np.ndarray:
        """The kernel's `prm` argument."""
        return np.array(self.params or [0.0], dtype=np.float64)

    def structure(self) -> dict:
        """Everything of the plan that shapes the source, and no number that arrives in `prm` (the cache key's
        part for the effects): the lines, which hold only slot names, the state slots, streams, counters, the
        arrays' lengths and the number of parameters."""
        return {"clock": self.clock, "navigation": self.navigation, "nav_rate": self.nav_rate, "per_imu": self.per_imu,
                "slots": [(var, m) for var, m, _ in self.slots], "streams": self.streams, "counters": self.counters,
                "constants": {name: [self.constant_bases[name], len(v)] for name, v in self.constants.items()},
                "axes_turns": sorted(self.axes_turns.items()), "mounting_quat": sorted(self.mounting_quat.items()),
                "origin": self.origin, "params": len(self.params), "bias_truth": self.bias_truth,
                "expressions": self.expression_structures}

    def add_axes_turn(self, m: int, lines: list[str], quaternion: tuple) -> None:
        self.axes_turns.setdefault(m, []).append((lines, quaternion))

    def add_counter(self, var: str, m: int, label: str) -> str:
        self.counters.append((len(self.slots), m, label))
        return self.add_state(var, m, lambda draw: 0.0)

    def add_stream(self, m: int, name: str) -> int:
        if (m, name) not in self.streams:
            self.streams.append((m, name))
            self.stream_effects.append(self._effect)
        return self.streams.index((m, name))

    def keys(self, seed: int) -> np.ndarray:
        from imu_emulator.numerics.counter_rng import stream_key
        # the navigation stage's streams belong to no IMU: index -1
        return np.array([stream_key(seed, -1 if m is None else m, name) for m, name in self.streams] or [0],
                        dtype=np.uint64)

    def initial_state(self, seed: int) -> np.ndarray:
        """Every state slot's value at the run's start (random draws keyed on the seed, never on the block)."""
        from imu_emulator.numerics.counter_rng import normals, stream_key

        drawn: dict = {}   # the flicker sums' starts redraw their poles' values: each draw costs a hash and a call

        def draw(m, stream, counter):
            if (m, stream) not in drawn or counter >= len(drawn[m, stream]):
                key = np.uint64(stream_key(seed, m, f"init.{stream}"))
                drawn[m, stream] = normals(key, 0, max(2, counter + 1))   # slots draw counters 0 and 1
            return float(drawn[m, stream][counter])

        def draw_for(m):
            return lambda stream, counter: draw(m, stream, counter)
        return np.array([initial(draw_for(m)) for _, m, initial in self.slots] or [0.0])

