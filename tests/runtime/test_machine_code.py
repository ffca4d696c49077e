"""numba functions kept as machine code (imu_emulator.native): what the loaded object computes equals what numba's
dispatcher computes for the same source (the oracle), for scalars of several dtypes, arrays, tuple results and
arrays allocated inside; warm runs import no numba; a damaged object is compiled again."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

from imu_emulator.native import objects
from tests.support.paths import REPO

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

ROOT = REPO


@numba.njit(cache=False)
def _mixed(key, scale, values, out, n):
    """uint64 and float32 inputs, an array written in place, a scratch array allocated, a tuple returned."""
    tmp = np.zeros(3, dtype=np.float32)
    total = 0.0
    for i in range(n):
        out[i] = values[i] * scale + float(key % np.uint64(7))
        tmp[i % 3] += np.float32(out[i])
        total += out[i]
    return n, total, tmp[0]


def test_exported_function_equals_numba_dispatcher(tmp_path, monkeypatch):
    values = np.linspace(-1.0, 2.0, 10)
    args = (np.uint64(2**63 + 12345), np.float32(1.5), values, np.zeros(10), 8)
    path = tmp_path / "mixed.o"
    assert objects.export(_mixed, args, path, {"note": "x"}, "functions/mixed.o")
    assert objects.load(path, "functions/other.o") is None       # sealed for another place: not linked
    function, meta = objects.load(path, "functions/mixed.o")
    assert meta == {"note": "x"}
    expected_out, got_out = np.zeros(10), np.zeros(10)
    expected = _mixed(args[0], args[1], values, expected_out, 8)
    got = function(args[0], args[1], values, got_out, 8)
    assert got == expected and np.array_equal(got_out, expected_out)
    # a view that is not contiguous is written through
    wide = np.zeros((10, 2))
    function(args[0], args[1], values, wide[:, 1], 8)
    assert np.array_equal(wide[:, 1], expected_out) and not wide[:, 0].any()
    with pytest.raises(TypeError):
        function(args[0], args[1], values[None, :], got_out, 8)


@pytest.mark.parametrize("damage", [lambda b: b[: len(b) // 2], lambda b: b[:-50] + bytes([b[-50] ^ 1]) + b[-49:],
                                    lambda b: b"garbage"])
def test_damaged_object_does_not_load(tmp_path, monkeypatch, damage):
    path = tmp_path / "mixed.o"
    assert objects.export(_mixed, (np.uint64(1), np.float32(1.0), np.zeros(3), np.zeros(3), 3), path, {}, "m.o")
    path.write_bytes(damage(path.read_bytes()))
    assert objects.load(path, "m.o") is None


def _run(code: str, cache: Path, native: bool = True) -> list:
    env = {**os.environ, "IMU_EMULATOR_CACHE": str(cache), "IMU_EMULATOR_NATIVE": "1" if native else "0"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])     # after what the command itself printed


def test_deferred_function_runs_without_numba_once_cached(tmp_path, monkeypatch):
    code = ("import sys, json; from imu_emulator.numerics.counter_rng import normals; "
            "print(json.dumps([normals(2**64 - 5, 7, 6).tolist(), 'numba' in sys.modules]))")
    first, second = _run(code, tmp_path), _run(code, tmp_path)
    oracle = _run(code, tmp_path, native=False)              # numba's dispatcher on the same source
    assert first[1] is True and second[1] is False and oracle[1] is True
    assert first[0] == second[0] == oracle[0]
    # damaged: numba compiles it again and rewrites it
    (path,) = (tmp_path / "functions").glob("*.o")
    path.write_bytes(path.read_bytes()[:100])
    again = _run(code, tmp_path)
    monkeypatch.setenv("IMU_EMULATOR_CACHE", str(tmp_path))
    assert again == first and objects.load(path, f"functions/{path.name}") is not None


def test_warm_stream_imports_no_numba_and_sends_the_same_bytes(tmp_path):
    scene = ROOT / "examples" / "circle.toml"

    def stream_to(name: str) -> str:
        return ("import sys, json; from imu_emulator.cli import main; "
                f"main(['stream', {str(scene)!r}, '--format', 'mavlink-highres', '--to', "
                f"{'file:' + str(tmp_path / name)!r}, '--speed', '0', '--duration', '0.5', '--quiet']); "
                "print(json.dumps('numba' in sys.modules))")
    assert _run(stream_to("cold.bin"), tmp_path / "cache") is True       # first run: compiles
    assert _run(stream_to("warm.bin"), tmp_path / "cache") is False      # warm: machine code only
    assert _run(stream_to("numba.bin"), tmp_path / "cache", native=False) is True
    warm = (tmp_path / "warm.bin").read_bytes()
    assert len(warm) > 0 and warm == (tmp_path / "numba.bin").read_bytes() == (tmp_path / "cold.bin").read_bytes()


@numba.njit(cache=False)
def _scaled_sum(values, k, x):
    """Writes its array in place and returns what it read: a tuple of an int64 and a float64."""
    values[0] += k * x
    return k, values.sum()


@pytest.mark.parametrize("case", ["plain", "numpy_scalars", "negative_two_digit_int", "int_beyond_two_digits",
                                  "int_for_float", "not_contiguous", "other_dtype",
                                  "equal_dtype_another_object", "byte_swapped"])
def test_entry_reads_arguments_in_place_or_converts_them(tmp_path, monkeypatch, case):
    """The entry reads the argument tuple in place (numpy's array struct, scalars' values) and refuses what it was
    not compiled for, which the caller converts: either way the numbers are numba's dispatcher's (the oracle, run
    on a copy of the same arguments)."""
    compiled_for = (np.zeros((2, 3)), 5, 2.0)
    path = tmp_path / "f.o"
    assert objects.export(_scaled_sum, compiled_for, path, {}, "f.o")
    function = objects.load(path, "f.o")[0]
    base = np.arange(12.0).reshape(4, 3)
    args = {"plain": (base[:2].copy(), 7, 0.5), "numpy_scalars": (base[:2].copy(), np.int64(-3), np.float64(1.25)),
            "negative_two_digit_int": (base[:2].copy(), -(2**40 + 9), 1.0),
            "int_beyond_two_digits": (base[:2].copy(), 2**62 + 1, 1.0),
            "int_for_float": (base[:2].copy(), 2, 3),
            "not_contiguous": (base[::2], 3, 1.5), "other_dtype": (base[:2].astype(np.float32), 4, 0.25),
            # a dtype equal to float64 but another object (as arrays from other libraries carry)
            "equal_dtype_another_object": (base[:2].copy().view(np.dtype("=f8", metadata={"unit": "m"})), 2, 0.5),
            "byte_swapped": (base[:2].astype(">f8"), 2, 0.5)}[case]
    oracle_args = (np.array(args[0], dtype=np.float64), np.int64(args[1]), float(args[2]))
    expected = _scaled_sum(*oracle_args)
    got = function(*args)
    assert got == expected and type(got[0]) is int and type(got[1]) is float
    assert np.array_equal(args[0], oracle_args[0].astype(args[0].dtype))      # written back in place
    if case == "not_contiguous":
        assert np.array_equal(base[1], [3.0, 4.0, 5.0])                       # rows between untouched


@numba.njit(cache=False)
def _picked(sources, which, out):
    """Reads and writes arrays picked from a tuple by index, as the wire encoders' source tuples are read."""
    total = 0.0
    for i in range(out.shape[0]):
        source = sources[which[i]]
        out[i] = source[i % source.shape[0], source.shape[1] - 1] * 2.0
        source[0, 0] += 1.0
        total += out[i]
    return total, which.shape[0]


