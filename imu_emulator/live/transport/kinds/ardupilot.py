"""ardupilot:[HOST:]PORT: ArduPilot SITL's JSON physics backend (SIM_JSON), UDP."""
from __future__ import annotations

from imu_emulator.live.transport.base import TargetOptions, Transport
from imu_emulator.live.transport.kinds._stack import parse_stack_spec
from imu_emulator.live.transport.spec import TargetKind, TargetSpec

DEFAULT_PORT = 9002     # SIM_JSON's control_port


def _parse(text: str, rest: str) -> TargetSpec:
    return parse_stack_spec("ardupilot", KIND.syntax, text, rest, DEFAULT_PORT)


def _open(spec: TargetSpec, format_kind: str, options: TargetOptions) -> Transport:
    from imu_emulator.live.transport.ardupilot_sitl import ArduPilotJsonTransport
    return ArduPilotJsonTransport(spec, options)


KIND = TargetKind(name="ardupilot", order=7, syntax="ardupilot:[HOST:]PORT[,record=PATH][,timeout=S]",
                  help=f"ArduPilot SITL's JSON backend: UDP port {DEFAULT_PORT}, one reply (format ardupilot-json) "
                       "per servo packet, servo outputs recorded; lockstep with --speed 0",
                  carries="serial", parse=_parse, open=_open, takes_argument=False)
