"""One table naming every wire format, so the CLI can list them and the streaming code can compute
link budgets without knowing any format's details.

Each format module calls `register(FormatInfo(...))` at import; `_load_all` imports them once.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Callable

_MODULES = ("mavlink", "vectornav", "xsens", "microstrain", "dronecan", "j1939", "bosch")


@dataclass(frozen=True)
class FormatInfo:
    name: str                      # e.g. "mavlink-highres"
    kind: str                      # "serial" or "can"
    description: str
    encoder: Callable              # encoder(**options) -> object with .encode(Samples)
    decoder: Callable              # decoder(**options) -> stream decoder
    # serial: bytes per sample with default options; CAN: list of (payload length, extended, fd)
    # per sample. Encoders whose size depends on options expose the same via .bytes_per_sample /
    # .frames_per_sample, which is what link budgets should use.
    bytes_per_sample: int = 0
    frames_per_sample: tuple = field(default_factory=tuple)
    options: dict = field(default_factory=dict)   # option name -> one-line help


_REGISTRY: dict[str, FormatInfo] = {}
_loaded = False


def register(info: FormatInfo) -> FormatInfo:
    if info.name in _REGISTRY:
        raise ValueError(f"format {info.name!r} registered twice")
    _REGISTRY[info.name] = info
    return info


def _load_all() -> None:
    global _loaded
    if not _loaded:
        for module in _MODULES:
            try:
                importlib.import_module(f"firmware_protocols.{module}")
            except ModuleNotFoundError as exc:
                if exc.name != f"firmware_protocols.{module}":
                    raise
        _loaded = True


def formats() -> dict[str, FormatInfo]:
    _load_all()
    return dict(sorted(_REGISTRY.items()))


def get(name: str) -> FormatInfo:
    known = formats()
    if name not in known:
        raise KeyError(f"unknown format {name!r}; known: {', '.join(known)}")
    return known[name]


def create_encoder(name: str, **options):
    return get(name).encoder(**options)


def create_decoder(name: str, **options):
    return get(name).decoder(**options)
