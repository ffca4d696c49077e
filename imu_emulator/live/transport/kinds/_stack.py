"""What the flight-stack targets (px4, ardupilot-json) share in their specs: `[HOST:]PORT[,record=PATH][,timeout=S]`."""
from __future__ import annotations

import math

from imu_emulator.errors import TargetError
from imu_emulator.live.transport.spec import TargetKind, TargetSpec

PARAMS = ("record", "timeout")


def parse_stack_spec(kind: str, syntax: str, text: str, rest: str, default_port: int) -> TargetSpec:
    """A malformed spec, an unknown or repeated parameter, a timeout that is not a positive number: a
    TargetError naming the syntax."""
    address, *extra = rest.split(",")
    params = {}
    for item in extra:
        key, sep, value = item.partition("=")
        if not sep or key not in PARAMS or not value:
            raise TargetError(f"{text}: {item!r} is not one of record=PATH, timeout=SECONDS (expected {syntax})")
        if key in params:
            raise TargetError(f"{text}: {key}= given twice")
        if key == "timeout":
            try:
                seconds = float(value)
            except ValueError:
                seconds = math.nan
            if not math.isfinite(seconds) or seconds <= 0:
                raise TargetError(f"{text}: timeout= expects a positive number of seconds, got {value!r}")
        params[key] = value
    host, sep, port = address.rpartition(":")
    if not sep:
        host, port = "127.0.0.1", address or str(default_port)
    host = host.strip("[]") or "127.0.0.1"
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise TargetError(f"{text}: expected {syntax} with a port between 1 and 65535")
    return TargetSpec(kind, text, path=host, port=int(port), params=tuple(sorted(params.items())))


def stack_kind(name: str, order: int, default_port: int, help: str, transport) -> TargetKind:
    """The TargetKind of a flight-stack target `name:[HOST:]PORT[,record=PATH][,timeout=S]`; `transport()` gives
    its Transport class (imported when a target is opened, not when the kinds are listed)."""
    syntax = f"{name}:[HOST:]PORT[,record=PATH][,timeout=S]"

    def parse(text: str, rest: str) -> TargetSpec:
        return parse_stack_spec(name, syntax, text, rest, default_port)

    def open_(spec: TargetSpec, format_kind: str, options):
        return transport()(spec, options)

    return TargetKind(name=name, order=order, syntax=syntax, help=help, carries="serial", parse=parse, open=open_,
                      takes_argument=False)
