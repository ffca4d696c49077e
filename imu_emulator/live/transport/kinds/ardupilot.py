"""ardupilot:[HOST:]PORT: ArduPilot SITL's JSON physics backend (SIM_JSON), UDP."""
from __future__ import annotations

from imu_emulator.live.transport.kinds._stack import stack_kind

DEFAULT_PORT = 9002     # SIM_JSON's control_port


def _transport():
    from imu_emulator.live.transport.ardupilot_sitl import ArduPilotJsonTransport
    return ArduPilotJsonTransport


KIND = stack_kind("ardupilot", 7, DEFAULT_PORT, transport=_transport,
                  help=f"ArduPilot SITL's JSON backend: UDP port {DEFAULT_PORT}, one reply (format ardupilot-json) "
                       "per servo packet, servo outputs recorded; lockstep with --speed 0")
