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
- The unit's sensors are the only ones (sole_sensor_params): SITL's own simulated IMUs, barometers and compasses
  sit on the ground while the unit reports the scripted flight, and ArduPilot's pre-arm checks fail on two IMUs
  that disagree ("Gyros inconsistent", AP_Arming.cpp:497-499).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

#: the SITL serial port the emulated unit is attached to (--serial4=uart:PTY:BAUD)
SERIAL_PORT = 4
BAUD = 230400


@dataclass(frozen=True)
class Device:
    what: str
    format: str                 # emulator --format
    options: tuple              # emulator --option values
    eahrs_type: int             # EAHRS_TYPE (AP_ExternalAHRS.cpp)
    imu_hz: float               # the rate the unit's IMU packets arrive at, as this setup makes it stream
    rate_params: dict           # the parameters that make it stream at imu_hz (none when the unit decides)


def _gq7_imu_hz() -> float:
    """The MIP preset's IMU (0x80) rate: ArduPilot's MicroStrain7 driver sends no command, the unit streams what
    it was set to (firmware_protocols.devices.microstrain PRESETS)."""
    from firmware_protocols.devices.microstrain import PRESETS, SENSOR_DATA_SET
    return PRESETS["ardupilot"][0]["sets"][SENSOR_DATA_SET][1]


#: VN-300 IMU rate: the VectorNav driver writes register 75 with divisor 400 / EAHRS_RATE on a VN-300
#: (AP_ExternalAHRS_VectorNav.cpp:451-459); 100 Hz divides the scene's 200 Hz and keeps the unit's packets well
#: inside 230400 baud
VN300_IMU_HZ = 100

