"""What the device tests share (holds no tests): a ground station's MAVLink side, and CPU time taken as the best of
three runs, for the linear-time checks that compare ratios, never absolute times."""
import time

from pymavlink.dialects.v20 import common as mavlink2


def gcs():
    """A ground station's MAVLink 2 object (system 255, component 190) that skips bad bytes."""
    mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    mav.robust_parsing = True
    return mav


def command_long(*params, command=511) -> bytes:
    """COMMAND_LONG to system 1, component 1 (SET_MESSAGE_INTERVAL unless `command` says otherwise)."""
    params = list(params) + [0.0] * (7 - len(params))
    return mavlink2.MAVLink_command_long_message(1, 1, command, 0, *params).pack(gcs())


def best_cpu(run, data) -> float:
    """CPU seconds of run(data), the best of three (at least 1 ms, so a ratio never divides by zero)."""
    times = []
    for _ in range(3):
        start = time.process_time()
        run(data)
        times.append(time.process_time() - start)
    return max(min(times), 1e-3)


def cpu_ratio(run, small: bytes, large: bytes) -> float:
    """CPU time of run(large) over run(small)."""
    return best_cpu(run, large) / best_cpu(run, small)
