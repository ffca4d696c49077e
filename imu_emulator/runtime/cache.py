"""The kernel cache on disk: where it lives, the key of an entry, and an entry's seal.

An entry is cache_dir()/<key>/: the generated source kernel.py (its first line an HMAC of the rest under the
cache's secret, imu_emulator.files.trust), its machine code kernel.o (imu_emulator.native.objects: a warm run loads
it without importing numba; sealed the same way) and numba's __pycache__ beside it. Nothing of an entry is loaded
unless the cache and the entry are the running user's alone and the seal matches. The key hashes the scene's
structure: the validated scene (imu_emulator.scene.digest) less the numbers that reach the kernel at run time
(PARAMETRIC; TIMING unless the motion is periodic), with the effects' plan (imu_emulator.codegen.plan: its lines
hold parameter slots, not values, and which values are zero), the outputs and the bytes of every module of the
generator;
imu_emulator.runtime.kernels publishes an entry (directory rename) only after it compiled, and removes and
regenerates an entry that fails its seal or its compile.
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import re
import shutil
import sys
from pathlib import Path

from imu_emulator.codegen.generate import CODEGEN_VERSION
from imu_emulator.codegen.plan import EffectPlan
from imu_emulator.codegen.signature import RUNTIME_IMPORTS
from imu_emulator.effects import EFFECTS
from imu_emulator.files import trust
from imu_emulator.scene.digest import KEY_EXCLUDES, canonical  # noqa: F401 (KEY_EXCLUDES: what the key leaves out)
from imu_emulator.scene.model import Expressions, Scene


def cache_dir() -> Path:
    """Where the entries are (for showing; kernels_dir() checks and creates it)."""
    return trust.cache_root() / "kernels"


def kernels_dir() -> Path:
    """The entries' directory, created private if missing; UntrustedCache unless the cache is the user's alone."""
    return trust.trusted_dir("kernels")


def generator_modules() -> list[Path]:
    """Every module the generated source depends on: found by following the imports (static, within the
    package) from every module of the generator (imu_emulator.codegen), from how an entry is compiled, exported
    and loaded (imu_emulator.runtime.kernels, which imports this module), every effect module, and the modules
    the generated source imports."""
    package_root = Path(__file__).resolve().parents[2]     # the folder holding imu_emulator/
    package = package_root / "imu_emulator"
    start = ["imu_emulator.codegen", *(f"imu_emulator.codegen.{p.stem}" for p in (package / "codegen").glob("*.py"))]
    start += ["imu_emulator.runtime.kernels", *RUNTIME_IMPORTS, *(f"imu_emulator.effects.{n}" for n in EFFECTS)]
    start += [f"imu_emulator.effects.{p.stem}" for p in (package / "effects").glob("_*.py")]
    start += ["imu_emulator.native.objects", "imu_emulator.native.lazy"]   # how its machine code is written and run
    seen: dict[str, Path] = {}
    todo = list(start)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        path = package_root / Path(*name.split("."))
        path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
        if not path.exists():
            continue
        seen[name] = path
        text = path.read_text()
        for module, names in _FROM_IMPORT.findall(text):
            todo.append(module)
            todo += [f"{module}.{n.split()[0]}" for n in _NAME.findall(names)]
        todo += _IMPORT.findall(text)
    return sorted(set(seen.values()))     # a package is found as itself and as its __init__


# Imports of the package, found by pattern rather than by parsing (parsing the 37 modules cost 90 ms of every
# start-up). A pattern matching an import inside a string only adds a module to the key: safe.
_FROM_IMPORT = re.compile(r"^[ \t]*from[ \t]+(imu_emulator[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n]*)", re.M)
_NAME = re.compile(r"\b(\w+(?:[ \t]+as[ \t]+\w+)?)")
_IMPORT = re.compile(r"^[ \t]*import[ \t]+(imu_emulator[\w.]*)", re.M)


@functools.lru_cache(maxsize=1)
def _code_fingerprint() -> str:
    """Read once per process: keying a scene costs microseconds (Monte Carlo builds many Simulations)."""
    h = hashlib.sha256(CODEGEN_VERSION.encode())
    for path in generator_modules():
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()

#: Scene fields no line of the kernel holds: the duration (no line reads it), the IMUs (their names reach no
#: line; their values reach the lines only as parameter slots, so EffectPlan.structure() stands for them), the
#: origin (parameters too; which of its ECEF terms are exactly 0 or 1 is in EffectPlan.structure()) and the
#: expressions' [params] (their values reach the lines as parameter slots or inside the expressions' structures).
PARAMETRIC = ("duration_s", "imus", "origin", "params")
#: Scene parts whose expressions' texts the key leaves out: EffectPlan.structure() holds their structures (the texts
#: with the numbers that arrive in prm as `c`: imu_emulator.numerics.expressions.lift) and, there, the [params]
#: values that stay in the source (phases, exponents, zeros), so the params table is parametric too.
EXPRESSION_PARTS = ("trajectory", "attitude")
#: Run-time parameters too (prm's t0, dt), but the phase constants of periodic motion (imu_emulator.motion.phases:
#: sin, cos, tan of a phase linear in t, reduced exactly) are literals computed from them: keyed while the motion
#: may have such (periodic_motion).
TIMING = ("t0_s", "rate_hz")
_TRIG = re.compile(r"sin|cos|tan")


def periodic_motion(scene: Scene) -> bool:
    """Whether the motion's source may hold phase constants: attitude angles as expressions (their cos and sin),
    a trajectory expression with a trigonometric function or in geodetic keys (cos and sin of latitude and
    longitude), an ECI frame or reference (the Earth's rotation angle). Decided from the texts, without sympy:
    a false yes only keys t0 and rate (a recompile), a false no would run stale phases, so it errs to yes."""
    if scene.frame == "ECI" or scene.attitude_reference == "ECI" or isinstance(scene.attitude, Expressions):
        return True
    trajectory = scene.trajectory
    return isinstance(trajectory, Expressions) and (tuple(trajectory.keys) != ("x", "y", "z")
                                                    or any(_TRIG.search(text) for text in trajectory.texts))


def scene_key(scene: Scene, attitude: bool, truth: bool, increments: int = 0, plan: EffectPlan | None = None) -> str:
    """The scene's structure (the validated scene less KEY_EXCLUDES and the fields whose numbers arrive at run
    time, plus the effects' plan), the outputs and every generator module, hashed. `plan`: the scene's
    EffectPlan when the caller has it (building one costs about a millisecond)."""
    outputs = [attitude, truth] + ([increments] if increments else [])
    described = canonical(scene)
    for name in PARAMETRIC + (() if periodic_motion(scene) else TIMING):
        described.pop(name)
    for part in EXPRESSION_PARTS:    # the expressions' structures (in the plan's) stand for their texts
        if isinstance(getattr(scene, part), Expressions):
            described[part].pop("texts")
    spec = {"scene": described, "plan": (plan or EffectPlan(scene)).structure(), "outputs": outputs,
            "code": _code_fingerprint(), "python": list(sys.version_info[:2])}
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:32]


_SEAL = "# hmac-sha256 "


def _label(key: str) -> str:
    return f"kernels/{key}/kernel.py"


def sealed(key: str, source: str) -> str:
    """An entry's kernel.py: the seal line (this cache's HMAC of the source, for this key), then the source."""
    return _SEAL + trust.digest(_label(key), source.encode()).hex() + "\n" + source


def entry_source(path: Path, key: str) -> str | None:
    """The text of an entry's kernel.py if this cache sealed it for this key, else None (edited, damaged, planted
    or copied from another cache: never executed). UntrustedCache if the file is not the user's alone."""
    try:
        text = trust.read_private(path).decode()
    except (FileNotFoundError, UnicodeDecodeError):
        return None
    first, _, rest = text.partition("\n")
    if not first.startswith(_SEAL):
        return None
    try:
        mac = bytes.fromhex(first[len(_SEAL):])
    except ValueError:
        return None
    return text if trust.matches(_label(key), rest.encode(), mac) else None


def discard(directory: Path) -> None:
    """Move aside, then delete: a reader never sees a half-deleted entry under the key's name."""
    trash = directory.with_name(f".trash-{directory.name}-{os.getpid()}-{os.urandom(4).hex()}")
    try:
        os.rename(directory, trash)
    except OSError:
        return
    shutil.rmtree(trash, ignore_errors=True)

