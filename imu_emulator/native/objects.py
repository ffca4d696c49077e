"""numba functions kept as machine code that loads without numba.

Loading a function from numba's own cache costs about a second of CPU before the first call: importing numba and
initializing its CPU target (typing and lowering registries), all for a function compiled long ago. Here the
function is compiled once behind a C-ABI wrapper (a `numba.cfunc` taking the call's argument tuple as a PyObject*,
a table of expected types, return pointers and a work area); the object code of that wrapper, which contains
everything it calls (numba links the libraries of the callees into it), is written to a file, and later runs load
it with llvmlite's JIT linker alone. The few C helpers numba's code may call on error paths (numba._helperlib, the
NRT) are loaded as plain extension modules, without importing the numba package. The wrapper reads the tuple in
place (numpy's array struct, scalar objects' values), so a call from Python costs one ctypes call, about what
numba's dispatcher costs; the struct layout is checked once per process (_array_struct_as_expected).

The wrapper is built from the argument values of a trial call, not from a hand-kept list: whatever arguments a
function grows, an integer/float scalar or an array of a plain dtype and any rank is passed through, or a tuple of
those (numba's UniTuple of arrays, which the wire encoders take as their sources), and it may return nothing, a
number or a tuple of numbers. Arrays the function allocates live in numba's runtime (NRT): its
C helpers and its reference-counting functions are loaded without the numba package. Trailing scratch arguments
the caller does not pass may be declared (`scratch` shapes): the loader allocates them per call.

If anything fails (another numba's private API, a platform llvmlite cannot link for, a damaged file), `export`
returns False, `load` returns None and the caller keeps numba's dispatcher. The file is sealed with the cache's
HMAC for the place `label` names (imu_emulator.files.trust): machine code this cache did not write there, or in a
file not the user's alone, is never linked.
"""
from __future__ import annotations

import importlib.util
import json
import os
from pathlib import Path

import numpy as np

from imu_emulator.files import trust

# 8: sealed with the cache's HMAC; 7: memory read by intrinsics; 6: tuples of arguments; 5: the argument tuple
# read in place
_MAGIC = b"IMUK8"
_ENTRY = "entry_c"
_DTYPES = ("float64", "float32", "int64", "uint64", "int32", "uint32", "int16", "uint16", "int8", "uint8")
_symbols_added = False
REFUSED = object()      # NativeFunction.call_checked: an array argument not of the type compiled for


def _describe(value, nested: bool = False) -> list:
    """How one argument is passed: ["scalar", dtype], ["array", dtype, ndim] (numba's own typing of it) or
    ["tuple", [element, ...]] (elements of the first two kinds)."""
    if type(value) is tuple and not nested and value:
        return ["tuple", [_describe(item, nested=True) for item in value]]
    if isinstance(value, np.ndarray):
        if value.dtype.name not in _DTYPES or value.ndim == 0:
            raise TypeError(f"no native passing for {value.dtype} arrays")
        return ["array", value.dtype.name, value.ndim]
    if isinstance(value, (bool, np.bool_)):
        raise TypeError("no native passing for booleans")
    if isinstance(value, np.generic) and value.dtype.name in _DTYPES:
        return ["scalar", value.dtype.name]
    if isinstance(value, int):
        return ["scalar", "int64"]
    if isinstance(value, float):
        return ["scalar", "float64"]
    raise TypeError(f"no native passing for {type(value).__name__}")


def _slots(kinds: list) -> list[tuple[list, int, int]]:
    """What the entry checks, in its order: (kind, parent, index) for each argument (parent -1), then each
    element of a tuple argument (parent: the argument's position, index: its position in the tuple)."""
    slots = [(kind, -1, 0) for kind in kinds]
    for position, kind in enumerate(kinds):
        if kind[0] == "tuple":
            slots += [(item, position, index) for index, item in enumerate(kind[1])]
    return slots


