"""The stream command's refusals: bad targets and link budgets give one-line errors and a non-zero exit."""
import os
import subprocess
import sys

import pytest

from tests.support.stream import REPO, run_emulator, write_scene

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]


def _one_line_error(result):
    assert result.returncode != 0
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


def _refused_in_process(capsys, *args):
    """Refusals happen before anything streams, so the CLI can run in this process (fast)."""
    from imu_emulator.cli import main
    code = main(["stream", *map(str, args)])
    captured = capsys.readouterr()
    return _one_line_error(subprocess.CompletedProcess(args, code, captured.out, captured.err))


@pytest.mark.parametrize("target, fmt, expected", [
    ("serial:/dev/does-not-exist@921600", "mavlink-highres", "No such file or directory"),
    ("bogus:thing", "mavlink-highres", "unknown target kind 'bogus'"),
    ("serial:", "mavlink-highres", "expected serial:DEVICE[@BAUD]"),
    ("serial:/dev/ttyUSB0@fast", "mavlink-highres", "baud rate after '@'"),
    ("udp:localhost", "mavlink-highres", "expected udp:HOST:PORT"),
    ("can:nosuchbus:ch0", "dronecan-rawimu", "unknown python-can interface"),
    ("can:socketcan", "dronecan-rawimu", "expected can:INTERFACE:CHANNEL"),
    ("can:virtual:ch0", "mavlink-highres", "carries can formats, not serial formats"),
    ("pty", "dronecan-rawimu", "carries serial formats, not can formats"),
    ("file:/no/such/dir/out.bin", "mavlink-highres", "cannot open"),
    ("file:/tmp/out.unknownsuffix", "dronecan-rawimu", "no CAN log writer"),
])
def test_bad_target_is_one_line_error(tmp_path, capsys, target, fmt, expected):
    scene = write_scene(tmp_path, rate=100)
    assert expected in _refused_in_process(capsys, scene, "--format", fmt, "--to", target, "--count", "5")


def test_bad_target_in_a_real_process_exits_2_without_traceback(tmp_path):
    scene = write_scene(tmp_path, rate=100)
    result = run_emulator(scene, "--format", "mavlink-highres", "--to", "serial:/dev/does-not-exist")
    assert result.returncode == 2
    assert "No such file or directory" in _one_line_error(result)


def test_serial_budget_refused_with_numbers_then_accepted_at_higher_baud(tmp_path, capsys):
    scene = write_scene(tmp_path, rate=1000)
    line = _refused_in_process(capsys, scene, "--format", "mavlink-highres", "--to", "serial:/dev/ttyS99@115200")
    assert "75,000 B/s" in line and "11,520 B/s" in line
    master, slave = os.openpty()
    try:
        ok = run_emulator(scene, "--format", "mavlink-highres", "--to", f"serial:{os.ttyname(slave)}@921600",
                          "--count", "20", "--quiet")
    finally:
        os.close(master)
        os.close(slave)
    assert ok.returncode == 0, ok.stderr


def test_can_budget_counts_worst_case_stuffing_and_allow_overload_overrides(tmp_path, capsys):
    scene = write_scene(tmp_path, rate=1000)
    line = _refused_in_process(capsys, scene, "--format", "dronecan-rawimu", "--to", "can:virtual:budget")
    assert "1120 bits/sample" in line and "1 Mbit/s" in line
    forced = run_emulator(scene, "--format", "dronecan-rawimu", "--to", "can:virtual:budget", "--count", "10",
                          "--allow-overload")
    assert forced.returncode == 0, forced.stderr
    faster_bus = run_emulator(scene, "--format", "dronecan-rawimu", "--to", "can:virtual:budget@2000000",
                              "--count", "10", "--quiet")
    assert faster_bus.returncode == 0, faster_bus.stderr


def test_stream_table_errors_name_the_key(tmp_path, capsys):
    scene = write_scene(tmp_path, extra='[[stream]]\nformat = "mavlink-highres"\nto = "pty"\nspeed = 3\n')
    assert "stream[0].speed: unknown key" in _refused_in_process(capsys, scene)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "imu_emulator", *args], capture_output=True, text=True, cwd=REPO)


def test_formats_and_targets_are_listed():
    formats = _cli("formats")
    assert formats.returncode == 0
    rows = {line.split()[0]: line for line in formats.stdout.splitlines()}
    assert "serial" in rows["mavlink-highres"] and "75 B/sample" in rows["mavlink-highres"]
    assert "can" in rows["dronecan-rawimu"] and "7 frames/sample" in rows["dronecan-rawimu"]
    targets = _cli("targets").stdout
    for syntax in ("pty", "serial:DEVICE[@BAUD]", "can:INTERFACE:CHANNEL[@BITRATE]", "udp:HOST:PORT", "file:PATH"):
        assert syntax in targets


def test_the_link_appears_only_once_the_stream_can_answer(tmp_path, capsys, monkeypatch):
    """Issue 23, item 8: --link appeared when the port opened, before the warm-up (on a cold cache, minutes), so a
    driver that opened it at once waited for answers. The link must not exist during the warm-up and must exist
    when the send loop starts; it is gone after the run."""
    from imu_emulator.cli import main
    from imu_emulator.live.streamer import Streamer
    link = tmp_path / "imu0"
    seen = {}
    warm_up, send_loop = Streamer._warm_up, Streamer._send_loop

    def recording_warm_up(self):
        seen["during warm-up"] = os.path.lexists(link)
        return warm_up(self)

    def recording_send_loop(self, *args):
        seen["when the loop starts"] = os.path.lexists(link)
        return send_loop(self, *args)

    monkeypatch.setattr(Streamer, "_warm_up", recording_warm_up)
    monkeypatch.setattr(Streamer, "_send_loop", recording_send_loop)
    scene = write_scene(tmp_path, rate=200)
    code = main(["stream", str(scene), "--format", "mavlink-highres", "--to", "pty", "--link", str(link),
                 "--count", "20", "--quiet"])
    assert code == 0, capsys.readouterr().err
    assert seen == {"during warm-up": False, "when the loop starts": True}
    assert not os.path.lexists(link)
