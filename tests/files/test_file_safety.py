"""What another user on the machine can place must not run or be overwritten (issue 23, items 1, 2 and 12).

The kernel cache is executed, so it is trusted only as ssh trusts ~/.ssh (the running user's alone) and each entry
carries this cache's HMAC; outputs are created without following a link someone else placed; a path a running
stream holds is locked; a killed writer's temporary part is removed by the next one. "Another user" is uid 65534
(nobody) in a forked child that drops root's privileges: these tests need root, as CI runs them.
"""
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import traceback
from pathlib import Path

import pytest

from imu_emulator.errors import TargetError
from imu_emulator.output.atomic import AtomicOutput
from imu_emulator.runtime import cache, kernels
from imu_emulator.scene.load import load_scene
from tests.support.paths import REPO
from tests.support.timing import scaled

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

NOBODY = 65534
as_root = pytest.mark.skipif(os.geteuid() != 0, reason="acting as another user (uid 65534) needs root")


def as_nobody(action) -> None:
    """Run `action` in a forked child as uid/gid 65534."""
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            os.setgroups([])
            os.setgid(NOBODY)
            os.setuid(NOBODY)
            action()
            code = 0
        except BaseException:
            traceback.print_exc()
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0, "the action as nobody failed"


@pytest.fixture
def shared(tmp_path):
    """A sticky world-writable directory (as /tmp is) that nobody can reach: tmp_path's parents are root's 0700."""
    directory = Path(tempfile.mkdtemp(prefix="imu-shared-", dir="/tmp"))
    directory.chmod(0o1777)
    yield directory
    shutil.rmtree(directory, ignore_errors=True)


def _cli(capsys, *args):
    from imu_emulator.cli import main
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.err


def _one_error_line(code: int, err: str, *expected: str) -> str:
    assert code == 2, err
    lines = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1 and "Traceback" not in err, err
    for text in expected:
        assert text in lines[0], lines[0]
    return lines[0]


def _root_secret_file(tmp_path: Path) -> Path:
    """A root-owned 0600 file: what a planted link points at."""
    target = tmp_path / "secret.conf"
    target.write_text("root only\n")
    target.chmod(0o600)
    return target


# --- the cache ------------------------------------------------------------------------------------

@as_root
@pytest.mark.parametrize("how", ["owned by nobody", "world-writable", "group-writable"])
def test_a_cache_not_the_users_alone_is_refused_with_the_fix(shared, tmp_path, monkeypatch, capsys, how):
    root = shared / "cache"
    if how == "owned by nobody":
        as_nobody(lambda: os.mkdir(root, 0o755))
    else:
        root.mkdir()
        root.chmod(0o777 if how == "world-writable" else 0o775)
    monkeypatch.setenv("IMU_EMULATOR_CACHE", str(root))
    monkeypatch.setattr(kernels, "_loaded", {})
    code, err = _cli(capsys, "generate", REPO / "examples/helix.toml", "-o", tmp_path / "out.csv", "--quiet")
    line = _one_error_line(code, err, str(root), "not trusted", "fix: rm -rf")
    assert ("uid 65534" in line) == (how == "owned by nobody"), line
    assert not (tmp_path / "out.csv").exists()