def _expected(kinds: list) -> list[int]:
    """What the entry compares with, in its order: numpy's ndarray type and Python's tuple type, then per slot
    (_slots) six words: its code (0 array, 1 int64, 2 float64, 3 another scalar, 4 tuple), the address of its
    dtype (arrays) or of its numpy scalar type, that of the Python type numba types the same (int, float; else 0,
    matching nothing) or for an array its dtype's scalar type (an equal dtype that is another object), its rank
    (a tuple: its length), its parent and index (_slots).
    Addresses differ per process: the table is built at load and passed at each call."""
    expect = [id(np.ndarray), id(tuple)]
    for kind, parent, index in _slots(kinds):
        if kind[0] == "tuple":
            expect += [4, 0, 0, len(kind[1])]
        elif kind[0] == "array":
            dtype = np.dtype(kind[1])
            expect += [0, id(dtype), id(dtype.type), int(kind[2])]
        else:
            dtype = np.dtype(kind[1])
            code = {"int64": 1, "float64": 2}.get(kind[1], 3)
            expect += [code, id(dtype.type), id({1: int, 2: float}[code]) if code < 3 else 0, 0]
        expect += [parent, index]
    return expect


def _work_size(kinds: list) -> int:
    """The entry's per-call words: a pointer per slot, an int per slot, then the arrays' dimensions."""
    slots = _slots(kinds)
    return 2 * len(slots) + sum(int(k[2]) for k, _, _ in slots if k[0] == "array")


# The entry's check of every argument, one loop whatever the arguments (typing unrolled per-argument checks cost
# numba seconds for a kernel's 20 arguments), reading memory with the intrinsics (plain loads: array indexing
# cost numba half a second of lowering per export): it fills work with each slot's data pointer (an array's data, a
# scalar's value: a numpy scalar's or a Python float's at byte 16, a Python int of up to two 30-bit digits read
# into work) and the arrays' dimensions, or returns 1 if one is not of the type the code was compiled for. A tuple
# is checked (type, length) before its elements, which are read from its items (PyTupleObject word 3 on).
_CHECK = """
    xe = _integer(expect)
    te = _integer(args)
    we = _integer(work)
    if _load(te + 16, I8) != N_ARGS:
        return 1
    s = 2 * N_SLOTS
    for j in range(N_SLOTS):
        e = xe + 16 + 48 * j
        code = _load(e, I8)
        own = _load(e + 8, I8)
        python = _load(e + 16, I8)
        nd = _load(e + 24, I8)
        parent = _load(e + 32, I8)
        if parent < 0:
            o = _load(te + 24 + 8 * j, I8)
        else:
            o = _load(_load(te + 24 + 8 * parent, I8) + 24 + 8 * _load(e + 40, I8), I8)
        kind = _load(o + 8, I8)
        if code == 4:
            if kind != _load(xe + 8, I8) or _load(o + 16, I8) != nd:
                return 1
            continue
        if code == 0:
            # PyArrayObject words: 1 type, 2 data, 3 nd (int), 4 dimensions, 7 descr, 8 flags (1: C-contiguous)
            if kind != _load(xe, I8) or (_load(o + 24, I8) & 0xFFFFFFFF) != nd or (_load(o + 64, I8) & 1) == 0:
                return 1
            descr = _load(o + 56, I8)
            if descr != own:
                # another dtype object: the same if its scalar type is (PyArray_Descr word 2) in native order
                # (byte 26: '>' is the only foreign order on a little-endian machine)
                if _load(descr + 16, I8) != python or _load(descr + 26, U1) == 62:
                    return 1
            _put(we + 8 * j, I8, _load(o + 16, I8))
            dims = _load(o + 32, I8)
            for d in range(nd):
                _put(we + 8 * (s + d), I8, _load(dims + 8 * d, I8))
            s += nd
        elif kind == own or (code == 2 and kind == python):
            _put(we + 8 * j, I8, o + 16)
        elif code == 1 and kind == python and -2 <= _load(o + 16, I8) <= 2:
            size = _load(o + 16, I8)
            value = np.int64(0)
            if size != 0:
                value = np.int64(_load(o + 24, U4))
            if size == 2 or size == -2:
                value |= np.int64(_load(o + 28, U4)) << 30
            if size < 0:
                value = -value
            _put(we + 8 * (N_SLOTS + j), I8, value)
            _put(we + 8 * j, I8, we + 8 * (N_SLOTS + j))
        else:
            return 1
"""


