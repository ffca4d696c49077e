"""[[imu]] time_offset_s: added to that IMU's time stamps in every output that carries stamps (CSV, NPZ, MCAP,
wire formats), never to the samples themselves. Expected stamps are the closed form t0 + k/rate + offset; the
MCAP bag is read back with rosbags, the wire stream with pymavlink (independent readers)."""
import calendar

import numpy as np
import pytest

from imu_emulator import ImuEmulatorError, scene_from_dict
from imu_emulator.cli import main
from imu_emulator.analysis.imulog import read_logs
from imu_emulator.runtime.simulation import Simulation

OFFSET_S = 3.7e-3      # not a multiple of the 10 ms sample period
RATE_HZ = 100.0
T0_S = 2.0


def scene_dict(offset=OFFSET_S):
    return {"scene": {"rate_hz": RATE_HZ, "duration_s": 0.5, "t0_s": T0_S},
            "trajectory": {"x": "0", "y": "0", "z": "0"},
            "attitude": {"mode": "euler", "roll": "0.2*sin(t)", "pitch": "0", "yaw": "0.3*t"},
            "imu": [{"name": "a"}, {"name": "b", "time_offset_s": offset}],
            "effects": {"gravity": True}}


def write_scene(tmp_path, offset=OFFSET_S):
    lines = ["[scene]", f"rate_hz = {RATE_HZ}", "duration_s = 0.5", f"t0_s = {T0_S}",
             "[trajectory]", 'x = "0"', 'y = "0"', 'z = "0"',
             "[attitude]", 'mode = "euler"', 'roll = "0.2*sin(t)"', 'pitch = "0"', 'yaw = "0.3*t"',
             "[[imu]]", 'name = "a"', "[[imu]]", 'name = "b"', f"time_offset_s = {offset!r}",
             "[effects]", "gravity = true"]
    path = tmp_path / "scene.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def nominal(n):
    return T0_S + np.arange(n) / RATE_HZ


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_file_outputs_carry_each_imus_own_stamps(tmp_path, suffix):
    out = tmp_path / f"run{suffix}"
    assert main(["generate", str(write_scene(tmp_path)), "-o", str(out), "--quiet"]) == 0
    logs = read_logs(out)
    t = nominal(len(logs["a"].t))
    np.testing.assert_allclose(logs["a"].t, t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(logs["b"].t, t + OFFSET_S, rtol=0, atol=1e-12)
    # the samples are the same instants' values: only the stamps move (yaw rate 0.3 rad/s is constant)
    np.testing.assert_array_equal(logs["a"].gyro, logs["b"].gyro)


def test_mcap_stamps_are_shifted_per_imu(tmp_path):
    from tests.output.test_output_mcap import read_bag
    bag = tmp_path / "run.mcap"
    assert main(["generate", str(write_scene(tmp_path)), "-o", str(bag), "--quiet"]) == 0
    topics = read_bag(bag)
    # stamped on generate's default --start-time, 2024-01-01T00:00:00Z (README conventions)
    ns = calendar.timegm((2024, 1, 1, 0, 0, 0)) * 10**9 + np.rint(nominal(50) * 1e9).astype(np.int64)
    for name, shift in (("a", 0), ("b", 3_700_000)):
        stamps = np.array([d.header.stamp.sec * 10**9 + d.header.stamp.nanosec for _, d in topics[f"/imu/{name}"]])
        np.testing.assert_array_equal(stamps, ns + shift)


def test_wire_time_fields_carry_the_offset(tmp_path):
    """HIGHRES_IMU's time_usec (since start) of IMU b starts at the offset, decoded by pymavlink."""
    from pymavlink.dialects.v20 import common
    scene = write_scene(tmp_path)
    stamps = {}
    for imu in ("a", "b"):
        capture = tmp_path / f"{imu}.bin"
        assert main(["stream", str(scene), "--imu", imu, "--format", "mavlink-highres", "--to", f"file:{capture}",
                     "--speed", "0", "--quiet"]) == 0
        mav = common.MAVLink(None)
        msgs = mav.parse_buffer(capture.read_bytes())
        stamps[imu] = np.array([m.time_usec for m in msgs if m.get_type() == "HIGHRES_IMU"], dtype=np.int64)
    assert len(stamps["a"]) == len(stamps["b"]) == 50
    np.testing.assert_array_equal(stamps["b"] - stamps["a"], 3700)


def test_block_offsets_follow_the_scene():
    block = Simulation(scene_from_dict(scene_dict()), attitude=False).run()
    np.testing.assert_array_equal(block.time_offset_s, [0.0, OFFSET_S])
    assert block.imu_offset_ns(1) == 3_700_000
    # all zero: no per-IMU stamps at all (NPZ keeps its one t)
    assert Simulation(scene_from_dict(scene_dict(0.0)), attitude=False).run().time_offset_s is None


@pytest.mark.parametrize("value, message", [
    ("3 ms", "imu[1].time_offset_s: expected a number"),
    (float("inf"), "imu[1].time_offset_s: must be a finite number"),
    (2e6, "imu[1].time_offset_s: 2000000.0 is out of range"),
    (True, "imu[1].time_offset_s: expected a number")])
def test_bad_time_offset_is_named(value, message):
    with pytest.raises(ImuEmulatorError, match=message.replace("[", r"\[").replace("]", r"\]")):
        scene_from_dict(scene_dict(value))


def test_offset_too_large_for_float_stamps_is_refused():
    raw = scene_dict(9e5)
    raw["scene"]["rate_hz"] = 1e7     # spacing of floats at 9e5 s (1.2e-10 s) > 1e-3 of 1e-7 s
    with pytest.raises(ImuEmulatorError, match=r"imu\[1\]\.time_offset_s: time stamps reach"):
        scene_from_dict(raw)
