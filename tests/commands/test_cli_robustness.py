"""The command line under bad options, unwritable outputs, failing runs and signals: one `error:` line and
exit code 2, never a traceback; nothing half-written left behind; the run's figures kept; warnings shown."""
import json
import os
import resource
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from tests.support.stream import REPO, Emulator, mavlink_parse, open_pty_reader, read_for, run_emulator, write_scene
from tests.support.timing import scaled

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

WARNING = "warning: imu[1].mounting_rpy_deg is ignored because effects.mounting is not true"


def _scene_ignoring_a_mounting(directory):
    """imu1 names a mounting, but the effect is off: the output ignores it, and the user must be told."""
    path = write_scene(directory, rate=100, duration=1.0)
    path.write_text(path.read_text().replace("mounting = true\n", ""))
    return path


def _cli(capsys, *args):
    """The CLI in this process (for runs that end before or without streaming): exit code, stdout, stderr."""
    from imu_emulator.cli import main
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _ends_with_one_error_line(code, err, *expected):
    assert code == 2, err
    assert "Traceback" not in err and "Warning:" not in err, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("error: "), err
    assert sum(line.startswith("error: ") for line in err.splitlines()) == 1, err
    for text in expected:
        assert text in last, err
    return last


def _only_one_error_line(code, err, *expected):
    _ends_with_one_error_line(code, err, *expected)
    assert len(err.strip().splitlines()) == 1, err


def _no_temporaries(directory):
    assert not [p.name for p in directory.iterdir() if p.name.endswith(".part")]


# --- numeric options ---------------------------------------------------------------------------

@pytest.mark.parametrize("option, value", [
    ("--duration", "nan"), ("--duration", "inf"), ("--duration", "-1"), ("--duration", "1e300"),
    ("--speed", "1e-300"), ("--speed", "nan"), ("--speed", "-inf"), ("--speed", "-1"), ("--speed", "1e300"),
    ("--count", "0"), ("--count", "1.5"), ("--count", "nan"),
    ("--pace-baud", "0"), ("--pace-baud", "1e400"), ("--bitrate", "-5"), ("--data-bitrate", "inf"),
])
def test_out_of_range_number_is_one_line_naming_the_option(tmp_path, capsys, option, value):
    scene = write_scene(tmp_path, rate=100)
    with pytest.raises(SystemExit) as exit_:
        _cli(capsys, "stream", scene, "--format", "mavlink-highres", "--to", f"file:{tmp_path / 'o.bin'}",
             f"{option}={value}")     # the = form: argparse would take "-1" for an option
    _only_one_error_line(exit_.value.code, capsys.readouterr().err, option, repr(value))


def test_duration_shorter_than_a_sample_is_refused(tmp_path, capsys):
    scene = write_scene(tmp_path, rate=100)
    code, _, err = _cli(capsys, "stream", scene, "--format", "mavlink-highres", "--to", f"file:{tmp_path / 'o.bin'}",
                        "--duration", "0.001")
    _only_one_error_line(code, err, "--duration", "less than one sample at 100 Hz")


@pytest.mark.parametrize("value", ["nan", "inf", "-1e999"])
def test_non_finite_encoder_option_is_refused_by_name(tmp_path, capsys, value):
    scene = write_scene(tmp_path, rate=100)
    code, _, err = _cli(capsys, "stream", scene, "--format", "dronecan-rawimu", "--to",
                        f"file:{tmp_path / 'o.log'}", "--option", f"sample_period_s={value}")
    _only_one_error_line(code, err, f"sample_period_s={value}", "finite")


def test_usage_mistake_is_one_line(capsys):
    with pytest.raises(SystemExit) as exit_:
        _cli(capsys, "generate", "scene.toml")
    _only_one_error_line(exit_.value.code, capsys.readouterr().err, "-o/--output")


# --- unwritable outputs --------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["x.csv", "x.npz"])
def test_unwritable_generate_output_fails_before_the_run(tmp_path, capsys, name):
    code, _, err = _cli(capsys, "generate", REPO / "examples/helix.toml", "-o", f"/proc/{name}")
    _only_one_error_line(code, err, f"/proc/{name}", "cannot create")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only directory")
