"""Where samples go. A target spec names the link, `KIND:REST` (`imu-emulator targets` lists them): each kind
declares its syntax, what it carries, how its spec parses, its link's capacity and how to open it in a module of
kinds/ (see spec.TargetKind), and its transport lives in a module here, imported only when opened. This module
finds the kinds, parses specs and opens the right one.
"""
from __future__ import annotations

from imu_emulator import extensions
from imu_emulator.errors import TargetError
from imu_emulator.live.transport import kinds
from imu_emulator.live.transport.base import LinkCapacity, TargetOptions, Transport
from imu_emulator.live.transport.spec import TargetKind, TargetSpec


def find_kinds(package) -> dict[str, TargetKind]:
    """name -> declaration of every module of `package` not starting with "_", in their declared order. The list
    is found, not kept; a module that fails to import, or declares no KIND of its own name, is an error naming it."""
    found = extensions.declared(package, "KIND", TargetKind)
    found.sort(key=lambda k: (k.order, k.name))
    return {k.name: k for k in found}


#: kind -> its declaration, in the order `imu-emulator targets` lists them
TARGET_KINDS: dict[str, TargetKind] = find_kinds(kinds)


def parse_target(text: str) -> TargetSpec:
    """Parse a target spec; malformed specs raise TargetError naming the expected syntax."""
    if not isinstance(text, str) or not text:
        raise TargetError("target: empty spec (expected one of: "
                          + ", ".join(kind.syntax for kind in TARGET_KINDS.values()) + ")")
    name, _, rest = text.partition(":")
    if name not in TARGET_KINDS:
        raise TargetError(f"{text}: unknown target kind {name!r} (known: {', '.join(TARGET_KINDS)})")
    kind = TARGET_KINDS[name]
    if kind.takes_argument and not rest:
        raise TargetError(f"{text}: expected {kind.syntax}")
    return kind.parse(text, rest)


def check_carries(spec: TargetSpec, format_kind: str) -> None:
    """Refuse a format the target cannot carry (CAN frames to a pty, bytes to a CAN bus)."""
    kind = TARGET_KINDS[spec.kind]
    if kind.carries not in ("any", format_kind):
        raise TargetError(f"{spec.text}: a {spec.kind} target carries {kind.carries} formats, "
                          f"not {format_kind} formats{kind.refusal_hint}")


def link_capacity(spec: TargetSpec, format_kind: str, options: TargetOptions = TargetOptions()) -> LinkCapacity:
    """The capacity the link budget is checked against, known from the spec alone (so an impossible
    stream is refused before any device is opened). A pty or UDP has none unless --pace-baud asks;
    a CAN target is held to its bit rate even when virtual, as the real bus would be."""
    return TARGET_KINDS[spec.kind].capacity(spec, format_kind, options)


def open_target(spec: TargetSpec, format_kind: str, options: TargetOptions = TargetOptions()) -> Transport:
    """Open a parsed target for a format of kind "serial" or "can". The kind's transport module is imported
    now; one that fails to import is an error naming the kind's module."""
    check_carries(spec, format_kind)
    kind = TARGET_KINDS[spec.kind]
    try:
        return kind.open(spec, format_kind, options)
    except ImportError as exc:
        raise ImportError(f"target kind {spec.kind!r} ({kind.open.__module__}) cannot import its transport: "
                          f"{exc}") from exc


__all__ = ["TARGET_KINDS", "LinkCapacity", "TargetKind", "TargetOptions", "TargetSpec", "Transport", "check_carries",
           "find_kinds", "link_capacity", "open_target", "parse_target"]
