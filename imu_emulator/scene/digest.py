"""A validated scene as an exact, JSON-able description (`canonical`) and its digest: what output files record
as the scene they came from, and what the kernel cache key (imu_emulator.runtime.cache) hashes."""
from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np

from imu_emulator.scene.model import Scene

#: Scene fields the description leaves out: none of them shapes the kernel's source, so the cache key leaves them
#: out too (streams are the stream command's, path and warnings are messages, the seed arrives at run time as
#: stream keys); output files record the seed and path beside the digest.
KEY_EXCLUDES = ("streams", "path", "warnings", "seed")


def canonical(value):
    """A JSON-able, exact description of a validated value (floats as hex so no bit is lost)."""
    if dataclasses.is_dataclass(value):
        return {"type": type(value).__name__,
                **{f.name: canonical(getattr(value, f.name)) for f in dataclasses.fields(value)
                   if not (type(value) is Scene and f.name in KEY_EXCLUDES)}}
    if isinstance(value, np.ndarray):
        return {"array": str(value.dtype), "shape": value.shape, "sha256": hashlib.sha256(
            np.ascontiguousarray(value).tobytes()).hexdigest()}
    if isinstance(value, float):
        return value.hex()
    if isinstance(value, (str, int, bool)) or value is None:
        return value
    if isinstance(value, (frozenset, set)):
        return sorted(canonical(v) for v in value)
    if isinstance(value, (list, tuple)):
        return [canonical(v) for v in value]
    if isinstance(value, dict) or hasattr(value, "items"):
        return {str(k): canonical(v) for k, v in sorted(value.items())}
    raise TypeError(f"cannot key a {type(value).__name__}")


def scene_digest(scene: Scene) -> str:
    """The validated scene (less KEY_EXCLUDES: no seed, path or streams) hashed alone, without the generator's
    code: what output files record as the scene they came from."""
    return hashlib.sha256(json.dumps(canonical(scene), sort_keys=True).encode()).hexdigest()