def _wrapper_source(kinds: list, n_returns: int | None) -> str:
    """The cfunc taking the call's argument tuple as a PyObject* and reading it in place (_CHECK), so that a call
    marshals nothing in Python; then `expect` (_expected), the return pointers and a per-thread work area. It
    returns 1 without calling the function when an argument is not of the type (rank, C-contiguity) the code
    was compiled for (the caller converts it and calls again), else 0, having stored what the function returns
    (None: nothing; 0: a number; n: a tuple of n). Only integers reach this source; dtypes are looked up by
    position in the namespace (D0, ..., R0, ...)."""
    n = len(kinds)
    slots = _slots(kinds)
    lines, at = [], 2 * len(slots)
    for i, (kind, _, _) in enumerate(slots):
        if kind[0] == "array":
            nd = int(kind[2])
            shape = "".join(f"_load(we + {8 * (at + d)}, I8), " for d in range(nd))
            lines.append(f"    a{i} = _view(_load(we + {8 * i}, I8), ({shape}), D{i})")
            at += nd
        elif kind[0] == "scalar":
            lines.append(f"    a{i} = _load(_load(we + {8 * i}, I8), D{i})")
    for i, (kind, parent, _) in enumerate(slots):
        if kind[0] == "tuple":
            items = "".join(f"a{j}, " for j, (_, p, _) in enumerate(slots) if p == i)
            lines.append(f"    a{i} = ({items})")
    call = f"function({', '.join(f'a{i}' for i in range(n))})"
    if n_returns is None:
        lines.append(f"    {call}")
    elif n_returns == 0:     # a single number
        lines += [f"    r = {call}", "    _put(rets[0], R0, r)"]
    else:
        lines.append(f"    r = {call}")
        lines += [f"    _put(rets[{j}], R{j}, r[{j}])" for j in range(n_returns)]
    lines.append("    return 0")
    return "\n".join([
        "@numba.cfunc(SIGNATURE, nogil=True, error_model='numpy')",
        f"def {_ENTRY}(args, expect, rets, work):",
    ]) + _CHECK + "\n".join(lines) + "\n"


def _intrinsics() -> dict:
    """The entry's memory access, as numba intrinsics (code emitted in place, nothing compiled on its own: numba's
    carray compiled an overload per dtype and rank, and cost a third of every export):
    _view(address, shape, dtype) a C-contiguous array over memory (no owner), _load(address, dtype) a number,
    _put(address, dtype, value) stores one, _integer(pointer) a pointer as an int64. An address is an int64 or
    a pointer."""
    from numba import types
    from numba.core import cgutils
    from numba.extending import intrinsic
    from numba.np.arrayobj import make_array, populate_array

    def pointer(context, builder, kind, value, dtype):
        data = context.get_data_type(dtype).as_pointer()
        if isinstance(kind, types.Integer):
            return builder.inttoptr(value, data)
        return builder.bitcast(value, data)

    @intrinsic
    def _view(typingctx, address, shape, dtype):
        if not isinstance(shape, types.BaseTuple) or not isinstance(dtype, types.DTypeSpec):
            return None
        array = types.Array(dtype.dtype, len(shape), "C")

        def codegen(context, builder, signature, args):
            dims = [context.cast(builder, builder.extract_value(args[1], d), signature.args[1][d], types.intp)
                    for d in range(len(shape))]
            itemsize = context.get_abi_sizeof(context.get_data_type(array.dtype))
            strides, stride = [], context.get_constant(types.intp, itemsize)
            for dim in reversed(dims):
                strides.insert(0, stride)
                stride = builder.mul(stride, dim)
            view = make_array(array)(context, builder)
            populate_array(view, data=pointer(context, builder, signature.args[0], args[0], array.dtype), shape=dims,
                           strides=strides, itemsize=itemsize, meminfo=None)
            return view._getvalue()
        return array(address, shape, dtype), codegen

    @intrinsic
    def _load(typingctx, address, dtype):
        def codegen(context, builder, signature, args):
            return builder.load(pointer(context, builder, signature.args[0], args[0], dtype.dtype))
        return dtype.dtype(address, dtype), codegen

    @intrinsic
    def _put(typingctx, address, dtype, value):
        def codegen(context, builder, signature, args):
            stored = context.cast(builder, args[2], signature.args[2], dtype.dtype)
            builder.store(stored, pointer(context, builder, signature.args[0], args[0], dtype.dtype))
            return context.get_dummy_value()
        return types.none(address, dtype, value), codegen

    @intrinsic
    def _integer(typingctx, address):
        def codegen(context, builder, signature, args):
            return builder.ptrtoint(args[0], cgutils.intp_t)
        return types.int64(types.voidptr), codegen
    return {"_view": _view, "_load": _load, "_put": _put, "_integer": _integer}


