"""One table naming every wire format, so the CLI can list them and the streaming code can compute
link budgets without knowing any format's details.

Each module of firmware_protocols.wire_formats calls `register(FormatInfo(...))` at import, then each module of
firmware_protocols.devices attaches its device to its formats (`attach_device`). `_load_all` finds and imports
them once, on the first question: the lists are found, not kept, so a module dropped into either folder is picked
up and one that fails to import is an error naming it.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

from imu_emulator import extensions     # the one scan every extension point uses (a leaf)

# Scanned in this order (devices attach to formats already registered). In each, modules whose names start with
# "_" and `base` (the package's interface) are helpers, not formats or devices.
_PACKAGES = ("firmware_protocols.wire_formats", "firmware_protocols.devices")
_NOT_SCANNED = ("base",)


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
    # device(rate_hz, **options) -> firmware_protocols.devices.base.Device: the part that answers a driver's
    # commands and decides what the link carries; None for formats whose real parts only talk.
    device: Callable | None = None
    device_options: dict = field(default_factory=dict)   # options only the device takes -> one-line help
    device_class: type | None = None     # the device's class: its __init__ gives the device options' defaults
    # Named option sets for drivers that expect one exact packet: preset name -> (options, one-line help).
    presets: dict = field(default_factory=dict)
    # The device reports navigation (position, velocity, linear acceleration): the streamer then computes truth.
    device_navigation: bool = False


_REGISTRY: dict[str, FormatInfo] = {}
_loaded = False


def register(info: FormatInfo) -> FormatInfo:
    if info.name in _REGISTRY:
        raise ValueError(f"format {info.name!r} registered twice")
    _REGISTRY[info.name] = info
    return info


def attach_device(name: str, device: Callable, device_options: dict | None = None, presets: dict | None = None,
                  navigation: bool = False, device_class: type | None = None) -> None:
    """Give the registered format `name` a device (and its device-only options, presets, and the class `device`
    builds, whose signature `formats --details` reads the options' defaults from)."""
    info = _REGISTRY[name]
    _REGISTRY[name] = replace(info, device=device, device_options=dict(device_options or {}),
                              presets=dict(presets or {}), device_navigation=navigation, device_class=device_class)


def _load_all() -> None:
    global _loaded
    if not _loaded:
        for package in _PACKAGES:
            extensions.modules(package, skip=_NOT_SCANNED)
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


def create_device(name: str, rate_hz: float, **options):
    """The format's device at the given sample rate; ValueError when the format has none."""
    info = get(name)
    if info.device is None:
        raise ValueError(f"format {name!r} has no device (its real parts only talk)")
    return info.device(rate_hz, **options)


def option_defaults(info: FormatInfo) -> dict:
    """Every keyword the format's encoder factory accepts, with its default, read from the signature (so a
    listing built from it cannot drift from the code). Follows `**options` into base classes' __init__;
    parameters bound by the registry (functools.partial, names starting with '_') are not options."""
    return signature_defaults(info.encoder)


def device_option_defaults(info: FormatInfo) -> dict:
    """Every keyword the format's device class accepts, with its default (as option_defaults; {} without a
    declared device class)."""
    return {} if info.device_class is None else signature_defaults(info.device_class)


def signature_defaults(factory) -> dict:
    """The keywords `factory` (a class, function or functools.partial) accepts with their defaults."""
    import inspect
    defaults: dict = {}
    target, bound_self = factory, False
    while target is not None:
        parameters = list(inspect.signature(target).parameters.items())[int(bound_self):]
        follow = None
        for name, parameter in parameters:
            if parameter.kind is parameter.VAR_KEYWORD:
                follow = _next_init(target)
            elif parameter.kind is not parameter.VAR_POSITIONAL and not name.startswith("_"):
                defaults.setdefault(name, parameter.default)
        target, bound_self = follow, True
    return defaults


def _next_init(target):
    """The base class __init__ that a subclass's `**options` are passed on to."""
    cls = target if isinstance(target, type) else getattr(target, "__self__", None)
    for base in (cls.__mro__[1:] if isinstance(cls, type) else ()):
        if "__init__" in vars(base) and base is not object:
            return base.__init__
    return None