#: device name -> Device
DEVICES = {
    "vn300": Device("VectorNav VN-300 (ArduPilot configures it)", "vectornav-binary", ("model=VN-300-CR",), 1,
                    VN300_IMU_HZ, {"EAHRS_RATE": VN300_IMU_HZ}),
    "gq7": Device("MicroStrain 3DM-GQ7 (streams from power-on)", "microstrain-mip", ("preset=ardupilot",), 7,
                  _gq7_imu_hz(), {}),
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


#: AP_HAL::Device::BusType BUS_TYPE_SERIAL (libraries/AP_HAL/Device.h:42, 265753db8b)
BUS_TYPE_SERIAL = 6
#: SITL's simulated compasses SIM_MAG1_DEVID..SIM_MAG6_DEVID have non-zero defaults (libraries/SITL/SITL.cpp:777-809;
#: MAG7 and MAG8 default to 0); AP_Compass_SITL registers each non-zero one (AP_Compass_SITL.cpp:12-20)
SITL_MAGS_WITH_DEVID = 6


#: SCHED_LOOP_RATE's floor (AP_Scheduler.cpp:110-111)
MIN_LOOP_HZ = 50


def serial_bus_id(port: int, address: int = 0, devtype: int = 0) -> int:
    """AP_HAL::Device::make_bus_id(BUS_TYPE_SERIAL, port, address, devtype) (Device.cpp:222-229): the bitfields
    bus_type:3, bus:5, address:8, devtype:8 of DeviceStructure (Device.h:371-376), lowest first."""
    if not (0 <= port < 32 and 0 <= address < 256 and 0 <= devtype < 256):
        raise ValueError(f"bus id: port {port} (0-31), address {address}, devtype {devtype} (0-255) out of range")
    return BUS_TYPE_SERIAL | port << 3 | address << 8 | devtype << 16


def sole_sensor_params(mask: int, serial_port: int, imu_hz: float,
                       compass_offsets_mgauss: tuple[float, float, float]) -> dict[str, float]:
    """Parameters that leave the unit's sensors (the EAHRS_SENSORS `mask`) the only ones of their kind in SITL.

    IMU: SIM_IMU_COUNT 0 (SITL.cpp:548; AP_InertialSensor.cpp:1199-1210 adds the external AHRS's IMU first, then
    SIM_IMU_COUNT simulated ones). With no other IMU, wait_for_sample waits for the unit's next sample every loop
    (AP_InertialSensor.cpp:2109-2117 leaves only once a gyro and an accel sample are there), so the main loop
    runs no faster than the unit's IMU, and a loop without a new sample marks the gyro unhealthy
    (AP_InertialSensor.cpp:1904, 791-798). SCHED_LOOP_RATE = half the IMU rate (the scheduler's floor, 50 Hz,
    AP_Scheduler.cpp:110-111, at least): two samples per loop, so packets that arrive bunched on a loaded machine
    do not slow the loop below the 90 % "Main loop slow" fails at (AP_Arming.cpp:1085-1091). A serial IMU is
    exempt from the gyro-rate check (AP_InertialSensor.cpp:1486).
    The calibration values of accelerometers 2 and 3 (a defaults file may hold them for SITL's simulated IMUs,
    as copter.parm does) are cleared: with no such accelerometer they fail "3D Accel calibration needed"
    (AP_InertialSensor.cpp:1656-1665); simple_accel_cal clears them the same way when it passes (:2666-2671).
    Baro: SIM_BARO_COUNT 0 (SITL.cpp:568; AP_Baro.cpp:556 creates that many simulated ones, :570-573 the
    unit's). AP_Baro::calibrate then returns at once (AP_Baro.cpp:302-304) and the unit's baro takes its first
    pressure as the ground pressure (AP_Baro.cpp:825-828).
    Compass: SIM_MAGn_DEVID 0 removes the simulated ones; the unit's is COMPASS instance 1 with the dev id
    AP_Compass_ExternalAHRS gives it (make_bus_id(SERIAL, port, 0, 0), AP_Compass_ExternalAHRS.cpp:23).
    Compass::configured (AP_Compass.cpp:2023-2062) wants non-zero offsets and a stored COMPASS_DEV_ID equal to
    the detected one; a defaults-file value is what AP_Param::load returns for a parameter never saved
    (AP_Param.cpp:1347-1361, 2616-2621). COMPASS_PRIO1_ID the same, else "Compass order change requires
    reboot" (AP_Compass.cpp:2078-2080). The offsets are the unit's calibration: ArduPilot adds them to the
    field (AP_Compass_Backend.cpp:84-85), so they are minus the magnetometer's hard iron."""
    params: dict[str, float] = {}
    if mask & SENSOR_BITS["imu"]:
        params.update({"SIM_IMU_COUNT": 0, **_paced_loop_params(imu_hz)})
    if mask & SENSOR_BITS["baro"]:
        params["SIM_BARO_COUNT"] = 0
    if mask & SENSOR_BITS["compass"]:
        if not any(compass_offsets_mgauss):
            raise ValueError("compass offsets all zero: ArduPilot takes that for an uncalibrated compass "
                             "(AP_Compass.cpp:2031); give the scene's magnetometer a hard_iron")
        params.update({f"SIM_MAG{i}_DEVID": 0 for i in range(1, SITL_MAGS_WITH_DEVID + 1)})
        dev_id = serial_bus_id(serial_port)
        params.update({"COMPASS_DEV_ID": dev_id, "COMPASS_PRIO1_ID": dev_id})
        params.update({f"COMPASS_OFS_{axis}": value for axis, value in zip("XYZ", compass_offsets_mgauss)})
    return params


def _paced_loop_params(imu_hz: float) -> dict[str, float]:
    """The main loop paced by an IMU at imu_hz: SCHED_LOOP_RATE half its rate (see sole_sensor_params; ArduPilot
    also fails "Gyro N rate ..Hz < loop ratex1.8" below 1.8 samples per loop, AP_InertialSensor.cpp:1480-1488),
    and the calibration values of accelerometers 2 and 3 cleared (there are none)."""
    if not (MIN_LOOP_HZ <= imu_hz <= 4000):
        raise ValueError(f"IMU rate {imu_hz:g} Hz: the main loop it paces must run at {MIN_LOOP_HZ}-2000 Hz "
                         "(SCHED_LOOP_RATE, AP_Scheduler.cpp:110-113)")
    return {"SCHED_LOOP_RATE": max(MIN_LOOP_HZ, imu_hz / 2),
            **{f"INS_ACC{n}{kind}_{axis}": 0 for n in (2, 3) for kind in ("OFFS", "SCAL") for axis in "XYZ"}}


def json_params(imu_hz: float) -> dict[str, float]:
    """The JSON backend: SITL's own EKF3 on the emulator's IMU samples at the scene's rate imu_hz (GPS, baro and
    compass are SITL's, simulated from the JSON position and attitude).

    One simulated IMU (SIM_IMU_COUNT 1): SITL's IMUs all read the JSON's gyro and accel, each with its own
    noise, and a second one failed "Gyros inconsistent" (AP_Arming.cpp:497-499) on the 2026-12-02 run. The
    loop at half the JSON rate: SIM_JSON's frame rate must stay above the vehicle's loop rate
    (libraries/SITL/examples/JSON/readme.md), and 200 Hz samples at Copter's default 400 Hz loop failed "Gyro 0
    rate 203Hz < loop ratex1.8 720Hz". SIM_DRIFT_SPEED 0: SITL adds to every gyro sample a drift growing by
    0.05 deg/s per minute (SITL.cpp:73, AP_InertialSensor_SITL.cpp:215-219, 363-375), on top of the scene's
    own gyro errors. (Its fixed noise floor, 0.04 deg/s gyro and 0.01 m/s^2 accel uniform,
    AP_InertialSensor_SITL.cpp:111-117, 222-229, has no parameter.)"""
    if not imu_hz >= 2 * MIN_LOOP_HZ:      # a serial IMU is exempt from the 1.8x check (:1486), SITL's is not
        raise ValueError(f"JSON rate {imu_hz:g} Hz: SITL's IMU needs 1.8 samples per main loop, and the loop "
                         f"runs at {MIN_LOOP_HZ} Hz at least: give the scene a rate of {2 * MIN_LOOP_HZ} Hz or more")
    return {"SIM_IMU_COUNT": 1, "SIM_DRIFT_SPEED": 0, **_paced_loop_params(imu_hz)}


def device_params(device: str, serial_port: int = SERIAL_PORT, sensors: str = "all",
                  compass_offsets_mgauss: tuple[float, float, float] | None = None,
                  json_imu_hz: float | None = None) -> dict[str, float]:
    """The parameters selecting `device` (a key of DEVICES, or "json") on SERIAL<serial_port>, with the unit's
    `sensors` (sensors_mask) registered in ArduPilot and the only ones of their kind (sole_sensor_params;
    compass_offsets_mgauss: the unit's compass calibration, needed when its compass is one of them). For "json",
    json_imu_hz is the scene's sample rate (json_params)."""
    common = {"DISARM_DELAY": 0, "FS_CRASH_CHECK": 0}
    if device == "json":
        if json_imu_hz is None:
            raise ValueError("device 'json': give json_imu_hz, the scene's sample rate")
        return {**common, **json_params(json_imu_hz)}
    if device not in DEVICES:
        raise ValueError(f"device {device!r}: not one of {', '.join(sorted(DEVICES) + ['json'])}")
    unit = DEVICES[device]
    mask = sensors_mask(sensors)
    if mask & SENSOR_BITS["compass"] and compass_offsets_mgauss is None:
        raise ValueError(f"device {device!r} with its compass: give compass_offsets_mgauss (the unit's calibration)")
    return {**common,
            "EAHRS_TYPE": unit.eahrs_type,
            f"SERIAL{serial_port}_PROTOCOL": 36,
            f"SERIAL{serial_port}_BAUD": BAUD,
            "GPS1_TYPE": 21,
            "AHRS_EKF_TYPE": 11,
            "INS_GYR_CAL": 1,
            "EAHRS_SENSORS": mask,
            **unit.rate_params,
            **sole_sensor_params(mask, serial_port, unit.imu_hz, compass_offsets_mgauss or (0.0, 0.0, 0.0))}


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
