"""One time base for every GNSS/UTC field (issue 24): Samples.time_ns is UTC Unix nanoseconds, the run's
--start-time plus the scene time; each format derives GPS week / time of week, UTC calendar fields and leap seconds
from it (firmware_protocols.gnss_time), and fields that count since the unit's start count from the run's start.

The reference here is independent of the module: Python's datetime arithmetic from the definitions (GPS time
began 1980-01-06T00:00:00 UTC and has gained 18 leap seconds on UTC since 2017-01-01, IERS Bulletin C: TAI - UTC
= 37 s, GPS = TAI - 19 s), cross-checked by a second route (calendar.timegm and whole-day counts). astropy is
not installed here. The GNSS records are read back by independent readers where one exists: pymavlink (HIL_GPS),
pydronecan (Fix2), the spec-layout readers of test_microstrain / test_vectornav_drivers, and the mcap library
for the ROS 2 bag's log times.
"""
import calendar
import io
import subprocess
import sys
from datetime import date, datetime, timedelta, timezone

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from firmware_protocols.base import Samples
from tests.support.paths import REPO
from tests.support.timing import scaled

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

UTC = timezone.utc
START_ISO = "2026-11-27T12:00:00Z"
START = datetime(2026, 11, 27, 12, tzinfo=UTC)
GPS_EPOCH = datetime(1980, 1, 6, tzinfo=UTC)
LEAP_S = 18
WEEK = timedelta(weeks=1)
# Scene times (us multiples, so datetime holds them exactly): the start, a quarter second, an hour and a half
# second, and either side of the GPS week rollover (Sunday 00:00:00 GPS = Saturday 2026-11-28 23:59:42 UTC).
ROLLOVER_S = (datetime(2026, 11, 28, 23, 59, 60 - LEAP_S, tzinfo=UTC) - START).total_seconds()
SCENE_US = [0, 250_000, 3_600_500_000, int(ROLLOVER_S * 1e6) - 1_000, int(ROLLOVER_S * 1e6) + 1_000]


def unix_ns(when: datetime) -> int:
    delta = when - datetime(1970, 1, 1, tzinfo=UTC)
    return (delta.days * 86_400 + delta.seconds) * 10**9 + delta.microseconds * 1000


def gps_week_tow_ns(when: datetime) -> tuple:
    since = when + timedelta(seconds=LEAP_S) - GPS_EPOCH
    week = since // WEEK
    rest = since - week * WEEK
    return week, (rest.days * 86_400 + rest.seconds) * 10**9 + rest.microseconds * 1000


START_NS = unix_ns(START)
WHEN = [START + timedelta(microseconds=us) for us in SCENE_US]
EXPECTED = [gps_week_tow_ns(w) for w in WHEN]


def test_the_reference_agrees_with_a_second_route():
    """Unix time by calendar.timegm; the GPS week by whole days since the GPS epoch's Sunday; both straddle the
    rollover the scene times were chosen around."""
    assert START_NS == calendar.timegm(START.timetuple()) * 10**9
    gps_start = START + timedelta(seconds=LEAP_S)       # 12:00:18 GPS: the same day
    assert EXPECTED[0][0] == (date(2026, 11, 27) - date(1980, 1, 6)).days // 7
    assert EXPECTED[0][1] == ((date(2026, 11, 27) - date(1980, 1, 6)).days % 7 * 86_400
                              + gps_start.hour * 3600 + gps_start.second) * 10**9
    assert EXPECTED[4][0] == EXPECTED[3][0] + 1 and EXPECTED[4][1] == 1_000_000 and \
        EXPECTED[3][1] == 7 * 86_400 * 10**9 - 1_000_000


@pytest.fixture(scope="module")
def block() -> Samples:
    """The five samples at START + SCENE_US, with the run's start declared; a receiver solution at each."""
    n = len(SCENE_US)
    llh = np.tile([47.4, 8.5, 500.0], (n, 1))
    return Samples(START_NS + np.array(SCENE_US, dtype=np.int64) * 1000, np.zeros((n, 3)), np.zeros((n, 3)),
                   position_llh=llh, velocity_ned=np.zeros((n, 3)), gnss_llh=llh, gnss_velocity_ned=np.zeros((n, 3)),
                   gnss_fix=np.full(n, 3.0), gnss_new=np.ones(n), gnss_age_s=np.zeros(n), start_ns=START_NS)


