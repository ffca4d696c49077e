"""px4:[HOST:]PORT: PX4 SITL's simulator interface (simulator_mavlink), a TCP server the stack connects to."""
from __future__ import annotations

from imu_emulator.live.transport.base import TargetOptions, Transport
from imu_emulator.live.transport.kinds._stack import parse_stack_spec
from imu_emulator.live.transport.spec import TargetKind, TargetSpec

DEFAULT_PORT = 4560     # simulator_mavlink's default (PX4_SIM_PORT / -p)


def _parse(text: str, rest: str) -> TargetSpec:
    return parse_stack_spec("px4", KIND.syntax, text, rest, DEFAULT_PORT)


def _open(spec: TargetSpec, format_kind: str, options: TargetOptions) -> Transport:
    from imu_emulator.live.transport.px4_sim import Px4SimTransport
    return Px4SimTransport(spec, options)


KIND = TargetKind(name="px4", order=6, syntax="px4:[HOST:]PORT[,record=PATH][,timeout=S]",
                  help=f"PX4 SITL's simulator interface: TCP server (port {DEFAULT_PORT}) the stack connects to; "
                       "HIL_SENSOR/HIL_GPS out, HIL_ACTUATOR_CONTROLS recorded; lockstep with --speed 0",
                  carries="serial", parse=_parse, open=_open, takes_argument=False)