@as_root
def test_an_entry_owned_by_another_user_is_refused_unread(tmp_path, monkeypatch):
    from imu_emulator.files import trust
    monkeypatch.setenv("IMU_EMULATOR_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(kernels, "_loaded", {})
    scene = load_scene(REPO / "examples/helix.toml")
    key = cache.scene_key(scene, True, False)
    entry = trust.trusted_dir("kernels") / key
    entry.mkdir()
    planted = tmp_path / "PWNED"
    (entry / "kernel.py").write_text(cache.sealed(key, f"open({str(planted)!r}, 'w')\n"))
    os.chown(entry, NOBODY, NOBODY)
    with pytest.raises(trust.UntrustedCache, match=f"{entry}: kernel cache not trusted: owned by uid 65534"):
        kernels.compile_kernel(scene)
    assert not planted.exists()


def test_an_entry_file_gone_between_listing_and_check_is_skipped_the_rest_still_checked(tmp_path, monkeypatch):
    """Two runs sharing a cache (xdist workers, parallel CI jobs): one lists an entry while the other renames its
    temporary file into place. The vanished name is skipped, not raised; the walk goes on and still refuses a
    file others can write (the rule of check_private, checked on the entry's real files)."""
    from imu_emulator.files import trust
    entry = tmp_path / "entry"
    (entry / "__pycache__").mkdir(parents=True, mode=0o700)
    entry.chmod(0o700)
    (entry / "kernel.py").write_text("x = 1\n")
    real_walk = os.walk

    def walk_listing_a_vanished_temp(top):
        for dirpath, dirnames, filenames in real_walk(top):
            yield dirpath, dirnames, [".kernel.o.1234.tmp", *filenames]
    monkeypatch.setattr(trust.os, "walk", walk_listing_a_vanished_temp)
    trust.check_tree(entry)
    (entry / "kernel.py").chmod(0o664)
    with pytest.raises(trust.UntrustedCache, match="kernel.py: kernel cache not trusted: writable by group"):
        trust.check_tree(entry)


def test_the_secret_is_created_0600_and_refused_otherwise(tmp_path, monkeypatch):
    from imu_emulator.files import trust
    monkeypatch.setenv("IMU_EMULATOR_CACHE", str(tmp_path / "cache"))
    key = trust.secret()
    path = tmp_path / "cache" / trust.SECRET_NAME
    assert len(key) == 32 and stat.S_IMODE(path.stat().st_mode) == 0o600
    assert stat.S_IMODE((tmp_path / "cache").stat().st_mode) == 0o700
    trust._secrets.clear()
    path.chmod(0o644)
    with pytest.raises(trust.UntrustedCache, match=f"{path}: .*readable by others .*fix: rm -rf"):
        trust.secret()


def _planted_source(planted: Path) -> str:
    # what the planted entry would do if it ran: leave a file behind, then fail like a kernel that does not load
    return f"open({str(planted)!r}, 'w').close()\n"


@pytest.mark.slow
@pytest.mark.parametrize("plant", ["edited, with the old sha256 line", "sealed by another cache root"])
def test_an_entry_not_sealed_by_this_cache_is_regenerated_without_running_it(tmp_path, monkeypatch, plant):
    """The issue's reproduction: kernel.py carrying its own checksum line ran. Now neither a checksum anyone can
    compute nor a valid seal of another cache (another secret) makes it run."""
    import hashlib
    from imu_emulator.runtime.simulation import Simulation
    scene = load_scene(REPO / "examples/helix.toml")
    key = cache.scene_key(scene, True, False)
    planted = tmp_path / "PWNED"
    source = _planted_source(planted)
    if plant.startswith("edited"):
        text = "# sha256 " + hashlib.sha256(source.encode()).hexdigest() + "\n" + source
    else:
        monkeypatch.setenv("IMU_EMULATOR_CACHE", str(tmp_path / "other"))
        text = cache.sealed(key, source)
    monkeypatch.setenv("IMU_EMULATOR_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(kernels, "_loaded", {})
    entry = tmp_path / "cache" / "kernels" / key
    entry.mkdir(parents=True)
    (entry / "kernel.py").write_text(text)
    out = Simulation(scene).block(0, 10)
    assert not planted.exists(), "the planted entry ran"
    assert out.accel.shape[-1] == 3
    assert cache.entry_source(entry / "kernel.py", key) is not None      # regenerated, sealed by this cache
    control = entry.with_name("control.py")      # the planted source sealed by this cache is what would run
    control.write_text(cache.sealed(key, source))
    assert cache.entry_source(control, key) == cache.sealed(key, source)


# --- outputs --------------------------------------------------------------------------------------

def _plant_link(shared: Path, name: str, target: Path) -> Path:
    link = shared / name
    as_nobody(lambda: os.symlink(target, link))
    assert link.lstat().st_uid == NOBODY
    return link


@as_root
@pytest.mark.parametrize("command", ["generate -o", "stream --to file:", "stream --stats-json", "stream --link"])
def test_a_link_another_user_planted_in_a_sticky_dir_is_refused(shared, tmp_path, capsys, command):
    """The issue's reproduction: a root-owned 0600 file was replaced through nobody's link in a 1777 directory."""
    target = _root_secret_file(tmp_path)
    link = _plant_link(shared, "out.csv" if command.startswith("generate") else "out.bin", target)
    scene = REPO / "examples/helix.toml"
    if command == "generate -o":
        code, err = _cli(capsys, "generate", scene, "-o", link, "--quiet")
    else:
        to = {"stream --to file:": [f"file:{link}"], "stream --stats-json": [f"file:{tmp_path / 'x.bin'}", "--stats-json", link],
              "stream --link": ["pty", "--link", link]}[command]
        result = subprocess.run([sys.executable, "-m", "imu_emulator", "stream", scene, "--format", "mavlink-highres",
                                 "--speed", "0", "--to", *to], capture_output=True, text=True, cwd=REPO, timeout=300)
        code, err = result.returncode, result.stderr
    assert target.read_bytes() == b"root only\n" and stat.S_IMODE(target.stat().st_mode) == 0o600, "written through"
    assert os.readlink(link) == str(target)
    _one_error_line(code, err, str(link), "owned by uid 65534")


def test_a_link_of_ones_own_is_replaced_itself_never_its_target(tmp_path):
    target = _root_secret_file(tmp_path)
    link = tmp_path / "out.csv"
    link.symlink_to(target)
    with AtomicOutput(link) as out:
        out.write("new\n")
    assert not link.is_symlink() and link.read_text() == "new\n"
    assert target.read_text() == "root only\n"


def test_a_capture_replaces_a_link_itself(tmp_path):
    from imu_emulator.live.transport.capture import RawFileTransport
    target = _root_secret_file(tmp_path)
    link = tmp_path / "capture.bin"
    link.symlink_to(target)
    capture = RawFileTransport(str(link))
    capture.send(b"\x01\x02")
    capture.close()
    assert not link.is_symlink() and link.read_bytes() == b"\x01\x02"
    assert target.read_text() == "root only\n"


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_a_stale_part_of_a_dead_writer_is_removed_a_live_ones_kept(tmp_path):
    out = tmp_path / "out.csv"
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        dead = tmp_path / f".out.csv.{_dead_pid()}.0badc0de.part"
        live = tmp_path / f".out.csv.{sleeper.pid}.0badc0de.part"
        other = tmp_path / f".other.csv.{_dead_pid()}.0badc0de.part"        # another output's: not ours to judge
        for part in (dead, live, other):
            part.write_text("half")
        with AtomicOutput(out) as file:
            file.write("whole\n")
        assert not dead.exists() and live.exists() and other.exists()
        assert out.read_text() == "whole\n"
    finally:
        sleeper.kill()
        sleeper.wait()


def test_a_part_left_by_a_killed_generate_is_removed_by_the_next(tmp_path, capsys, monkeypatch):
    """SIGKILL in the middle of `generate` (the part written, the rename not reached), then a second run."""
    monkeypatch.setenv("IMU_EMULATOR_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "out.csv"
    script = ("import os, signal, sys; from imu_emulator.output.atomic import AtomicOutput; "
              f"o = AtomicOutput({str(out)!r}); o.write('half'); o.file.flush(); os.kill(os.getpid(), signal.SIGKILL)")
    killed = subprocess.run([sys.executable, "-c", script], cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert killed.returncode == -9
    parts = list(tmp_path.glob(".out.csv.*.part"))
    assert len(parts) == 1
    code, err = _cli(capsys, "generate", REPO / "examples/helix.toml", "-o", out, "--quiet")
    assert code == 0, err
    assert not list(tmp_path.glob(".out.csv.*.part")) and out.exists()


# --- a path a running stream holds ----------------------------------------------------------------

def _holding(path: Path) -> subprocess.Popen:
    """Another process holding `path` as a stream would (the lock beside it), until killed."""
    script = (f"import time; from imu_emulator.live.transport.capture import RawFileTransport; "
              f"RawFileTransport({str(path)!r}); print('held', flush=True); time.sleep(60)")
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=REPO, stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.stdout.readline() == "held\n"
    return proc


@pytest.mark.parametrize("kind", ["pty --link", "file:"])
def test_a_second_stream_in_one_process_on_a_held_path_gets_a_clear_error(tmp_path, kind):
    from imu_emulator.live.transport.capture import RawFileTransport
    from imu_emulator.live.transport.pty import PtyPair
    path = tmp_path / "imu0"
    first = PtyPair(str(path)) if kind == "pty --link" else RawFileTransport(str(path))
    if kind == "pty --link":
        first.publish()                     # what a stream does once it can answer
    before = os.readlink(path) if kind == "pty --link" else None
    try:
        with pytest.raises(TargetError, match="in use by another running stream"):
            PtyPair(str(path)) if kind == "pty --link" else RawFileTransport(str(path))
        if kind == "pty --link":
            assert os.readlink(path) == before, "the second stream took over the first one's link"
    finally:
        first.close()
    # released: the next stream gets it
    again = PtyPair(str(path)) if kind == "pty --link" else RawFileTransport(str(path))
    again.close()


def test_a_second_stream_process_is_refused_with_one_line(tmp_path):
    capture = tmp_path / "imu1.log"
    holder = _holding(capture)
    try:
        result = subprocess.run([sys.executable, "-m", "imu_emulator", "stream", REPO / "examples/helix.toml",
                                 "--format", "mavlink-highres", "--speed", "0", "--to", f"file:{capture}"],
                                capture_output=True, text=True, cwd=REPO, timeout=scaled(300))
        _one_error_line(result.returncode, result.stderr, str(capture),
                        f"in use by another running stream (pid {holder.pid}")
    finally:
        holder.kill()
        holder.wait()


def test_hil_bench_writes_no_fixed_name_in_tmp():
    text = (REPO / "examples/hil_bench.toml").read_text()
    assert "/tmp" not in "".join(line for line in text.splitlines() if not line.startswith("#"))


@pytest.mark.slow
def test_numbas_pickled_index_lives_only_inside_the_entry(tmp_path, monkeypatch):
    """With NUMBA_CACHE_DIR set numba would keep (and later unpickle) the kernel's index there, outside the
    checked entry: the kernel's dispatcher caches inside the entry or not at all."""
    from numba.core import config
    from imu_emulator.runtime.simulation import Simulation
    monkeypatch.setenv("IMU_EMULATOR_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("IMU_EMULATOR_NATIVE", "0")       # numba's dispatcher, which is what uses its cache
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setattr(kernels, "_loaded", {})
    scene = load_scene(REPO / "examples/helix.toml")
    Simulation(scene).block(0, 10)
    assert not list((tmp_path / "numba").rglob("*.nbi")), "numba's index was written outside the entry"
