"""numba functions that do not import numba until one of them is needed.

A warm run loads its kernel as machine code (imu_emulator.native.objects) and never needs numba, but the modules of
numba functions (the kernel's runtime imports, the wire encoders) are imported anyway. Their functions are declared
with `@jit(...)` instead of `@numba.njit(...)`: the name holds a `Deferred`.

- Called from Python, a Deferred runs its machine code (also once numba is imported, so that every function
  called from Python gets its object file on the first run that calls it): the object file for these
  argument types under the cache directory (IMU_EMULATOR_CACHE, like the kernels, trusted and sealed as they are:
  imu_emulator.files.trust), keyed on the bytes of every
  module of the function's package, numba's version and the argument types; if there is none (or it is damaged),
  numba compiles it once and writes it. Arguments that cannot be passed that way (structured arrays, objects),
  results that are arrays, and IMU_EMULATOR_NATIVE=0 take numba's dispatcher (tuples of arrays and numbers
are passed).
- `realize()` imports numba, builds every declared dispatcher and puts each in its module's globals under its own
  name, so that numba's typing (which reads those globals) and `from module import name` after that see the real
  dispatcher. Code that numba compiles and that calls these functions must call `realize()` first.
"""
from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import sys
from pathlib import Path

import numpy as np

from imu_emulator.files import trust

_pending: list["Deferred | DeferredIntrinsic"] = []
# IMU_EMULATOR_NATIVE=0: numba's dispatcher only (read once: a per-call lookup cost a microsecond per call;
# tools/bench_encode.py sets it to compare both in one process)
NATIVE = os.environ.get("IMU_EMULATOR_NATIVE") != "0"

_fingerprints: dict[str, str] = {}


class Deferred:
    """Stands for `numba.njit(**options)(py_func)` until that is needed."""

    def __init__(self, py_func, options: dict):
        self.py_func = py_func
        self.options = options
        self.dispatcher = None
        self._native: dict[str, object] = {}      # argument kinds -> loaded machine code (or None: use numba)
        self._last = None                         # the machine code called last
        self._numba_only = False
        _pending.append(self)

    def __call__(self, *args):
        if NATIVE and not self._numba_only:
            # the last machine code called, again: its entry checks every argument's type itself (refusing others),
            # so a call from Python costs less than numba's dispatcher (tools/bench_encode.py)
            last = self._last
            if last is not None:
                result = last.call_checked(args)
                if result is not _refused():
                    return result
            function = self._machine_code(args)
            if function is not None:
                self._last = function
                return function(*args)
            # arguments machine code cannot take (structured arrays, objects): numba's dispatcher from now on,
            # without looking at the arguments twice per call
            self._numba_only = True
        realize()
        return _NUMBA_CALL[type(self.dispatcher)](self.dispatcher, *args)

    def _machine_code(self, args):
        # the types that decide the compiled code, cheaply (dtype names cost microseconds to build)
        quick = tuple(_quick(a) for a in args)
        if quick in self._native:
            return self._native[quick]
        from imu_emulator.native import objects
        kinds = objects.kinds_of(args)
        if kinds is None:
            self._native[quick] = None
            return None
        signature = json.dumps(kinds)
        if signature not in self._native:
            path = trust.trusted_dir("functions") / f"{self._key(signature)}.o"
            label = f"functions/{path.name}"
            refused = path.with_suffix(".numba")    # a marker: this numba cannot export it, do not try again
            loaded = None if refused.exists() else objects.load(path, label)
            if loaded is None and not refused.exists():
                realize()
                with trust.private_umask():
                    if objects.export(self.dispatcher, args, path, {}, label):
                        loaded = objects.load(path, label)
                    else:
                        refused.touch()
            self._native[signature] = None if loaded is None else loaded[0]
        self._native[quick] = self._native[signature]
        return self._native[signature]

    def _key(self, signature: str) -> str:
        h = hashlib.sha256(signature.encode())
        h.update(f"{self.py_func.__module__}.{self.py_func.__qualname__}/{sys.version_info[:2]}".encode())
        h.update(_fingerprint(self.py_func.__module__.split(".")[0]).encode())
        h.update(_fingerprint("imu_emulator.native").encode())      # how the object's entry is built and called
        h.update(_fingerprint("numba").encode())
        return h.hexdigest()[:32]

    def __repr__(self) -> str:
        return f"<deferred numba function {self.py_func.__module__}.{self.py_func.__qualname__}>"