@pytest.mark.parametrize("case", ["plain", "element_not_contiguous", "element_of_another_dtype", "list_for_tuple",
                                  "shorter_tuple"])
def test_tuple_of_arrays_is_passed_or_converted_as_numba_would(tmp_path, monkeypatch, case):
    """A tuple of arrays (numba's UniTuple) is read in place element by element; a tuple the code was not compiled
    for is refused by the entry, and converted if it can be (written back in place): the numbers and the written
    arrays are numba's dispatcher's (the oracle, run on copies)."""
    compiled_for = ((np.zeros((3, 2)), np.zeros((1, 2)), np.zeros((4, 1))), np.zeros(5, dtype=np.int64), np.zeros(5))
    path = tmp_path / "picked.o"
    assert objects.export(_picked, compiled_for, path, {}, "picked.o")
    function = objects.load(path, "picked.o")[0]
    which = np.array([0, 1, 2, 0, 2], dtype=np.int64)
    wide = np.zeros((4, 3))
    wide[:, 1] = [7.0, 8.0, 9.0, 10.0]
    plain = (np.arange(6.0).reshape(3, 2), np.ones((1, 3)), np.full((4, 1), 7.0))
    sources = {"plain": plain, "element_not_contiguous": plain[:2] + (wide[:, 1:2],),
               "element_of_another_dtype": plain[:2] + (np.full((4, 1), 7, dtype=np.int32),),
               "list_for_tuple": list(plain), "shorter_tuple": plain[:2]}[case]
    oracle_sources = tuple(np.array(s, dtype=np.float64) for s in sources)
    oracle_out, out = np.zeros(5), np.zeros(5)
    accepted = function.call_checked((sources, which, out)) is not objects.REFUSED
    assert accepted == (case == "plain")
    if case in ("list_for_tuple", "shorter_tuple"):
        with pytest.raises(TypeError):
            function(sources, which, out)
        return
    if accepted:      # run once more from the same state for the comparison
        sources, out = tuple(s.copy() for s in oracle_sources), np.zeros(5)
    expected = _picked(oracle_sources, which, oracle_out)
    got = function(sources, which, out)
    assert got == expected and np.array_equal(out, oracle_out)
    for source, oracle in zip(sources, oracle_sources):        # each array written back in place
        assert np.array_equal(source, oracle.astype(source.dtype))
    if case == "element_not_contiguous":
        assert np.array_equal(wide[:, 1], oracle_sources[2][:, 0]) and not wide[:, 0].any()


