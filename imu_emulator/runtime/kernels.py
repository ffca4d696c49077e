"""The compiled kernels this process holds: compile_kernel generates a scene's source (imu_emulator.codegen),
publishes it in the cache (imu_emulator.runtime.cache) only once it compiled, and loads it as machine code
without numba when the entry holds it (imu_emulator.native.objects), else through numba's dispatcher.
"""
from __future__ import annotations

import importlib
import importlib.util
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from imu_emulator.codegen.generate import generate_source
from imu_emulator.codegen.signature import RUNTIME_IMPORTS, trial, trial_arguments
from imu_emulator.files import trust
from imu_emulator.runtime.cache import cache_dir, discard, entry_source, kernels_dir, scene_key, sealed
from imu_emulator.scene.model import Scene

_loaded: dict[str, object] = {}
NATIVE = "kernel.o"     # the entry's machine code (imu_emulator.native.objects), beside kernel.py


def _module_name(key: str) -> str:
    return f"imu_emulator_kernel_{key}"


def _import(path: Path, key: str, source: str):
    """The module of the entry's source, run from the text whose seal was checked (not read again from the file,
    and never from a .pyc someone could have put beside it); its functions name `path` as their file, where
    numba keeps its cache index."""
    # numba's on-disk cache refers to the module by name when it reloads a compiled kernel.
    spec = importlib.util.spec_from_file_location(_module_name(key), path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        exec(compile(source, str(path), "exec"), module.__dict__)
    except BaseException:
        sys.modules.pop(spec.name, None)
        raise
    _confine_numba_cache(module, path.parent)
    return module


def _confine_numba_cache(module, directory: Path) -> None:
    """numba's cache index is pickled data numba loads: it may live only inside the entry (checked as the user's
    alone), never in NUMBA_CACHE_DIR or the user-wide directory numba falls back to. A dispatcher whose cache is
    elsewhere caches nothing (numba's private attributes, so looked up with care: absent, nothing is changed)."""
    for value in list(vars(module).values()):
        path = getattr(getattr(value, "_cache", None), "_cache_path", None)
        if path is not None and Path(path) != directory / "__pycache__":
            from numba.core.caching import NullCache
            value._cache = NullCache()


def _trial_call(kernel, scene: Scene, attitude: bool, truth: bool, increments: int) -> None:
    """Compile now (numba compiles on the first call) on one sample, with the argument types the Simulation
    uses, so that an entry is only ever published compiled."""
    trial(kernel, scene, attitude, truth, increments)


def _export_native(module, text: str, key: str, scene: Scene, attitude: bool, truth: bool, increments: int,
                   directory: Path) -> bool:
    """Write the machine code of the generated `kernel_body` (compiled for the Simulation's argument types, plus
    its scratch) to directory/NATIVE; False if this numba cannot (the entry then runs on numba's dispatcher)."""
    from imu_emulator.native import objects as native
    if not _native_enabled():
        return False
    scratch = [(module.N_PHASE, module.CHUNK)]
    args = trial_arguments(scene, attitude, truth, increments) + tuple(np.empty(shape) for shape in scratch)
    meta = {"scratch": scratch, "source": _seal_line(text)}
    return native.export(module.kernel_body, args, directory / NATIVE, meta, _seal_label(key))


def _native_enabled() -> bool:
    """IMU_EMULATOR_NATIVE=0: numba's dispatcher only, nothing exported (an escape hatch, and the benchmarks'
    comparison)."""
    return os.environ.get("IMU_EMULATOR_NATIVE") != "0"


def _seal_line(text: str) -> str:
    """The seal line of the entry's source: the machine code names the source it was compiled from."""
    return text.partition("\n")[0]


def _seal_label(key: str) -> str:
    """What the machine code's HMAC is bound to: the entry's key."""
    return f"kernels/{key}/{NATIVE}"


def _load_native(directory: Path, key: str, text: str, scene: Scene, attitude: bool, truth: bool, increments: int):
    """The entry's kernel as machine code (no numba import), tried on no sample; None if there is none, it is
    damaged, not sealed by this cache for this key, or it was compiled from another source."""
    from imu_emulator.native import objects as native
    if not _native_enabled():
        return None
    loaded = native.load(directory / NATIVE, _seal_label(key))
    if loaded is None or loaded[1].get("source") != _seal_line(text):
        return None
    _trial_call(loaded[0], scene, attitude, truth, increments)
    return loaded[0]


def _realize_runtime() -> None:
    """The functions the generated source imports become numba dispatchers (imu_emulator.native.lazy) before numba
    types a kernel that calls them."""
    from imu_emulator.native import lazy as lazy_jit
    for module in RUNTIME_IMPORTS:
        importlib.import_module(module)
    lazy_jit.realize()


def _numba_kernel(path: Path, key: str, text: str, scene: Scene, attitude: bool, truth: bool, increments: int):
    """The generated module's numba kernel (loaded from numba's cache beside it, or compiled), tried."""
    _realize_runtime()
    module = _import(path, key, text)
    _trial_call(module.kernel, scene, attitude, truth, increments)
    return module


def kernel_outputs(scene: Scene, attitude: bool, truth: bool) -> tuple[bool, bool]:
    """The outputs a scene's kernel computes when asked for `attitude` and `truth`: the companion sensors
    (imu_emulator.companions) read the truth and each IMU's attitude, so a scene naming one computes both."""
    companions = any(imu.companions for imu in scene.imus)
    return attitude or companions, truth or companions


def compile_kernel(scene: Scene, attitude: bool = True, truth: bool = False, increments: int = 0, plan=None):
    """The kernel function for this scene's motion, effects and outputs (cached in memory and on disk).
    Loaded as machine code without numba when the entry holds it (imu_emulator.native.objects), else numba's.
    UntrustedCache if the cache or the entry is not the running user's alone (imu_emulator.files.trust).
    Scenes of one structure (imu_emulator.runtime.cache.scene_key) share the kernel: the caller passes the
    scene's numbers at run time (EffectPlan.param_values; `plan`: the scene's EffectPlan if the caller has it)."""
    attitude, truth = kernel_outputs(scene, attitude, truth)
    key = scene_key(scene, attitude, truth, increments, plan)
    if key in _loaded:
        return _loaded[key]
    root = kernels_dir()
    entry = root / key
    with trust.private_umask():
        kernel = _load_entry(entry, key, scene, attitude, truth, increments) if os.path.lexists(entry) else None
        if kernel is None:
            kernel = _generate(root, entry, key, scene, attitude, truth, increments)
    _loaded[key] = kernel
    return kernel


def _load_entry(entry: Path, key: str, scene: Scene, attitude: bool, truth: bool, increments: int):
    """The published entry's kernel, or None after discarding an entry that is not sealed by this cache for this
    key (before running any of it) or that fails to load or compile."""
    trust.check_tree(entry)        # the user's alone, numba's pickled index included, or refused
    text = entry_source(entry / "kernel.py", key)
    try:
        if text is None:
            raise ValueError("seal")
        kernel = _load_native(entry, key, text, scene, attitude, truth, increments)
        if kernel is None:   # no machine code, or damaged: numba's, and write the machine code again
            module = _numba_kernel(entry / "kernel.py", key, text, scene, attitude, truth, increments)
            kernel = module.kernel
            if _export_native(module, text, key, scene, attitude, truth, increments, entry):
                kernel = _load_native(entry, key, text, scene, attitude, truth, increments) or kernel
        return kernel
    except trust.UntrustedCache:
        raise               # not the user's alone: nothing is removed, the user is told
    except Exception:   # planted, truncated, garbage or not compiling: regenerate (never trust it again)
        sys.modules.pop(_module_name(key), None)
        discard(entry)
        return None


def _generate(root: Path, entry: Path, key: str, scene: Scene, attitude: bool, truth: bool, increments: int):
    """Generate, compile in a private staging directory, publish by renaming it to the key's name."""
    _realize_runtime()
    text = sealed(key, generate_source(scene, attitude, truth, increments))
    staging = Path(tempfile.mkdtemp(prefix=f".tmp-{key}-", dir=root))
    kernel = None
    try:
        (staging / "kernel.py").write_text(text)
        module = _import(staging / "kernel.py", key, text)
        if _export_native(module, text, key, scene, attitude, truth, increments, staging):   # compiles once
            kernel = _load_native(staging, key, text, scene, attitude, truth, increments)
        if kernel is None:
            _trial_call(module.kernel, scene, attitude, truth, increments)
        try:
            os.rename(staging, entry)    # atomic publish; fails if another process published first
        except OSError:
            pass                         # theirs is as good as ours: same key, same source
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        sys.modules.pop(_module_name(key), None)
    if kernel is None:
        # Load from the published path, so numba's cache index lives beside the entry, not in the staging dir.
        kernel = _import(entry / "kernel.py", key, text).kernel
    return kernel


def is_loaded(scene: Scene, attitude: bool = True, truth: bool = False, increments: int = 0) -> bool:
    """Whether this process has this scene's kernel loaded already (compile_kernel returns it at once)."""
    return scene_key(scene, *kernel_outputs(scene, attitude, truth), increments) in _loaded


def cached_kernel(scene: Scene, attitude: bool = True, truth: bool = False, increments: int = 0) -> tuple[Path, bool]:
    """Where this scene's kernel lives in the cache, and whether it is there compiled already (numba's index
    beside it), for `check` and the first-run status line; it generates and compiles nothing."""
    entry = cache_dir() / scene_key(scene, *kernel_outputs(scene, attitude, truth), increments)
    return entry, (entry / "kernel.py").exists() and ((entry / NATIVE).exists()
                                                      or any((entry / "__pycache__").glob("*.nbi")))
