"""`imu-emulator check`: validates without running, describes the scene, exits 2 with one line on a bad one."""
import math
import os

import numpy as np
import pytest

from imu_emulator.cli import main
from tests.support.paths import REPO

ROOT = REPO
EXAMPLES = sorted((ROOT / "examples").glob("*.toml"))

SMALL = """
[scene]
rate_hz = 100
duration_s = 2.0
[trajectory]
shape = "circle"
radius_m = 2.0
frequency_hz = 0.5
[attitude]
mode = "tangent"
[[imu]]
name = "front"
lever_arm_m = [0.2, 0.0, 0.0]
[effects]
gravity = true
lever_arm = true
"""


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_check_every_example(path, capsys):
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"scene {path}: valid")
    for word in ("frame ", "samples at", "trajectory", "effects", "imu ", "NPZ", "CSV", "kernel"):
        assert word in out
    import tomllib
    raw = tomllib.loads(path.read_text())
    for imu in raw["imu"]:
        assert f"imu {imu['name']}:" in out
    assert out.count("  stream  ") == len(raw.get("stream", []))


def test_check_describes_what_generate_then_does(tmp_path, capsys, fresh_cache):
    """Sample count = duration x rate; the NPZ size estimate matches the file `generate` writes (its arrays' bytes
    plus at most run_size.NPZ_ARRAY_OVERHEAD per array); the CSV bound is above the real CSV; the kernel is
    reported compiled after `generate` compiled it, and not before."""
    scene = tmp_path / "small.toml"
    scene.write_text(SMALL)
    assert main(["check", str(scene)]) == 0
    before = capsys.readouterr().out
    assert "200 samples at 100 Hz" in before
    assert "generate: not compiled yet" in before
    assert main(["generate", str(scene), "-o", str(tmp_path / "o.npz"), "--quiet"]) == 0
    assert main(["generate", str(scene), "-o", str(tmp_path / "o.csv"), "--quiet"]) == 0
    assert main(["check", str(scene)]) == 0
    after = capsys.readouterr().out
    assert "generate: compiled in the cache" in after and "stream: not compiled yet" in after
    from imu_emulator.commands.check import output_sizes
    from imu_emulator.scene.load import load_scene
    sizes = output_sizes(load_scene(scene), truth=False)
    data = np.load(tmp_path / "o.npz")
    payload = sum(data[k].nbytes for k in data.files)
    from imu_emulator.output.formats.npz import NPZ_ARRAY_OVERHEAD
    assert payload < os.path.getsize(tmp_path / "o.npz") <= sizes["NPZ"] <= payload + NPZ_ARRAY_OVERHEAD * len(data.files)
    assert os.path.getsize(tmp_path / "o.csv") <= sizes["CSV bound"]


def test_check_reports_each_streams_link_budget(tmp_path, capsys):
    # mavlink-highres is 75 bytes per sample (MAVLink 2 header 10 + payload 63 + CRC 2): at 100 Hz 7,500 B/s
    # against 115200 baud / 10 = 11,520 B/s is 65 %.
    scene = tmp_path / "s.toml"
    scene.write_text(SMALL + '[[stream]]\nformat = "mavlink-highres"\nto = "serial:/dev/null@115200"\n')
    assert main(["check", str(scene)]) == 0
    out = capsys.readouterr().out
    assert "front as mavlink-highres to serial:/dev/null@115200: needs 7,500 B/s (75 B/sample); 65% of 11,520 B/s" in out


BAD = [
    (SMALL.replace("rate_hz = 100", "rate_hz = 0"), "scene.rate_hz: must be positive"),
    (SMALL.replace("radius_m = 2.0", ""), "trajectory.radius_m: missing"),
    (SMALL + "[[stream]]\nformat = \"nope\"\nto = \"pty\"\n", "unknown format 'nope'"),
    (SMALL + "[[stream]]\nformat = \"mavlink-highres\"\n", "stream[0].to: missing"),
    (SMALL + "[[stream]]\nimu = \"back\"\nformat = \"mavlink-highres\"\nto = \"pty\"\n", "stream[0].imu: no IMU named 'back'"),
    (SMALL + "[[stream]]\nformat = \"mavlink-highres\"\nto = \"pty\"\noptions = { sysid = 300 }\n", "sysid: must be 0..255"),
    # 75 B/sample at 100 Hz = 7,500 B/s > 9600 baud / 10 = 960 B/s
    (SMALL + "[[stream]]\nformat = \"mavlink-highres\"\nto = \"serial:/dev/null@9600\"\n", "needs more than its link"),
    ("[scene\n", "not valid TOML"),
]


@pytest.mark.parametrize("text, message", BAD)
def test_check_bad_scene_is_one_error_line_exit_2(text, message, tmp_path, capsys):
    scene = tmp_path / "bad.toml"
    scene.write_text(text)
    assert main(["check", str(scene)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err


def test_check_missing_file(capsys):
    assert main(["check", "/nonexistent/scene.toml"]) == 2
    assert "cannot read scene file" in capsys.readouterr().err


def test_check_lists_each_effects_nonzero_parameters_in_si_one_a_line(capsys):
    """examples/drone_imu.toml: the preset's and the scene's datasheet units, converted by hand (0.5 deg/s =
    0.5 pi/180 rad/s; 0.014 deg/s/sqrt(Hz) from the bosch-bmi088 preset; 10 mg = 0.0980665 m/s^2), each under
    its effect; a parameter left at zero (the constant bias) is not listed."""
    assert main(["check", str(ROOT / "examples" / "drone_imu.toml")]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    at = lines.index("  imu fc:")
    block = lines[at + 1:]
    assert block[0].split() == ["bias", "gyro.turn_on_bias_sd", "=", f"{0.5 * math.pi / 180:.6g}", "rad/s"]
    assert block[1].split() == ["accel.turn_on_bias_sd", "=", f"{0.010 * 9.80665:.6g}", "m/s^2"]
    noise = next(i for i, line in enumerate(block) if line.split()[0] == "noise")
    assert block[noise].split()[1:] == ["gyro.noise_density", "=", f"{0.014 * math.pi / 180:.6g}", "rad/s/sqrt(Hz)"]
    assert "gyro.bias =" not in out and "accel.bias =" not in out