def test_read_only_directory_is_one_line(tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    code, _, err = _cli(capsys, "generate", REPO / "examples/helix.toml", "-o", locked / "x.csv")
    _only_one_error_line(code, err, str(locked / "x.csv"), "Permission denied")


def test_unwritable_stats_json_fails_before_anything_streams(tmp_path, capsys):
    scene = write_scene(tmp_path, rate=100)
    capture = tmp_path / "o.bin"
    code, out, err = _cli(capsys, "stream", scene, "--format", "mavlink-highres", "--to", f"file:{capture}",
                          "--speed", "0", "--stats-json", "/proc/x.json")
    _only_one_error_line(code, err, "/proc/x.json", "cannot create")
    assert not capture.exists() and out == ""


@pytest.mark.parametrize("fmt, target", [("mavlink-highres", "file:/proc/x.csv"), ("dronecan-rawimu", "file:/proc/x.csv"),
                                         ("dronecan-rawimu", "file:/proc/x.log")])
def test_unwritable_capture_fails_before_anything_streams(tmp_path, capsys, fmt, target):
    scene = write_scene(tmp_path, rate=100)
    code, _, err = _cli(capsys, "stream", scene, "--format", fmt, "--to", target, "--speed", "0")
    _only_one_error_line(code, err, target, "cannot open")


def test_capture_to_full_device_keeps_the_figures(tmp_path):
    stats = tmp_path / "stats.json"
    result = run_emulator(write_scene(tmp_path, rate=100), "--format", "mavlink-highres", "--to", "file:/dev/full",
                          "--speed", "0", "--stats-json", stats)
    _ends_with_one_error_line(result.returncode, result.stderr, "file:/dev/full", "No space left on device")
    assert "done:" in result.stderr
    summary = json.loads(stats.read_text())
    assert summary["streams"][0]["target"] == "file:/dev/full"
    _no_temporaries(tmp_path)


def test_stats_json_that_cannot_be_written_still_shows_the_figures(tmp_path):
    capture = tmp_path / "o.bin"
    result = run_emulator(write_scene(tmp_path, rate=100, duration=1.0), "--format", "mavlink-highres",
                          "--to", f"file:{capture}", "--speed", "0", "--quiet", "--stats-json", "/dev/full")
    _ends_with_one_error_line(result.returncode, result.stderr, "/dev/full", "No space left on device")
    # --quiet, yet the summary shows: the JSON that should have kept it could not be written.
    assert "done: 100 samples" in result.stderr
    assert "sent 100, dropped 0" in result.stderr
    assert len(mavlink_parse(capture.read_bytes())[0]) == 100


# --- no half-written files ----------------------------------------------------------------------

@pytest.mark.parametrize("name", ["out.csv", "out.npz"])
def test_failing_later_block_leaves_no_file_and_keeps_the_old_one(tmp_path, capsys, monkeypatch, name):
    from imu_emulator.errors import ImuEmulatorError
    from imu_emulator.runtime.simulation import Simulation
    block = Simulation.block

    def fail_at_the_third(self, k0, n):
        if k0 >= 2 * n:
            raise ImuEmulatorError("the third block failed")
        return block(self, k0, n)

    monkeypatch.setattr(Simulation, "block", fail_at_the_third)
    fresh = tmp_path / name
    code, _, err = _cli(capsys, "generate", REPO / "examples/helix.toml", "-o", fresh, "--block", "100")
    _only_one_error_line(code, err, "the third block failed")
    assert not fresh.exists()
    old = tmp_path / ("old" + fresh.suffix)
    old.write_bytes(b"the previous run's file")
    code, _, err = _cli(capsys, "generate", REPO / "examples/helix.toml", "-o", old, "--block", "100")
    assert code == 2 and old.read_bytes() == b"the previous run's file"
    _no_temporaries(tmp_path)


@pytest.mark.parametrize("name", ["big.csv", "big.npz"])
def test_write_error_is_one_line_naming_the_file_and_leaves_nothing(tmp_path, name):
    # A file size limit makes the kernel refuse the write (EFBIG), as a full disk would (ENOSPC);
    # CPython ignores SIGXFSZ, so the write fails with an OSError instead of killing the process.
    def limit_file_size():
        resource.setrlimit(resource.RLIMIT_FSIZE, (50_000, 50_000))

    out = tmp_path / name
    args = [sys.executable, "-m", "imu_emulator", "generate", "examples/helix.toml", "--block", "100", "-o"]
    # the kernel compiled first, without the limit: the limit is for the output, not for the cache's own files
    # (a cold cache would hit it writing numba's index, whatever the order the tests run in)
    warm = subprocess.run(args + [str(tmp_path / "warm.npz")], capture_output=True, text=True, cwd=REPO, timeout=scaled(600))
    assert warm.returncode == 0, warm.stderr
    (tmp_path / "warm.npz").unlink()
    result = subprocess.run(args + [str(out)], capture_output=True, text=True, cwd=REPO, timeout=scaled(120),
                            preexec_fn=limit_file_size)
    _only_one_error_line(result.returncode, result.stderr, str(out), "cannot write", "File too large")
    assert not out.exists()
    _no_temporaries(tmp_path)


def test_output_replaces_a_file_keeping_its_permissions_and_a_symlink_itself(tmp_path, capsys):
    """A file is replaced keeping its mode; a link is replaced by the file, its target left as it was (writing
    through a link is what let another user's link steer the output: issue 23, tests/files/test_file_safety.py)."""
    real = tmp_path / "real.csv"
    real.write_text("old")
    real.chmod(0o640)
    code, _, err = _cli(capsys, "generate", REPO / "examples/helix.toml", "-o", real, "--quiet")
    assert code == 0, err
    assert real.stat().st_mode & 0o777 == 0o640
    # README: one row per IMU per sample, round(T·f) = 1000 samples of the helix, plus the header (after the
    # '#' lines stating frames and units).
    assert len([line for line in real.read_text().splitlines() if not line.startswith("#")]) == 1001
    link = tmp_path / "link.csv"
    link.symlink_to(real)
    real.write_text("old")
    code, _, err = _cli(capsys, "generate", REPO / "examples/helix.toml", "-o", link, "--quiet")
    assert code == 0, err
    assert not link.is_symlink() and len([x for x in link.read_text().splitlines() if not x.startswith("#")]) == 1001
    assert real.read_text() == "old"


# --- warnings -----------------------------------------------------------------------------------

@pytest.mark.parametrize("quiet", [[], ["--quiet"]])
def test_both_commands_show_the_scene_warnings_even_when_quiet(tmp_path, capsys, quiet):
    scene = _scene_ignoring_a_mounting(tmp_path)
    code, _, err = _cli(capsys, "generate", scene, "-o", tmp_path / "o.csv", *quiet)
    assert code == 0 and WARNING in err.splitlines(), err
    result = run_emulator(scene, "--format", "mavlink-highres", "--to", f"file:{tmp_path / 'o.bin'}", "--speed", "0",
                          *quiet)
    assert result.returncode == 0 and WARNING in result.stderr.splitlines(), result.stderr


# --- signals and late readers on a pty ----------------------------------------------------------

@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGTERM])
def test_hangup_closes_like_sigterm_link_removed_summary_shown(tmp_path, sig):
    link = tmp_path / "imu"
    stats = tmp_path / "stats.json"
    with Emulator(write_scene(tmp_path, rate=200), "--format", "mavlink-highres", "--to", "pty", "--link", link,
                  "--loop", "--stats-json", stats) as emu:
        assert os.path.realpath(link) == emu.targets[0]
        fd = open_pty_reader(str(link))
        data = read_for(fd, 20.0, stop_after=60 * 75)     # streaming has begun: 60 packets arrived
        emu.proc.send_signal(sig)
        code, err = emu.wait()
        os.close(fd)
    assert code == 0, err
    assert "done:" in err and "Traceback" not in err
    assert not os.path.lexists(link), "the symlink outlives the stream"
    assert json.loads(stats.read_text())["samples"] > 0
    assert len(mavlink_parse(data)[0]) >= 59