def _returns(function, args) -> tuple[int | None, list[str]]:
    """What `function` compiled for these arguments returns: (None, []) nothing, (0, [dtype]) one number,
    (n, dtypes) a tuple of n numbers."""
    import numba
    from numba import types
    from numba.np.numpy_support import as_dtype
    signature = tuple(numba.typeof(a) for a in args)
    function.compile(signature)
    result = function.overloads[signature].signature.return_type
    if result == types.none:
        return None, []
    if isinstance(result, types.BaseTuple):
        return len(result), [as_dtype(t).name for t in result]
    return 0, [as_dtype(result).name]


def _contiguous(value):
    """The argument as the entry passes it: arrays (also in a tuple) C-contiguous."""
    if isinstance(value, np.ndarray):
        return np.ascontiguousarray(value)
    if type(value) is tuple:
        return tuple(_contiguous(item) for item in value)
    return value


def export(function, args: tuple, path: Path, meta: dict, label: str) -> bool:
    """Compile `function` (a numba dispatcher) for the types of `args` behind a C entry, and write its object
    code with `meta` (JSON) to `path` atomically, sealed for `label`. False if this numba cannot."""
    try:
        import numba
        from numba import types
        kinds = [_describe(a) for a in args]
        args = tuple(_contiguous(a) for a in args)
        n_returns, returns = _returns(function, args)
        if any(name not in _DTYPES for name in returns):
            return False
        namespace = {"numba": numba, "np": np, "function": function, **_intrinsics(), "I8": np.int64,
                     "U4": np.uint32, "U1": np.uint8,
                     "N_ARGS": len(kinds),
                     "N_SLOTS": len(_slots(kinds)),
                     "SIGNATURE": types.int32(types.voidptr, types.voidptr, types.CPointer(types.voidptr),
                                              types.voidptr)}
        namespace.update({f"D{i}": np.dtype(k[1]).type for i, (k, _, _) in enumerate(_slots(kinds))
                          if k[0] != "tuple"})
        namespace.update({f"R{j}": np.dtype(name).type for j, name in enumerate(returns)})
        exec(compile(_wrapper_source(kinds, n_returns), f"<native wrapper {path.name}>", "exec"), namespace)
        entry = namespace[_ENTRY]
        code = bytes(entry._library._get_compiled_object())      # numba's private API: guarded
        name = entry.native_name
    except Exception:      # noqa: BLE001 -- any failure means: keep numba's dispatcher
        return False
    header = json.dumps({"entry": name, "kinds": kinds, "returns": [n_returns, returns], "meta": meta}).encode()
    body = len(header).to_bytes(4, "little") + header + code
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}-{os.urandom(4).hex()}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    with open(fd, "wb") as f:
        f.write(_MAGIC + trust.digest(label, body) + body)
    os.replace(tmp, path)     # a concurrent reader sees the whole file or none
    return True


def kinds_of(args) -> list | None:
    """How these arguments would be passed, or None if one of them cannot be (the caller uses numba)."""
    try:
        return [_describe(a) for a in args]
    except TypeError:
        return None


