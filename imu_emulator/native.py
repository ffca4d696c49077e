"""Compiled kernels kept as machine code that loads without numba.

Loading a kernel from numba's own cache costs about 0.5 s of CPU before the first sample: importing numba and
initializing its CPU target (typing and lowering registries, scipy.linalg for BLAS), all for a function that was
compiled long ago. Here the kernel is compiled once behind a C-ABI wrapper (`numba.cfunc` taking pointers and
shapes), its object code is written beside the kernel source, and later runs load that object with llvmlite's JIT
linker alone (about 0.04 s of CPU). The few C helpers numba's code may call on error paths (numba._helperlib,
the NRT) are loaded as plain extension modules, without importing the numba package.

The kernel must not allocate (NRT-managed arrays would need numba's runtime): scratch space is an argument.
If anything here fails (another numba's private API, a platform llvmlite cannot link for), `export` returns False,
`load` returns None and the caller keeps using numba's dispatcher.
"""
from __future__ import annotations

import ctypes
import importlib.util
import json
import os
from pathlib import Path

import numpy as np

_ENTRY = "kernel_c"
_linker = None


def _wrapper_source(ndims: tuple[int, ...]) -> str:
    """A cfunc that turns (k0, n, pointers, shapes) into C-contiguous float64 arrays and calls `kernel`.
    Only integers from `ndims` reach this source."""
    args, lines = [], []
    for i, nd in enumerate(ndims):
        shape = ", ".join(f"shapes[{3 * i + d}]" for d in range(int(nd)))
        lines.append(f"    a{i} = numba.carray(ptrs[{i}], ({shape},))")
        args.append(f"a{i}")
    return "\n".join([
        "@numba.cfunc(SIGNATURE, nogil=True, error_model='numpy')",
        f"def {_ENTRY}(k0, n, ptrs, shapes):",
        *lines,
        f"    kernel(k0, n, {', '.join(args)})",
    ]) + "\n"


def export(kernel, ndims: tuple[int, ...], path: Path, meta: dict) -> bool:
    """Compile `kernel` (a numba dispatcher taking k0, n and float64 arrays of these ranks) behind a C entry and
    write its object code to `path` (atomically), with `meta` (JSON) for the loader. False if this numba cannot."""
    try:
        import numba
        from numba import types
        namespace = {"numba": numba, "kernel": kernel, "SIGNATURE": types.void(
            types.int64, types.int64, types.CPointer(types.CPointer(types.float64)), types.CPointer(types.int64))}
        exec(compile(_wrapper_source(ndims), f"<native wrapper {path.name}>", "exec"), namespace)
        entry = namespace[_ENTRY]
        code = entry._library._get_compiled_object()      # numba's private API: guarded
        name = entry.native_name
    except Exception:      # noqa: BLE001 -- any failure means: keep numba's dispatcher
        return False
    header = json.dumps({"entry": name, "meta": meta, "host": _host()}).encode()
    blob = len(header).to_bytes(4, "little") + header + bytes(code)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_bytes(blob)
    os.replace(tmp, path)
    return True


class NativeKernel:
    """Calls the loaded machine code like the numba dispatcher: kernel(k0, n, *arrays)."""

    def __init__(self, address: int, ndims: tuple[int, ...]):
        self._call = ctypes.CFUNCTYPE(None, ctypes.c_int64, ctypes.c_int64, ctypes.c_void_p, ctypes.c_void_p)(address)
        self.ndims = ndims

    def __call__(self, k0, n, *arrays):
        if len(arrays) != len(self.ndims):
            raise TypeError(f"kernel takes {len(self.ndims)} arrays, got {len(arrays)}")
        pointers = (ctypes.c_void_p * len(arrays))()
        shapes = np.zeros(3 * len(arrays), dtype=np.int64)
        views, copies = [], []
        for i, (array, nd) in enumerate(zip(arrays, self.ndims)):
            if array.ndim != nd:
                raise TypeError(f"kernel array {i}: expected {nd} dimensions, got {array.ndim}")
            if array.dtype != np.float64 or not array.flags.c_contiguous:
                # the machine code indexes C-contiguous float64; write results back into the caller's view
                contiguous = np.ascontiguousarray(array, dtype=np.float64)
                copies.append((array, contiguous))
                array = contiguous
            views.append(array)
            pointers[i] = array.ctypes.data
            shapes[3 * i:3 * i + nd] = array.shape
        self._call(int(k0), int(n), pointers, shapes.ctypes.data)
        for original, contiguous in copies:
            if original.flags.writeable:
                original[...] = contiguous


def _host() -> str:
    """The CPU the machine code is compiled for (numba targets the host's exact CPU and features)."""
    import llvmlite.binding as llvm
    return f"{llvm.get_process_triple()} {llvm.get_host_cpu_name()} {llvm.get_host_cpu_features().flatten()}"


def _numba_extension(name: str, relative: str):
    """A numba C extension module loaded from its file, without running numba/__init__.py."""
    spec = importlib.util.find_spec("numba")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("numba is not installed")
    folder = Path(list(spec.submodule_search_locations)[0]) / Path(relative).parent
    stem = Path(relative).name + "."
    candidates = [p for p in folder.iterdir() if p.name.startswith(stem) and p.suffix in (".so", ".pyd")]
    if not candidates:
        raise ImportError(f"numba extension {relative} not found")
    ext_spec = importlib.util.spec_from_file_location(name, candidates[0])
    module = importlib.util.module_from_spec(ext_spec)
    ext_spec.loader.exec_module(module)
    return module


def _jit_linker():
    """llvmlite's MCJIT with the symbols numba-compiled code refers to (the same names numba itself registers)."""
    global _linker
    if _linker is None:
        import builtins

        import llvmlite.binding as llvm
        llvm.initialize_native_target()
        llvm.initialize_native_asmprinter()
        helpers = _numba_extension("numba._helperlib", "_helperlib")
        nrt = _numba_extension("numba.core.runtime._nrt_python", "core/runtime/_nrt_python")
        llvm.add_symbol("_Py_NoneStruct", id(None))
        for py_name, address in helpers.c_helpers.items():
            llvm.add_symbol("numba_" + py_name, address)
        for py_name, address in nrt.c_helpers.items():
            llvm.add_symbol(py_name if py_name.startswith("_") else "NRT_" + py_name, address)
        for obj in vars(builtins).values():
            if isinstance(obj, type) and issubclass(obj, BaseException):
                llvm.add_symbol(f"PyExc_{obj.__name__}", id(obj))
        machine = llvm.Target.from_default_triple().create_target_machine()
        _linker = llvm.create_mcjit_compiler(llvm.parse_assembly(""), machine)
    return _linker


def load(path: Path, ndims: tuple[int, ...]) -> tuple[NativeKernel, dict] | None:
    """The kernel whose object code `export` wrote to `path` and its `meta`, or None if there is none or it cannot
    be linked."""
    try:
        blob = path.read_bytes()
    except OSError:
        return None
    try:
        import llvmlite.binding as llvm
        size = int.from_bytes(blob[:4], "little")
        header = json.loads(blob[4:4 + size])
        if header.get("host") != _host():   # compiled for another CPU (a copied cache): compile again
            return None
        engine = _jit_linker()
        engine.add_object_file(llvm.ObjectFileRef.from_data(blob[4 + size:]))
        engine.finalize_object()
        address = engine.get_function_address(header["entry"])
    except Exception:      # noqa: BLE001 -- a damaged or foreign object: compile again
        return None
    if not address:
        return None
    return NativeKernel(address, ndims), header["meta"]
