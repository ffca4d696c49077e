"""The pieces that give the SocketCAN tests a User Mode Linux where Debian bookworm's cannot start
(tests/support/uml): marking a symbol version weak, read back by binutils' readelf, and what boot.py will run."""
import os
import shutil
import subprocess
import sys

import pytest

from tests.support.paths import UML

sys.path.insert(0, str(UML))
import boot  # noqa: E402
import weak_version  # noqa: E402

pytestmark = pytest.mark.subprocess


@pytest.mark.skipif(not (shutil.which("gcc") and shutil.which("readelf")), reason="needs gcc and readelf")
def test_a_weakened_version_requirement_reads_weak_and_the_program_still_runs(tmp_path):
    source, program = tmp_path / "hello.c", tmp_path / "hello"
    source.write_text('#include <stdio.h>\nint main(void) { puts("hello"); return 0; }\n')
    subprocess.run(["gcc", "-o", str(program), str(source)], check=True)

    def needs():       # readelf -V: "Name: GLIBC_2.2.5  Flags: none  Version: 2"
        out = subprocess.run(["readelf", "-V", str(program)], capture_output=True, text=True, check=True).stdout
        return {line.split("Name:")[1].split()[0]: line.split("Flags:")[1].split()[0]
                for line in out.splitlines() if "Name: GLIBC_" in line}

    before = needs()
    version = sorted(before)[0]
    assert before[version] == "none"
    data = bytearray(program.read_bytes())
    assert weak_version.weaken(data, {version}) == 1
    program.write_bytes(bytes(data))
    after = needs()
    assert after[version] == "WEAK" and all(after[v] == before[v] for v in after if v != version)
    assert subprocess.run([str(program)], capture_output=True, text=True).stdout == "hello\n"


def test_weaken_refuses_what_is_not_a_64_bit_elf():
    with pytest.raises(ValueError, match="not a 64-bit little-endian ELF"):
        weak_version.weaken(bytearray(b"#!/bin/sh\n" + bytes(64)), {"GLIBC_2.38"})


def test_boot_runs_nothing_from_the_repository_that_others_may_write(tmp_path, monkeypatch):
    monkeypatch.setattr(boot, "REPO", tmp_path)
    os.chmod(tmp_path, 0o755)
    binary = tmp_path / "root/usr/bin/linux.uml"
    binary.parent.mkdir(parents=True)
    binary.write_text("")
    for p in (tmp_path / "root", tmp_path / "root/usr", binary.parent):
        os.chmod(p, 0o755)
    binary.chmod(0o755)
    assert boot._trusted(binary)
    binary.chmod(0o775)                          # group-writable: someone else could replace what runs
    assert not boot._trusted(binary)
    binary.chmod(0o755)
    os.chmod(tmp_path / "root/usr", 0o777)       # a directory on the way
    assert not boot._trusted(binary)
    os.chmod(tmp_path / "root/usr", 0o755)
    module_dir = tmp_path / "root/usr/lib/uml/modules/7.2.7/kernel"
    module_dir.mkdir(parents=True)
    for p in [module_dir, *module_dir.parents]:
        if p == tmp_path:
            break
        os.chmod(p, 0o755)
    assert boot._trusted_tree(tmp_path / "root/usr/lib/uml/modules")
    os.chmod(module_dir, 0o777)                  # the guest would load whatever someone put there
    assert not boot._trusted_tree(tmp_path / "root/usr/lib/uml/modules")