_CTYPES = {"float64": "c_double", "float32": "c_float", "int64": "c_int64", "uint64": "c_uint64", "int32": "c_int32",
           "uint32": "c_uint32", "int16": "c_int16", "uint16": "c_uint16", "int8": "c_int8", "uint8": "c_uint8"}


def _array_struct_as_expected() -> bool:
    """Whether numpy's array struct lies where the entry reads it (64-bit CPython, little-endian): checked on a
    view, once per process. If not, nothing loads and numba's dispatcher runs."""
    import ctypes
    import sys
    if sys.byteorder != "little" or ctypes.sizeof(ctypes.c_void_p) != 8:
        return False
    probe = np.zeros((4, 3))[1:3]
    words = (ctypes.c_int64 * 9).from_address(id(probe))
    dims = (ctypes.c_int64 * 2).from_address(words[4])
    arrays = (words[1] == id(np.ndarray) and words[2] == probe.ctypes.data and words[3] & 0xFFFFFFFF == 2
              and tuple(dims) == (2, 3) and words[7] == id(probe.dtype) and words[8] & 1 == 1)
    big, negative, value, real = 2 ** 40 + 3, -5, np.uint64(7), 2.5
    digits = (ctypes.c_uint32 * 2).from_address(id(big) + 24)
    held = (big, negative, value, real)
    items = (ctypes.c_int64 * 7).from_address(id(held))
    scalars = (items[2] == 4 and items[3] == id(big) and (ctypes.c_int64 * 3).from_address(id(big))[2] == 2
               and digits[0] | digits[1] << 30 == big and (ctypes.c_int64 * 3).from_address(id(negative))[2] == -1
               and (ctypes.c_uint64 * 3).from_address(id(value))[2] == 7
               and (ctypes.c_double * 3).from_address(id(real))[2] == 2.5)
    native_, swapped = np.dtype("=f8"), np.dtype(">f8")
    dtypes = ((ctypes.c_int64 * 3).from_address(id(native_))[2] == id(np.float64)
              and (ctypes.c_uint8 * 32).from_address(id(native_))[26] in (ord("="), ord("<"))
              and (ctypes.c_uint8 * 32).from_address(id(swapped))[26] == ord(">"))
    return arrays and scalars and dtypes


