"""What every output file states about its numbers: the frames they are in and their units, in lines a reader
can show (CSV '#' lines, NPZ "conventions", Parquet's footer and fields' metadata, MCAP's metadata record).

Scenes on the Earth with truth state the Earth truth's conventions (imu_emulator.motion.earth_truth.conventions);
other scenes state their frame here from the scene's frame name. Either way a "units:" line follows, from the
column schema (imu_emulator.output.columns). A writer not told the frame (a caller that passes none) states the
units only.
"""
from __future__ import annotations

from imu_emulator.output.base import Contents
from imu_emulator.output.columns import described

_WHERE = {"ENU": "ENU (x east, y north, z up)", "NED": "NED (x north, y east, z down)",
          "ECEF": "WGS-84 ECEF", "ECI": "ECI (axes on ECEF's at t = 0 s, turning at omega_ie about z)"}


def frame_lines(frame: str | None) -> list[str]:
    """A scene's frames in the words of the Earth conventions (the "frame:" line names the frame: `plot` reads
    it)."""
    if frame not in _WHERE:
        return []
    body = "forward-left-up" if frame == "ENU" else "forward-right-down"
    return [f"frame: trajectory px py pz, vx vy vz in {_WHERE[frame]}",
            f"attitude: roll pitch yaw z-y-x, body {body} -> navigation; quaternions scalar first, "
            "body (or sensor) -> navigation",
            f"sensor axes: each IMU's sensor frame is the {body} body turned by its mounting_rpy_deg",
            "accelerometers: specific force f = a - g (+g up at rest: ENU z = +g, NED z = -g)"]


def units_line(contents: Contents) -> str:
    return "units: " + ", ".join(f"{c.name} [{c.unit}]" if c.unit else c.name for c in described(contents.layout))


def statement(contents: Contents) -> list[str]:
    """The lines a file of these contents states."""
    lines = list(contents.conventions) if contents.conventions else frame_lines(contents.frame)
    return lines + [units_line(contents)]
