"""When a slower sensor (magnetometer, barometer) has a new reading among the IMU's samples.

Samples carry every sensor at the IMU's rate, the slower ones held between their own readings, and say where
a reading is new: `Samples.mag_new` and `Samples.baro_new` (1 at the sample where the sensor's reading arrives,
as `gnss_new` for the GNSS receiver), which `stream` takes from the scene's companions ([imu.magnetometer]
rate_hz, [imu.barometer] rate_hz). A format that marks new readings (MAVLink HIL_SENSOR's fields_updated bits)
or sends a message only when one exists (SCALED_PRESSURE, a DroneCAN node's StaticPressure) reads them through
`new_readings`; without the flags every sample is new (a sensor running at the sample rate).

The encoder options `mag_rate_hz` and `baro_rate_hz` that once set these rates are retired: a second rate at the
encoder could only disagree with the readings the samples hold (a flag where the value did not change, or a new
value without its flag). Given, they are refused in one line naming the scene key instead.
"""
from __future__ import annotations

import numpy as np

#: retired encoder option -> where the rate comes from now
RETIRED_RATES = {"mag_rate_hz": ("[imu.magnetometer] rate_hz", "mag_new"),
                 "baro_rate_hz": ("[imu.barometer] rate_hz", "baro_new")}


def refuse_retired(**given) -> None:
    """ValueError naming the first retired rate option given a value (None: not given)."""
    for name, value in given.items():
        if value is not None:
            key, flag = RETIRED_RATES[name]
            raise ValueError(f"{name}: retired; the sensor's rate is the scene's {key} (readings are new where "
                             f"Samples.{flag} is 1)")


def retired_help(name: str) -> str:
    """The option listing's line for a retired rate option."""
    key, _ = RETIRED_RATES[name]
    return f"retired: set the scene's {key} (refused here)"


def new_readings(flags: np.ndarray | None, n: int) -> np.ndarray:
    """(n,) bool: where the sensor has a new reading (every sample when the samples carry no flags)."""
    return np.ones(n, dtype=bool) if flags is None else np.asarray(flags) != 0
