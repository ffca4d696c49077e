"""px4:[HOST:]PORT: PX4 SITL's simulator interface (simulator_mavlink), a TCP server the stack connects to."""
from __future__ import annotations

from imu_emulator.live.transport.kinds._stack import stack_kind

DEFAULT_PORT = 4560     # simulator_mavlink's default (PX4_SIM_PORT / -p)


def _transport():
    from imu_emulator.live.transport.px4_sim import Px4SimTransport
    return Px4SimTransport


KIND = stack_kind("px4", 6, DEFAULT_PORT, transport=_transport,
                  help=f"PX4 SITL's simulator interface: TCP server (port {DEFAULT_PORT}) the stack connects to; "
                       "HIL_SENSOR/HIL_GPS out, HIL_ACTUATOR_CONTROLS recorded; lockstep with --speed 0")
