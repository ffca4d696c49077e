"""Body axes and reference frames at the wire: each format declares them, and the one conversion at its edge.

`Samples` carries vectors in the part's own forward-right-down (FRD) axes, as it sits upright facing forward, and
attitude FRD -> NED (base.Samples). Every encoder class declares, from its vendor's manual or its message
definition (cited beside the declaration):

    body_axes   the axes its sensor vectors (accel, gyro, mag, increments) are written in: one of BODY_AXES
    reference   the frame its attitude and navigation fields refer to ("NED", "ENU", ...), None when it has none

A format whose body axes are not FRD calls `to_body_axes` once, on entry to `encode`; nothing else in it knows.
`declarations()` gathers the table (`imu-emulator formats --details` prints it; docs/concepts.md, "At the wire").
"""
from __future__ import annotations

import copy
import functools

import numpy as np

from firmware_protocols import attitude
from firmware_protocols.base import Samples

#: Body axes a format may declare, each as q_FA: the rotation taking vectors in those axes to FRD, and the
#: per-axis signs of that rotation's matrix (both are diagonal: the axes differ by a half turn about x).
#: FLU (forward-left-up) is the habit of ROS REP 103, Xsens' sensor frame and automotive (ISO 8855) parts.
BODY_AXES = {
    "FRD": (np.array([1.0, 0.0, 0.0, 0.0]), np.array([1.0, 1.0, 1.0])),
    "FLU": (np.array([0.0, 1.0, 0.0, 0.0]), np.array([1.0, -1.0, -1.0])),
}

#: Fields holding a vector in body axes (Samples' docstring); everything NED-referenced is left alone.
VECTOR_FIELDS = ("accel", "gyro", "mag", "delta_theta", "delta_velocity")


def reexpress(samples: Samples, source: str, target: str) -> Samples:
    """`samples` whose body vectors are in `source` axes and attitude source -> reference, re-expressed in
    `target` axes: vectors v_T = C_TS v_S, attitude q_RT = q_RS (x) q_ST, the attitude change over each interval
    q_ST* (x) dq (x) q_ST (the same rotation seen from the other axes), euler recomputed from the new attitude.
    The reference side is untouched. Returns `samples` itself when the axes agree."""
    if source not in BODY_AXES or target not in BODY_AXES:
        raise ValueError(f"body axes: {source!r} -> {target!r}; known: {', '.join(BODY_AXES)}")
    if source == target:
        return samples
    signs, quat_index, quat_signs, change_signs = _maps(source, target)
    # + 0.0 turns the -0.0 a negated zero would be into +0.0: a part at rest sends the zero a native one does
    changes = {name: getattr(samples, name) * signs + 0.0 for name in VECTOR_FIELDS
               if getattr(samples, name) is not None}
    quat = samples.quat
    if quat is None and samples.euler is not None:
        quat = attitude.from_euler(samples.euler)
    if quat is not None:
        changes["quat"] = attitude.canonical(quat[:, quat_index] * quat_signs)
        if samples.euler is not None:
            changes["euler"] = attitude.to_euler(changes["quat"])
        if samples.quat is None:          # the caller gave euler alone: keep it that way
            del changes["quat"]
    if samples.attitude_change is not None:
        changes["attitude_change"] = attitude.canonical(samples.attitude_change * change_signs)
    out = copy.copy(samples)           # the fields are checked already: no __post_init__ (dataclasses.replace)
    for name, value in changes.items():
        setattr(out, name, value)
    return out


@functools.lru_cache(maxsize=None)
def _maps(source: str, target: str) -> tuple:
    """What reexpress applies, as index and sign arrays (a few microseconds a call, where the quaternion products
    they stand for cost tens: the live path runs this per block and a device per sample): the vectors' signs
    C_TS; q -> q (x) q_ST as a signed permutation of (w, x, y, z); dq -> q_ST* (x) dq (x) q_ST as signs. Both are
    exact because q_ST is the identity or a half turn about an axis (a basis quaternion), which the matrices,
    computed here from attitude.multiply itself, confirm."""
    (q_fs, signs_s), (q_ft, signs_t) = BODY_AXES[source], BODY_AXES[target]
    q_st = attitude.multiply(attitude.conjugate(q_fs), q_ft)
    basis = np.eye(4)
    right = np.array([attitude.multiply(e, q_st) for e in basis]).T          # column j: e_j (x) q_ST
    change = np.array([attitude.multiply(attitude.multiply(attitude.conjugate(q_st), e), q_st) for e in basis]).T
    index = np.argmax(np.abs(right), axis=1)
    quat_signs = right[np.arange(4), index]
    if not (np.allclose(np.abs(right).sum(axis=1), 1.0) and np.allclose(change, np.diag(np.diag(change)))):
        raise ValueError(f"body axes {source} -> {target}: not a half turn about an axis")
    return signs_s * signs_t, index, quat_signs, np.diag(change).copy()


def to_body_axes(samples: Samples, axes: str) -> Samples:
    """Samples (FRD, the contract) in a format's declared body axes: what its `encode` does first."""
    return reexpress(samples, "FRD", axes)


def declared(encoder_factory) -> tuple[str | None, str | None]:
    """(body_axes, reference) a registered encoder factory declares: the class itself, or the class a
    functools.partial binds. (None, None) when it declares nothing (tests/firmware_protocols/test_formats_contract.py catches that)."""
    cls = getattr(encoder_factory, "func", encoder_factory)
    return getattr(cls, "body_axes", None), getattr(cls, "reference", None)


def declarations() -> dict[str, tuple[str | None, str | None, str]]:
    """format name -> (body axes, reference, the source the declaration was read from): the one table."""
    from firmware_protocols.registry import formats
    out = {}
    for name, info in formats().items():
        cls = getattr(info.encoder, "func", info.encoder)
        out[name] = (*declared(info.encoder), getattr(cls, "axes_source", ""))
    return out