def _first_time_s(fd, seconds=1.0) -> float:
    messages, bad = mavlink_parse(read_for(fd, seconds), types=("HIL_GPS",))
    assert messages and not bad
    return messages[0].time_usec * 1e-6


def test_reader_that_opens_late_or_reopens_gets_fresh_packets(tmp_path):
    # With --start-time now a GNSS fix's UTC time stamp (HIL_GPS time_usec) is the wall clock at its deadline.
    # Held back in the pty, the first packet a late reader gets would be up to a buffer (about 1 s) old.
    period = 1 / 200
    stats = tmp_path / "stats.json"
    with Emulator(write_scene(tmp_path, rate=200, duration=5.0), "--format", "mavlink-hil-gps", "--to", "pty",
                  "--loop", "--start-time", "now", "--stats-json", stats) as emu:
        time.sleep(2.0)
        opened = time.time()
        fd = open_pty_reader(emu.targets[0])
        first = _first_time_s(fd)
        # The reader stops reading (the pty fills: nobody's fault but the reader's), then goes away
        # with a full buffer unread; the next reader must not get those packets.
        time.sleep(1.5)
        os.close(fd)
        time.sleep(1.0)
        reopened = time.time()
        fd = open_pty_reader(emu.targets[0])
        again = _first_time_s(fd)
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err
    # Ten periods: the sender may run late under load; stale packets would be ~1 s old.
    assert opened - 10 * period <= first <= time.time()
    assert reopened - 10 * period <= again <= time.time()
    summary = json.loads(stats.read_text())
    assert summary["dropped"] >= 200 * 1.0 * 0.8    # at least the second without a reader, counted


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_generate_stopped_by_a_signal_leaves_no_file(tmp_path, sig):
    out = tmp_path / "long.csv"
    proc = subprocess.Popen([sys.executable, "-m", "imu_emulator", "generate", "examples/circle.toml", "-o", str(out),
                             "--block", "1000"], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + scaled(120)
    while not any(p.name.endswith(".part") and p.stat().st_size > 0 for p in tmp_path.iterdir()):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=scaled(60))
    assert proc.returncode != 0 and "Traceback" not in err, err
    assert list(tmp_path.iterdir()) == []