def test_module_gps_time_is_the_reference(block):
    from firmware_protocols.gnss_time import gps_week_tow_ns as module_week_tow
    week, tow = module_week_tow(block.time_ns)
    assert list(zip(week.tolist(), tow.tolist())) == EXPECTED


def test_vectornav_gps_week_tow_and_utc(block):
    from firmware_protocols.wire_formats.vectornav_binary import BinaryDecoder, BinaryEncoder
    encoder = BinaryEncoder("time:timestartup,timegps,gpstow,gpsweek,timeutc")
    packets = BinaryDecoder().feed(encoder.encode(block).data)
    assert len(packets) == len(SCENE_US) and not encoder.saturated.counts
    for p, when, (week, tow), us in zip(packets, WHEN, EXPECTED, SCENE_US):
        f = p.fields
        assert (f["time.gpsweek"], f["time.gpstow"]) == (week, tow)
        assert f["time.timegps"] == week * WEEK // timedelta(microseconds=1) * 1000 + tow
        assert f["time.timestartup"] == us * 1000                      # since the unit's (the run's) start
        assert (f["time.timeutc.year"] + 2000, f["time.timeutc.month"], f["time.timeutc.day"], f["time.timeutc.hour"],
                f["time.timeutc.minute"], f["time.timeutc.second"], f["time.timeutc.ms"]) == \
            (when.year, when.month, when.day, when.hour, when.minute, when.second, when.microsecond // 1000)


def test_microstrain_gps_timestamp(block):
    from firmware_protocols.wire_formats.microstrain import MipDecoder, MipEncoder
    packets = MipDecoder().feed(MipEncoder(fields=("gps_timestamp",)).encode(block).data)
    for p, (week, tow), t in zip(packets, EXPECTED, block.time_ns.tolist()):
        assert p.fields["gps_week"] == week and p.fields["gps_tow"] == tow / 1e9
        assert p.fields["time_ns"] == t                                 # back to UTC Unix ns


def test_xsens_utc_time_and_gnss_pvt_itow(block):
    from firmware_protocols.wire_formats.xsens import XsensDecoder, XsensEncoder
    data = XsensEncoder(items=("sample_time_fine", "utc_time", "gnss_pvt_data")).encode(block).data
    packets = [p for p in XsensDecoder().feed(bytes(data)) if "utc_time" in p.fields]
    assert len(packets) == len(SCENE_US)
    for p, when, (week, tow), us in zip(packets, WHEN, EXPECTED, SCENE_US):
        nano, year, month, day, hour, minute, second, flags = p.fields["utc_time"]
        assert (year, month, day, hour, minute, second, nano) == (when.year, when.month, when.day, when.hour,
                                                                  when.minute, when.second, when.microsecond * 1000)
        assert p.fields["gnss_pvt_data"][0] == tow // 1_000_000        # iTOW, ms
        assert p.fields["sample_time_fine"] == us // 100                # 10 kHz ticks since the start


def test_mavlink_hil_gps_is_utc_and_highres_imu_counts_since_start(block):
    from firmware_protocols.wire_formats.mavlink import MavlinkEncoder
    from firmware_protocols.wire_formats.mavlink_nav import MavlinkNavEncoder
    mav = mavlink2.MAVLink(io.BytesIO())
    gps = mav.parse_buffer(bytes(MavlinkNavEncoder("mavlink-hil-gps").encode(block).data))
    assert [m.time_usec for m in gps] == [unix_ns(w) // 1000 for w in WHEN]
    for m, (week, tow) in zip(gps, EXPECTED):
        # what a consumer makes of UTC us (PX4: time_utc_usec; ArduPilot's UNIX_OFFSET_MSEC + leap seconds)
        assert divmod(m.time_usec * 1000 + (LEAP_S * 10**9 - unix_ns(GPS_EPOCH)), WEEK // timedelta(microseconds=1)
                      * 1000) == (week, tow)
    imu = mavlink2.MAVLink(io.BytesIO()).parse_buffer(bytes(MavlinkEncoder("mavlink-highres").encode(block).data))
    assert [m.time_usec for m in imu] == SCENE_US


def test_dronecan_fix2_is_utc_with_its_leap_seconds(block):
    from firmware_protocols.wire_formats.dronecan_sensors import Fix2Encoder
    from tests.firmware_protocols.wire_formats.test_dronecan_sensors import transfers
    fixes = [t.payload for _, t in transfers(Fix2Encoder().encode(block))]
    assert len(fixes) == len(SCENE_US)
    for fix, when, (week, tow) in zip(fixes, WHEN, EXPECTED):
        assert fix.gnss_time_standard == 2 and fix.num_leap_seconds == LEAP_S          # UTC, 18 s
        assert fix.gnss_timestamp.usec == unix_ns(when) // 1000
        # AP_GPS_DroneCAN handle_fix2_msg: gps_ms = utc_ms - UNIX_OFFSET_MSEC + num_leap_seconds * 1000
        gps_ms = fix.gnss_timestamp.usec // 1000 - unix_ns(GPS_EPOCH) // 10**6 + fix.num_leap_seconds * 1000
        assert divmod(gps_ms, 7 * 86_400_000) == (week, tow // 1_000_000)


def test_dronecan_imu_and_sitl_json_count_since_the_start(block):
    """uavcan.Timestamp of RawIMU (the node's own clock: no time sync) and SIM_JSON's physics time count from the
    run's start, read by pydronecan and json."""
    import json

    from firmware_protocols.wire_formats.ardupilot_json import ArduPilotJsonEncoder
    from firmware_protocols.wire_formats.dronecan import RawImuEncoder
    from tests.firmware_protocols.wire_formats.test_dronecan_sensors import transfers
    raw = [t.payload.timestamp.usec for _, t in transfers(RawImuEncoder(sample_period_s=0.01).encode(block))]
    assert raw == SCENE_US
    lines = bytes(ArduPilotJsonEncoder().encode(block).data).split(b"\n")
    assert [json.loads(line)["timestamp"] for line in lines if line] == [us / 1e6 for us in SCENE_US]


def test_gps_week_offset_is_retired_in_one_line():
    from firmware_protocols.devices.vectornav import VectorNavDevice
    from firmware_protocols.wire_formats.vectornav_binary import BinaryEncoder
    for make in (lambda: BinaryEncoder(gps_week_offset=2300), lambda: VectorNavDevice(400.0, gps_week_offset=2300)):
        with pytest.raises(ValueError, match="--start-time") as err:
            make()
        assert "\n" not in str(err.value)


# --- one run: the ROS 2 bag's stamps and the wire's UTC times agree -------------------------------------------

RATE = 50


def _cli(*args, timeout=scaled(120)) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "imu_emulator", *map(str, args)], cwd=REPO, capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One scene (0.2 s at 50 Hz), generated to a bag and streamed as HIL_GPS to a file, both from START_ISO."""
    from tests.support.stream import write_scene
    directory = tmp_path_factory.mktemp("time_base")
    scene = write_scene(directory, rate=RATE, duration=0.2)
    bag, wire = directory / "run.mcap", directory / "wire.bin"
    generated = _cli("generate", scene, "-o", bag, "--start-time", START_ISO, "--quiet")
    assert generated.returncode == 0, generated.stderr
    streamed = _cli("stream", scene, "--format", "mavlink-hil-gps", "--to", f"file:{wire}", "--speed", "0",
                    "--count", "10", "--quiet", "--start-time", START_ISO)
    assert streamed.returncode == 0, streamed.stderr
    return bag, wire


def test_ros2_stamps_and_wire_utc_times_of_one_run_agree(runs):
    from mcap.reader import make_reader
    bag, wire = runs
    with open(bag, "rb") as f:
        stamps = {}
        for _, channel, m in make_reader(f).iter_messages():
            if channel.topic.startswith("/imu/") and channel.topic.count("/") == 2:     # sensor_msgs/Imu per IMU
                stamps.setdefault(channel.topic, []).append(m.log_time)
    expected = [START_NS + k * 10**9 // RATE for k in range(10)]
    first = sorted(stamps)[0]               # the stream sends the scene's first IMU
    assert stamps[first][:10] == expected
    gps = mavlink2.MAVLink(io.BytesIO()).parse_buffer(wire.read_bytes())
    assert [m.time_usec * 1000 for m in gps] == expected


@pytest.mark.parametrize("command", ["generate", "stream"])
def test_a_bad_start_time_is_one_error_line(tmp_path, command):
    from tests.support.stream import write_scene
    scene = write_scene(tmp_path, rate=RATE, duration=0.2)
    extra = ["-o", tmp_path / "x.csv"] if command == "generate" else ["--format", "mavlink-highres", "--to",
                                                                      f"file:{tmp_path / 'x.bin'}"]
    result = _cli(command, scene, *extra, "--start-time", "2026-13-45T99:00:00Z")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("error") or ": error:" in line]
    assert len(errors) == 1 and "--start-time" in errors[0] and "2026-13-45T99:00:00Z" in errors[0], result.stderr
