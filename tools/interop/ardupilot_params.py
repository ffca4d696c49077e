"""The ArduPilot parameters that put an emulated external AHRS (or the JSON physics backend) into Copter SITL, and
the defaults file SITL reads them from (`arducopter --defaults A,B`: later files override earlier ones).

Sources, ArduPilot commit 265753db8b (master of 2025-07-21):
- Tools/autotest/arduplane.py `fly_external_AHRS` (the project's own SITL test of these drivers): EAHRS_TYPE,
  SERIAL4_PROTOCOL 36 (AHRS), SERIAL4_BAUD 230400, GPS1_TYPE 21 (the AHRS's GNSS), AHRS_EKF_TYPE 11 (the AHRS's
  own solution), INS_GYR_CAL 1; EAHRS_TYPE values in libraries/AP_ExternalAHRS/AP_ExternalAHRS.cpp (1 VectorNav,
  7 MicroStrain7; EAHRS_SENSORS defaults to 0xF: GPS, IMU, baro, compass all from the unit).
- The device sits on SERIAL4 as in that test (SITL's SERIAL3 carries its simulated GPS).
- The scene's motion is scripted, not flown: once armed the copter must neither disarm itself on the ground
  (DISARM_DELAY 0, ArduCopter/motors.cpp auto_disarm_check) nor declare a crash when its attitude does not follow
  its demands (FS_CRASH_CHECK 0, ArduCopter/crash_check.cpp).
"""
from __future__ import annotations

import math
import re
from pathlib import Path

#: the SITL serial port the emulated unit is attached to (--serial4=uart:PTY:BAUD)
SERIAL_PORT = 4
BAUD = 230400

#: device name -> (what it is, emulator --format, emulator --option values, EAHRS_TYPE)
DEVICES = {
    "vn300": ("VectorNav VN-300 (ArduPilot configures it)", "vectornav-binary", ["model=VN-300-CR"], 1),
    "gq7": ("MicroStrain 3DM-GQ7 (streams from power-on)", "microstrain-mip", ["preset=ardupilot"], 7),
}

_NAME = re.compile(r"[A-Z][A-Z0-9_]{0,15}")


#: EAHRS_SENSORS bits (libraries/AP_ExternalAHRS/AP_ExternalAHRS.h AvailableSensor, 265753db8b): which of the
#: unit's sensors ArduPilot registers as its own; the attitude and position (AHRS_EKF_TYPE 11) come from the unit
#: whatever they are
SENSOR_BITS = {"gps": 1, "imu": 2, "baro": 4, "compass": 8}


def sensors_mask(names: str) -> int:
    """EAHRS_SENSORS from a comma-separated list of SENSOR_BITS names ("all": every one)."""
    if names == "all":
        return sum(SENSOR_BITS.values())
    mask = 0
    for name in filter(None, (n.strip() for n in names.split(","))):
        if name not in SENSOR_BITS:
            raise ValueError(f"sensor {name!r}: not one of {', '.join(SENSOR_BITS)} (or all)")
        mask |= SENSOR_BITS[name]
    return mask


def device_params(device: str, serial_port: int = SERIAL_PORT, sensors: str = "all") -> dict[str, float]:
    """The parameters selecting `device` (a key of DEVICES, or "json") on SERIAL<serial_port>, with the unit's
    `sensors` (sensors_mask) registered in ArduPilot."""
    common = {"DISARM_DELAY": 0, "FS_CRASH_CHECK": 0}
    if device == "json":
        return common            # SITL's own EKF3 on the emulator's IMU, GPS from the JSON position
    if device not in DEVICES:
        raise ValueError(f"device {device!r}: not one of {', '.join(sorted(DEVICES) + ['json'])}")
    return {**common,
            "EAHRS_TYPE": DEVICES[device][3],
            f"SERIAL{serial_port}_PROTOCOL": 36,
            f"SERIAL{serial_port}_BAUD": BAUD,
            "GPS1_TYPE": 21,
            "AHRS_EKF_TYPE": 11,
            "INS_GYR_CAL": 1,
            "EAHRS_SENSORS": sensors_mask(sensors)}


def param_text(params: dict[str, float]) -> str:
    """A defaults file: one `NAME VALUE` line each (AP_Param::parse_param_line splits a line at ", =\\t", names of
    at most AP_MAX_NAME_SIZE = 16 characters; `--defaults A,B` loads several, split at commas). Names are checked,
    values must be finite: a line SITL cannot read would be skipped without a word."""
    lines = []
    for name, value in params.items():
        if not _NAME.fullmatch(name):
            raise ValueError(f"parameter name {name!r}: not an ArduPilot parameter name")
        if not math.isfinite(float(value)):
            raise ValueError(f"parameter {name}: value {value!r} is not finite")
        lines.append(f"{name} {float(value):.9g}")
    return "\n".join(lines) + "\n"


def write_params(path: Path, params: dict[str, float]) -> Path:
    from imu_emulator.output.atomic import write_text
    write_text(path, param_text(params))
    return Path(path)