def test_stats_json_to_a_pipe_is_written_in_place(tmp_path):
    # /dev/stdout is a pipe here: it cannot be replaced by a rename, so it is written directly.
    result = run_emulator(write_scene(tmp_path, rate=100, duration=1.0), "--format", "mavlink-highres",
                          "--to", f"file:{tmp_path / 'o.bin'}", "--speed", "0", "--quiet", "--stats-json", "/dev/stdout")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout[result.stdout.index("{"):])
    assert summary["samples"] == 100


def test_align_json_that_cannot_be_written_is_one_line_after_the_report(tmp_path, capsys):
    record = tmp_path / "two.csv"
    assert _cli(capsys, "generate", REPO / "examples/two_imus.toml", "-o", record, "--quiet")[0] == 0
    code, out, err = _cli(capsys, "align", record, record, "--imu-a", "imu0", "--imu-b", "imu1",
                          "--json", "/proc/x.json")
    _ends_with_one_error_line(code, err, "/proc/x.json", "cannot create")
    assert out.strip(), "the results are shown before the JSON fails"


def test_generate_in_process_gives_the_signal_handlers_back(tmp_path, capsys):
    import signal
    before = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT)}
    scene = _scene_ignoring_a_mounting(tmp_path)
    code, _, _ = _cli(capsys, "generate", scene, "-o", tmp_path / "o.csv", "--quiet")
    assert code == 0
    assert {s: signal.getsignal(s) for s in before} == before
