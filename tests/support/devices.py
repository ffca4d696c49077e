"""What the device tests share (holds no tests): a ground station's MAVLink side, and floods with the hang limit
that tells a parser whose cost grows with the square of its input from one whose cost grows with its size."""
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


#: Floods this long expose a parser that rescans its buffer for every byte: n^2/2 = 2.2e12 bytes compared, over
#: 100 s even at memchr speed (20 GB/s). Every parser here takes under 10 s of CPU on one (the slowest, a flood of
#: '$' through the VectorNav device, about 9 s; 2026-12-02, AMD EPYC, load 1). 2 MiB of 0xFD took the MAVLink
#: device 411 s on 168021a.
FLOOD_BYTES = 2 * 1024 * 1024
#: A hang limit on the reference machine (tests/support/timing.py scales it): 4 times the slowest fixed parser,
#: under half the fastest quadratic one. It asserts no speed; tools/bench_decoder_floods.py prints the figures.
FLOOD_LIMIT_S = 40.0


def flood(unit: bytes, size: int = FLOOD_BYTES) -> bytes:
    """`unit` repeated to `size` bytes."""
    return (unit * (size // len(unit) + 1))[:size]


def cpu_seconds(run, data) -> float:
    """CPU seconds of this process spent in run(data)."""
    start = time.process_time()
    run(data)
    return time.process_time() - start
