"""Counter-based standard normals for the kernel: normal(key, counter) is a pure function.

Any sample of any stream can be computed on its own, so a block's noise depends only on (seed, IMU, stream,
sample index) and never on how the run was cut into blocks, on the process, or on other effects.

- 64 random bits = SplitMix64's output function applied to key + (counter + 1) * golden gamma (Steele, Lea,
  Flood, OOPSLA 2014: the sequence of a key is SplitMix64's own stream, which passes BigCrush).
- A standard normal from them by the 256-layer ziggurat (Marsaglia & Tsang 2000, in the 64-bit form numpy's
  Generator uses): one table lookup and one compare in 99 % of draws. The rare wedge and tail draws take further
  bits from mix(z + i * odd constant), still a pure function of (key, counter).

Stream keys come from `stream_key(seed, imu, name)`: a hash of the stream's name, so turning one effect on does
not change another effect's noise, and each IMU has its own streams.
"""
from __future__ import annotations

import hashlib
import math

from imu_emulator.native.lazy import jit
import numpy as np

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_EXTRA = np.uint64(0xD1B54A32D192ED03)
_S30, _S27, _S31 = np.uint64(30), np.uint64(27), np.uint64(31)
_S8, _S9, _S11, _S1 = np.uint64(8), np.uint64(9), np.uint64(11), np.uint64(1)
_LOW8 = np.uint64(0xFF)
_LOW52 = np.uint64(0x000FFFFFFFFFFFFF)
_ONE = np.uint64(1)

# --- ziggurat tables (256 layers of equal area under exp(-x^2/2)) ------------------------------------------
_LAYERS = 256
_R = 3.6541528853610088          # right edge of the base layer (Marsaglia & Tsang, 256 layers)
_V = 0.00492867323399            # area of each layer


def _tables():
    """Layer 0 is the base (rectangle up to R plus the tail, virtual width V / f(R)); layers 1..255 have right
    edges x_1 < ... < x_255 = R, layer 1 at the top. Layer i is safe (under the curve) up to x_{i-1} (x_0 = 0);
    fi[i] = f(x_i) and fi[0] = f(0) = 1 bound the wedge test of layer i by fi[i-1] and fi[i]."""
    f = lambda x: math.exp(-0.5 * x * x)  # noqa: E731
    edge = np.zeros(_LAYERS)
    edge[_LAYERS - 1] = _R
    for i in range(_LAYERS - 1, 1, -1):
        edge[i - 1] = math.sqrt(-2.0 * math.log(_V / edge[i] + f(edge[i])))
    base = _V / f(_R)
    scale = 2.0 ** 52
    ki = np.empty(_LAYERS, np.uint64)
    wi = np.empty(_LAYERS)
    fi = np.empty(_LAYERS)
    ki[0], wi[0], fi[0] = np.uint64(int(_R / base * scale)), base / scale, 1.0
    for i in range(1, _LAYERS):
        wi[i] = edge[i] / scale
        ki[i] = np.uint64(int(edge[i - 1] / edge[i] * scale))
        fi[i] = f(edge[i])
    return ki, wi, fi, edge


KI, WI, FI, _X = _tables()
_INV_R = 1.0 / _R


@jit
def mix64(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@jit
def _unit(z, i):
    """A double in [0, 1) from the i-th extra draw of state z."""
    return float(mix64(z + np.uint64(i) * _EXTRA) >> _S11) * (1.0 / 9007199254740992.0)


@jit
def _slow_path(z, idx, rabs, x):
    """The 1 % of draws outside a layer's safe rectangle: wedge test, tail, or a fresh draw."""
    i = 1
    while True:
        if idx == 0:   # tail beyond R (Marsaglia 1964)
            while True:
                xx = -_INV_R * math.log1p(-_unit(z, i))
                yy = -math.log1p(-_unit(z, i + 1))
                i += 2
                if yy + yy > xx * xx:
                    return -(_R + xx) if ((rabs >> _S8) & _S1) else _R + xx
        if (FI[idx - 1] - FI[idx]) * _unit(z, i) + FI[idx] < math.exp(-0.5 * x * x):
            return x
        # rejected: the ziggurat takes the next number
        r = mix64(z + np.uint64(i + 1) * _EXTRA)
        i += 2
        idx = int(r & _LOW8)
        r = r >> _S8
        rabs = (r >> _S1) & _LOW52
        x = float(rabs) * WI[idx]
        if r & _S1:
            x = -x
        if rabs < KI[idx]:
            return x


@jit
def normal(key, counter):
    """The standard normal number `counter` of stream `key` (both uint64-compatible integers)."""
    z = key + (np.uint64(counter) + _ONE) * _GAMMA
    r = mix64(z)
    idx = int(r & _LOW8)
    r = r >> _S8
    sign = r & _S1
    rabs = (r >> _S1) & _LOW52
    x = float(rabs) * WI[idx]
    if sign:
        x = -x
    if rabs < KI[idx]:
        return x
    return _slow_path(z, idx, rabs, x)


@jit(cache=True)   # every new process draws initial states: compiling it cost each batch worker seconds
def _normals_into(key, first, out):
    for i in range(out.shape[0]):
        out[i] = normal(key, first + i)


def normals(key, first, n):
    """n consecutive normals of one stream (tests, initial state draws). Allocated here, filled by machine code
    that returns nothing (imu_emulator.native.lazy passes no arrays back)."""
    out = np.empty(int(n))
    _normals_into(np.uint64(key), np.int64(first), out)
    return out


def stream_key(seed: int, imu: int, name: str) -> int:
    """The 64-bit key of a named random stream of one IMU under a seed."""
    digest = hashlib.sha256(f"{int(seed)}/{int(imu)}/{name}".encode()).digest()
    return int.from_bytes(digest[:8], "little")
