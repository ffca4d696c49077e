"""The MAVLink device carrying the sensor head's other messages (`also=`) beside its IMU message on one link: one
sequence, each message at its own rate, and the rate commands of common.xml (MAV_CMD_SET_MESSAGE_INTERVAL 511,
MAV_CMD_REQUEST_MESSAGE 512, MAV_CMD_GET_MESSAGE_INTERVAL 510) working for them as for the IMU message.
pymavlink is the ground station."""
import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from firmware_protocols import registry
from firmware_protocols.base import Samples

RATE = 100.0


def gcs():
    return mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)


def head_block(n=300):
    """3 s at 100 Hz, a GNSS receiver at 5 Hz (new solution every 20th sample), a 10 Hz barometer (every 10th)."""
    rng = np.random.default_rng(1)
    t = (np.arange(n) * 1e9 / RATE).astype(np.int64)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return Samples(t, rng.normal(0, 1, (n, 3)), rng.normal(0, 0.1, (n, 3)), mag=rng.normal(0, 0.3, (n, 3)),
                   pressure_pa=np.full(n, 96000.0), temperature_c=np.full(n, 18.0), quat=q,
                   gnss_llh=np.tile([47.0, 8.0, 400.0], (n, 1)), gnss_velocity_ned=np.zeros((n, 3)),
                   gnss_new=(np.arange(n) % 20 == 0).astype(float), baro_new=(np.arange(n) % 10 == 0).astype(float))


def run(device, block, lo, hi):
    return b"".join(device.output(block, i) for i in range(lo, hi))


def parse(data):
    return [m for m in (gcs().parse_buffer(data) or []) if m.get_type() != "BAD_DATA"]


def make(**options):
    info = registry.get("mavlink-hil-sensor")
    return info.device(RATE, also="mavlink-hil-gps, mavlink-scaled-pressure,mavlink-attitude", **options)


def test_each_message_at_its_own_rate_with_one_sequence():
    device = make()
    block = head_block()
    messages = parse(run(device, block, 0, 300))
    kinds = [m.get_type() for m in messages]
    assert kinds.count("HEARTBEAT") == 3 and kinds.count("HIL_SENSOR") == 300 and kinds.count("ATTITUDE") == 300
    assert kinds.count("HIL_GPS") == 15                # 3 s of 5 Hz fixes
    assert kinds.count("SCALED_PRESSURE") == 30        # 3 s of 10 Hz barometer readings
    seqs = [m.get_seq() for m in messages]
    assert all((b - a) % 256 == 1 for a, b in zip(seqs, seqs[1:]))     # no gaps, no repeats: one sender
    sensors = [m for m in messages if m.get_type() == "HIL_SENSOR"]
    baro_bits = 0b1101000000000
    assert sum(m.fields_updated & baro_bits == baro_bits for m in sensors) == 30


def test_rate_commands_reach_the_extra_messages():
    device = make()
    block = head_block()
    mav = gcs()
    # ATTITUDE (30) every 50 ms: every 5th sample
    (reply,) = device.receive(mav.command_long_encode(1, 1, 511, 0, 30, 50_000, 0, 0, 0, 0, 0).pack(mav))
    (ack,) = parse(reply)
    assert (ack.command, ack.result) == (511, 0)
    kinds = [m.get_type() for m in parse(run(device, block, 0, 100))]
    assert kinds.count("ATTITUDE") == 20
    # and it reports that interval back
    interval, ack = parse(b"".join(device.receive(mav.command_long_encode(1, 1, 510, 0, 30, 0, 0, 0, 0, 0, 0)
                                                   .pack(mav))))
    assert (interval.message_id, interval.interval_us, ack.result) == (30, 50_000, 0)
    # HIL_GPS asked for between fixes: the held solution goes out once with the next sample
    (reply,) = device.receive(mav.command_long_encode(1, 1, 512, 0, 113, 0, 0, 0, 0, 0, 0).pack(mav))
    assert parse(reply)[0].result == 0
    kinds = [m.get_type() for m in parse(run(device, block, 101, 105))]
    assert kinds.count("HIL_GPS") == 1
    # a message the device cannot send is still denied
    (reply,) = device.receive(mav.command_long_encode(1, 1, 511, 0, 24, 10_000, 0, 0, 0, 0, 0).pack(mav))
    assert parse(reply)[0].result == 2


def test_a_thinned_hil_sensor_flags_the_readings_of_the_samples_it_skipped():
    """SET_MESSAGE_INTERVAL HIL_SENSOR (107) to 30 ms: every 3rd sample of 100 Hz. The 10 Hz barometer's readings
    (every 10th sample) fall on skipped samples two times in three; each still goes out once, flagged in the first
    message at or after it, so PX4 sees all 10 a second."""
    device = make()
    block = head_block()
    mav = gcs()
    (reply,) = device.receive(mav.command_long_encode(1, 1, 511, 0, 107, 30_000, 0, 0, 0, 0, 0).pack(mav))
    assert parse(reply)[0].result == 0
    sensors = [m for m in parse(run(device, block, 0, 300)) if m.get_type() == "HIL_SENSOR"]
    assert len(sensors) == 100                                 # message j is sample 3j
    baro_bits = 0b1101000000000
    flagged = [j for j, m in enumerate(sensors) if m.fields_updated & baro_bits == baro_bits]
    assert flagged == [-(-k // 3) for k in range(0, 300, 10)]      # ceil(k / 3): 30 readings, 30 flags


def test_unknown_extra_message_is_a_one_line_error():
    with pytest.raises(ValueError, match="also: 'mavlink-gps' is not one of mavlink-hil-gps"):
        registry.get("mavlink-hil-sensor").device(RATE, also="mavlink-gps")


def test_nav_message_alone_is_a_device_too():
    device = registry.get("mavlink-gps-raw-int").device(RATE)
    kinds = [m.get_type() for m in parse(run(device, head_block(), 0, 100))]
    assert kinds.count("GPS_RAW_INT") == 5 and kinds.count("HEARTBEAT") == 1


def test_streamed_on_a_pty_with_the_position_the_scene_gives(tmp_path):
    """The emulator in its own process: HIL_SENSOR with also=HIL_GPS and ATTITUDE_QUATERNION on one pty. Without a
    GNSS receiver in the scene the fix carries the navigation the streamer computes (fix_type 3)."""
    import os
    from tests.support.stream import Emulator, read_for, write_scene
    scene = write_scene(tmp_path, rate=100, duration=30.0)
    with Emulator(scene, "--format", "mavlink-hil-sensor", "--to", "pty", "--duration", "5",
                  "--option", "also=mavlink-hil-gps,mavlink-attitude-quaternion") as emu:
        fd = os.open(emu.targets[0], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        data = read_for(fd, 2.0)
    messages = parse(data)
    kinds = [m.get_type() for m in messages]
    assert kinds.count("HIL_SENSOR") > 50
    assert kinds.count("HIL_GPS") == kinds.count("ATTITUDE_QUATERNION") == kinds.count("HIL_SENSOR")
    fixes = [m for m in messages if m.get_type() == "HIL_GPS"]
    assert {m.fix_type for m in fixes} == {3} and all(m.lat != 0 and m.lon != 0 for m in fixes)
    seqs = [m.get_seq() for m in messages]
    assert all((b - a) % 256 == 1 for a, b in zip(seqs, seqs[1:]))