def test_warm_stream_of_every_format_imports_no_numba(tmp_path):
    """Every wire format's encoder (and device) runs as machine code on a warm run: a process streaming each
    format once imports no numba, and writes what the process that filled the cache wrote. The cache is the
    suite's own (the encoders' tests have filled most of it); the kernel and the encoders' bytes against numba's
    dispatcher are checked above and by each format's oracle tests."""
    scene = ROOT / "examples" / "circle.toml"

    def stream_all(folder: Path) -> str:
        return ("import sys, json; from imu_emulator.cli import main; import firmware_protocols as fp\n"
                "for name, info in sorted(fp.formats().items()):\n"
                f"    path = {str(folder)!r} + '/' + name + ('.log' if info.kind == 'can' else '.bin')\n"
                f"    main(['stream', {str(scene)!r}, '--format', name, '--to', 'file:' + path, '--count', '3',"
                "'--speed', '0', '--quiet'])\n"
                "print(json.dumps('numba' in sys.modules))")
    env_cache = os.environ.get("IMU_EMULATOR_CACHE")
    cache = Path(env_cache) if env_cache else Path.home() / ".cache" / "imu-emulator"
    (tmp_path / "first").mkdir()
    (tmp_path / "warm").mkdir()
    _run(stream_all(tmp_path / "first"), cache)
    assert _run(stream_all(tmp_path / "warm"), cache) is False
    first = sorted(p.name for p in (tmp_path / "first").iterdir())
    assert len(first) >= 16 and first == sorted(p.name for p in (tmp_path / "warm").iterdir())
    for name in first:
        written = (tmp_path / "warm" / name).read_bytes()
        assert written and written == (tmp_path / "first" / name).read_bytes(), name