class NativeFunction:
    """Calls the loaded machine code like the numba dispatcher: f(*args) (then the declared scratch arrays).

    The entry reads the argument tuple in place (numpy's array struct, scalars' values), so a call costs one
    ctypes call with one object, less than numba's dispatcher typing each argument. An argument of another type
    (an array of another dtype or not C-contiguous, a large Python int) is refused by the entry: it is
    converted, passed again and (arrays) written back."""

    def __init__(self, address: int, kinds: list, returns: list, scratch: list):
        import ctypes
        import threading
        self._call = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.py_object, ctypes.c_void_p, ctypes.c_void_p,
                                      ctypes.c_void_p)(address)
        self.kinds = kinds
        self.n_returns, self.returns = returns
        self.scratch = [tuple(int(x) for x in shape) for shape in scratch]
        self._dtypes = [[np.dtype(item[1]) for item in k[1]] if k[0] == "tuple" else np.dtype(k[1]) for k in kinds]
        # the dtype objects numpy uses for new arrays of these types (singletons): their addresses for the entry
        self._expect = np.array(_expected(kinds), dtype=np.int64)
        self._expect_address = self._expect.ctypes.data
        self._local = threading.local()

    def _rets(self):
        local = self._local
        if not hasattr(local, "address"):
            import ctypes
            # ctypes numbers: .value is the Python int or float numba's dispatcher would return
            local.results = [getattr(ctypes, _CTYPES[name])() for name in self.returns]
            local.rets = (ctypes.c_void_p * max(len(self.returns), 1))(*[ctypes.addressof(r) for r in local.results])
            local.address = ctypes.addressof(local.rets)
            local.work = np.zeros(max(_work_size(self.kinds), 1), dtype=np.int64)
            local.work_address = local.work.ctypes.data
        return local

    def _returned(self, local):
        if self.n_returns is None:
            return None
        if self.n_returns == 0:
            return local.results[0].value
        return tuple([r.value for r in local.results])

    def call_checked(self, args):
        """f(*args) for a function without scratch, or REFUSED when an array is not of the compiled type."""
        local = self._rets()
        if self._call(args, self._expect_address, local.address, local.work_address):
            return REFUSED
        return self._returned(local)

    def __call__(self, *args):
        if len(args) + len(self.scratch) != len(self.kinds):
            raise TypeError(f"takes {len(self.kinds) - len(self.scratch)} arguments, got {len(args)}")
        if self.scratch:
            args = args + tuple(np.empty(shape) for shape in self.scratch)
        local = self._rets()
        if self._call(args, self._expect_address, local.address, local.work_address):
            self._convert_and_call(args, local)
        return self._returned(local)

    def _convert_and_call(self, args, local) -> None:
        """The machine code indexes C-contiguous arrays of its dtypes: work on copies, written back after."""
        copies = []

        def convert(value, kind, dtype, where):
            if kind[0] == "tuple":
                if not isinstance(value, tuple) or len(value) != len(kind[1]):
                    raise TypeError(f"{where}: expected a tuple of {len(kind[1])}")
                return tuple(convert(v, k, d, f"{where}[{j}]") for j, (v, k, d) in enumerate(zip(value, kind[1], dtype)))
            if kind[0] != "array":
                return dtype.type(value)
            if not isinstance(value, np.ndarray) or value.ndim != kind[2]:
                raise TypeError(f"{where}: expected an array of {kind[2]} dimensions")
            if type(value) is not np.ndarray or value.dtype is not dtype or not value.flags.c_contiguous:
                contiguous = np.empty(value.shape, dtype=dtype)     # numpy's own dtype object
                contiguous[...] = value
                copies.append((value, contiguous))
                return contiguous
            return value
        converted = tuple(convert(value, self.kinds[i], self._dtypes[i], f"argument {i}") for i, value in enumerate(args))
        if self._call(converted, self._expect_address, local.address, local.work_address):
            raise TypeError("arguments not of the types the machine code was compiled for")
        for original, contiguous in copies:
            if original.flags.writeable:
                original[...] = contiguous


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


def _jit_engine():
    """A fresh llvmlite MCJIT engine (one per object: objects may define the same linked-in helpers), with the
    symbols numba-compiled code refers to (the names numba itself registers) added once per process."""
    global _symbols_added
    import llvmlite.binding as llvm
    if not _symbols_added:
        import builtins
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
        _symbols_added = True
    machine = llvm.Target.from_default_triple().create_target_machine()
    return llvm.create_mcjit_compiler(llvm.parse_assembly(""), machine)


def load(path: Path, label: str) -> tuple[NativeFunction, dict] | None:
    """The function `export` wrote to `path` for `label` and its `meta`, or None if there is none, it is damaged,
    this cache did not seal it for `label`, or it cannot be linked here. UntrustedCache if the file is not the
    user's alone."""
    try:
        blob = trust.read_private(path)
    except FileNotFoundError:
        return None
    body = blob[len(_MAGIC) + 32:]
    if blob[:len(_MAGIC)] != _MAGIC or not trust.matches(label, body, blob[len(_MAGIC):len(_MAGIC) + 32]):
        return None
    try:
        import llvmlite.binding as llvm
        size = int.from_bytes(body[:4], "little")
        header = json.loads(body[4:4 + size])
        engine = _jit_engine()
        engine.add_object_file(llvm.ObjectFileRef.from_data(body[4 + size:]))
        engine.finalize_object()
        address = engine.get_function_address(header["entry"])
        if not address:
            return None
        if not _array_struct_as_expected():
            return None
        meta = header["meta"]
        function = NativeFunction(address, header["kinds"], header["returns"], meta.get("scratch", []))
        function.engine = engine     # the machine code lives as long as its engine
        return function, meta
    except Exception:      # noqa: BLE001 -- a foreign object or llvmlite without MCJIT: compile again
        return None
