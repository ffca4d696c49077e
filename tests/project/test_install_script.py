"""install.sh --dry-run under stand-in commands: what it would do as root, as a user without sudo and where
there is no apt-get. The stand-ins (id, sudo, dpkg-query, apt-get) are shell scripts on a PATH of their own, so
the test needs neither root nor a Debian machine and changes nothing."""
from __future__ import annotations

import os
import shutil
import stat
import subprocess
from pathlib import Path

import pytest

from tests.support.paths import REPO

pytestmark = pytest.mark.subprocess

BASH = shutil.which("bash")
TOOLS = ("dirname", "sed", "grep", "env")        # real commands the script runs, linked into the stand-in PATH


def _stub(bin_dir: Path, name: str, body: str) -> None:
    path = bin_dir / name
    path.write_text(f"#!{BASH}\n{body}\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)


def _dry_run(tmp_path: Path, *, uid: int, sudo_ok: bool, apt: bool, installed: bool = False,
             venv: bool = False, uml: bool = False) -> subprocess.CompletedProcess:
    """Runs a copy of install.sh (it works in its own folder: no .venv there unless venv) with stand-ins."""
    tmp_path.mkdir(exist_ok=True)
    work = tmp_path / "checkout"
    work.mkdir()
    shutil.copy(REPO / "install.sh", work / "install.sh")
    if venv:
        (work / ".venv/bin").mkdir(parents=True)
        _stub(work / ".venv/bin", "python", "exit 0")
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in TOOLS:
        os.symlink(shutil.which(tool), bin_dir / tool)
    _stub(bin_dir, "id", f"echo {uid}")
    _stub(bin_dir, "sudo", "exit 0" if sudo_ok else "echo 'sudo: a password is required' >&2; exit 1")
    _stub(bin_dir, "dpkg-query", "echo 'install ok installed'" if installed else "exit 1")
    _stub(bin_dir, "python3", "exit 0")
    if apt:
        _stub(bin_dir, "apt-get", "echo 'apt-get ran in a dry run' >&2; exit 1")
    if uml:
        _stub(bin_dir, "linux.uml", "echo 'linux.uml ran in a dry run' >&2; exit 1")
    return subprocess.run([BASH, str(work / "install.sh"), "--dry-run"], capture_output=True, text=True,
                          env={"PATH": str(bin_dir), "HOME": str(tmp_path)})


def _apt_lines(out: str) -> list[str]:
    return [line.strip() for line in out.splitlines() if "apt-get" in line and line.strip().startswith("$")]


def test_root_installs_the_missing_packages_waiting_for_the_dpkg_lock(tmp_path):
    out = _dry_run(tmp_path, uid=0, sudo_ok=False, apt=True)
    assert out.returncode == 0, out.stderr
    update, install = _apt_lines(out.stdout)
    assert update == "$ apt-get -o DPkg::Lock::Timeout=600 update -qq"
    assert install == ("$ env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq "
                       "user-mode-linux kmod can-utils iproute2")
    assert "waiting up to 600 s" in out.stdout
    assert "$ python3 -m venv .venv" in out.stdout
    assert out.stdout.rstrip().endswith("dry run: nothing was changed")


def test_a_user_with_passwordless_sudo_goes_through_sudo(tmp_path):
    out = _dry_run(tmp_path, uid=1000, sudo_ok=True, apt=True)
    assert out.returncode == 0, out.stderr
    assert all(line.startswith("$ sudo -n ") for line in _apt_lines(out.stdout))
    assert len(_apt_lines(out.stdout)) == 2


def test_a_user_without_sudo_skips_the_debian_packages_and_goes_on(tmp_path):
    out = _dry_run(tmp_path, uid=1000, sudo_ok=False, apt=True)
    assert out.returncode == 0, out.stderr
    assert _apt_lines(out.stdout) == []
    assert "SocketCAN tests will be skipped: not root and sudo needs a password" in out.stdout
    assert "$ .venv/bin/python -m pip install -q -e .[test,plot]" in out.stdout


@pytest.mark.parametrize("case", ["no apt-get", "all installed"])
def test_nothing_to_install_says_why_and_a_second_run_keeps_the_venv(tmp_path, case):
    out = _dry_run(tmp_path, uid=0, sudo_ok=True, apt=case != "no apt-get", installed=True, venv=True)
    assert out.returncode == 0, out.stderr
    assert _apt_lines(out.stdout) == []
    expected = "no apt-get here; SocketCAN tests will be skipped" if case == "no apt-get" else "all installed already"
    assert expected in out.stdout
    assert ".venv exists: kept" in out.stdout and "-m venv" not in out.stdout


def test_user_mode_linux_is_checked_where_installed_and_skipped_where_not(tmp_path):
    """Whether Debian's UML starts on this CPU is checked by booting it, so a dry run only says how."""
    out = _dry_run(tmp_path / "with", uid=0, sudo_ok=True, apt=True, installed=True, uml=True)
    assert out.returncode == 0, out.stderr
    assert ("$ python3 tests/support/uml/boot.py --check   (where Debian's UML cannot start on this CPU: "
            "tests/support/uml/newer_uml.sh)") in out.stdout
    assert "linux.uml ran" not in out.stderr
    out = _dry_run(tmp_path / "without", uid=0, sudo_ok=True, apt=True, installed=True)
    assert "no linux.uml: SocketCAN tests will be skipped" in out.stdout


def test_an_unknown_option_is_one_line_and_exit_2(tmp_path):
    out = subprocess.run([BASH, str(REPO / "install.sh"), "--yes"], capture_output=True, text=True)
    assert out.returncode == 2
    assert out.stderr.strip() == "install.sh: unknown option '--yes' (see ./install.sh --help)"