def _quick(value):
    if type(value) is np.ndarray:
        return value.dtype, value.ndim
    if type(value) is tuple:      # the encoders' sources: one compiled function per kind of tuple
        return tuple(_quick(item) for item in value)
    return type(value)


_REFUSED = []


def _refused():
    if not _REFUSED:
        from imu_emulator.native.objects import REFUSED
        _REFUSED.append(REFUSED)
    return _REFUSED[0]


class DeferredIntrinsic:
    """Stands for `numba.extending.intrinsic(func)` until realize(): an intrinsic (LLVM code a numba function
    inlines, such as a memcpy) needs numba to be defined, and the functions calling it are Deferred themselves."""

    def __init__(self, func):
        self.func = func
        _pending.append(self)

    def __repr__(self) -> str:
        return f"<deferred numba intrinsic {self.func.__module__}.{self.func.__qualname__}>"


def intrinsic(func):
    """`@intrinsic`: numba.extending.intrinsic, applied by realize() (before any Deferred that calls it compiles;
    the intrinsic's own body imports what it needs of numba)."""
    return DeferredIntrinsic(func)


def jit(py_func=None, **options):
    """`@jit` or `@jit(cache=True, ...)`: numba.njit's options, applied when numba is first needed."""
    if py_func is None:
        return lambda f: Deferred(f, options)
    return Deferred(py_func, options)


def _fingerprint(package: str) -> str:
    """A hash of every Python file of a top-level package (read once per process; numba's by its version file,
    without importing it)."""
    if package not in _fingerprints:
        spec = importlib.util.find_spec(package)
        if spec.submodule_search_locations:
            folder = Path(list(spec.submodule_search_locations)[0])
            files = [folder / "_version.py"] if package == "numba" else sorted(folder.rglob("*.py"))
        else:    # a module on its own
            folder, files = Path(spec.origin).parent, [Path(spec.origin)]
        h = hashlib.sha256()
        for path in files:
            h.update(path.relative_to(folder).as_posix().encode())
            h.update(path.read_bytes())
        _fingerprints[package] = h.hexdigest()
    return _fingerprints[package]


_NUMBA_CALL: dict[type, object] = {}      # our dispatcher subclass -> numba's own call
_subclasses: dict[type, type] = {}


def _python_calls_to_machine_code(base: type) -> type:
    """A subclass of numba's dispatcher class whose calls from Python go through the Deferred's machine code."""
    if base in _subclasses:
        return _subclasses[base]

    def __call__(self, *args, **kwargs):
        if kwargs:
            return base.__call__(self, *args, **kwargs)
        return self.deferred(*args)
    cls = type(base.__name__, (base,), {"__call__": __call__, "__module__": base.__module__})
    _NUMBA_CALL[cls] = base.__call__
    _subclasses[base] = cls
    return cls


def realize() -> None:
    """Build every declared dispatcher (imports numba; compiles nothing: numba compiles on first call)."""
    if not _pending:
        return
    import numba
    from numba.extending import intrinsic as numba_intrinsic
    built = {}
    while _pending:
        deferred = _pending.pop(0)
        if type(deferred) is DeferredIntrinsic:
            built[id(deferred)] = numba_intrinsic(deferred.func)
            continue
        dispatcher = numba.njit(**deferred.options)(deferred.py_func)
        # Calls from Python keep going to the machine code (numba's typing sees a plain dispatcher)
        dispatcher.__class__ = _python_calls_to_machine_code(type(dispatcher))
        dispatcher.deferred = deferred
        deferred.dispatcher = built[id(deferred)] = dispatcher
    # every module that holds one (its own, and those that imported it by name), as numba reads their globals
    for module in list(sys.modules.values()):
        names = getattr(module, "__dict__", None)
        if names is None:
            continue
        for name, value in list(names.items()):
            if type(value) in (Deferred, DeferredIntrinsic) and id(value) in built:
                names[name] = built[id(value)]
