"""Parquet output: the same doubles as the whole-run NPZ, the run's identity in the footer, and memory that does
not grow with the duration (block by block)."""
import json
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

from imu_emulator.cli import main
from imu_emulator.runtime.progress import bar
from imu_emulator.runtime.memory import memory_bytes
from tests.support.paths import EXAMPLES



def test_generate_parquet_equals_npz_bit_for_bit(tmp_path, monkeypatch):
    scene = str(EXAMPLES / "two_imus.toml")
    assert main(["generate", scene, "-o", str(tmp_path / "o.parquet"), "--quiet", "--truth", "--block", "999"]) == 0
    assert main(["generate", scene, "-o", str(tmp_path / "o.npz"), "--quiet", "--truth"]) == 0
    table = pq.read_table(tmp_path / "o.parquet")
    whole = np.load(tmp_path / "o.npz")
    n = whole["t"].shape[0]
    assert table.num_rows == 2 * n
    # rows interleave the IMUs sample by sample, as in CSV
    assert table.column("imu").to_pylist()[:4] == ["imu0", "imu1", "imu0", "imu1"]
    assert np.array_equal(table.column("t_ns").to_numpy()[::2], np.rint(whole["t"] * 1e9).astype(np.int64))
    for m in range(2):
        rows = slice(m, None, 2)
        for i, axis in enumerate("xyz"):
            assert np.array_equal(table.column(f"a{axis}").to_numpy()[rows], whole["accel"][m, :, i])
            assert np.array_equal(table.column(f"g{axis}").to_numpy()[rows], whole["gyro"][m, :, i])
            assert np.array_equal(table.column(f"p{axis}").to_numpy()[rows], whole["position"][:, i])
    assert table.schema.field("t_ns").type == "int64"


def test_parquet_footer_names_scene_seed_and_versions(tmp_path, monkeypatch):
    text = (EXAMPLES / "two_imus.toml").read_text().replace("[scene]\n", "[scene]\nseed = {seed}\n", 1)
    digests = []
    for seed in (5, 6):
        scene = tmp_path / f"s{seed}.toml"
        scene.write_text(text.replace("{seed}", str(seed)))
        assert main(["generate", str(scene), "-o", str(tmp_path / f"{seed}.parquet"), "--quiet"]) == 0
        meta = json.loads(pq.read_schema(tmp_path / f"{seed}.parquet").metadata[b"imu_emulator"])
        assert meta["seed"] == seed
        assert meta["versions"]["numpy"] == np.__version__
        assert meta["imu_names"] == ["imu0", "imu1"]
        digests.append(meta["scene_sha256"])
    # the hash is the scene's, not the seed's: two seeds of one scene share it
    assert digests[0] == digests[1] and len(digests[0]) == 64


def test_progress_bar_shows_rate_and_time_left():
    # 250 of 1000 in 5 s: 50 per second, 750 more take 15 s
    assert bar(250, 1000, 5.0, "samples", width=4).endswith("[#...] 250/1000 samples, 50 samples/s, 0:00:15 left")


SCENE_4IMU = """
[scene]
rate_hz = 1000
duration_s = {duration}
[trajectory]
shape = "circle"
radius_m = 20.0
frequency_hz = 0.1
[attitude]
mode = "tangent"
[[imu]]
name = "a"
gyro = {{ noise_density = "0.01 deg/s/sqrt(Hz)" }}
[[imu]]
name = "b"
[[imu]]
name = "c"
[[imu]]
name = "d"
[effects]
gravity = true
noise = true
"""

# Runs `generate` in a fresh process and records the resident set size at every block (through the progress
# hook, which the block loop calls after writing each block; --quiet only hides the bar).
_RSS_TRACE = """
import json, sys
from imu_emulator.runtime import progress
from imu_emulator.cli import main
trace = []
def record(self, done, total):
    with open("/proc/self/status") as f:
        rss = int(f.read().split("VmRSS:")[1].split()[0]) * 1024
    trace.append((done / total, rss))
progress.Progress.__call__ = record
assert main(["generate", sys.argv[1], "-o", sys.argv[2], "--quiet", "--block", "4096"]) == 0
print(json.dumps(trace))
"""


@pytest.mark.parametrize("suffix, flat", [(".parquet", True), (".csv", True), (".npz", False)])
def test_generate_memory_stays_flat_while_it_runs(tmp_path, monkeypatch, suffix, flat):
    """Parquet and CSV stay flat; NPZ, which holds the run by design, grows (and shows the check can fail)."""
    scene = tmp_path / "long.toml"
    scene.write_text(SCENE_4IMU.format(duration=320))
    out = subprocess.run([sys.executable, "-c", _RSS_TRACE, str(scene), str(tmp_path / f"run{suffix}")],
                         capture_output=True, text=True, check=True)
    trace = json.loads(out.stdout.splitlines()[-1])
    at_quarter = next(rss for fraction, rss in trace if fraction >= 0.25)
    at_end = trace[-1][1]
    # Holding the samples would add the last 75 % of the run's arrays (t + 4 IMUs x 6 doubles per sample:
    # 0.75 x 64 MB = 48 MB) between the two readings, more with the writer's copies; block by block, RSS is
    # set by one block (4096 samples: 0.8 MB) and the libraries. A third of that growth (16 MB) separates
    # the two with room for allocator noise.
    growth_if_held = 0.75 * memory_bytes(320_000, 4, quat=False, truth=False)
    assert (at_end - at_quarter < growth_if_held / 3) == flat, (at_quarter, at_end, trace[::10])


def test_parquet_carries_the_increments_as_npz_does(tmp_path, monkeypatch):
    scene = str(EXAMPLES / "two_imus.toml")
    for suffix in (".parquet", ".npz"):
        assert main(["generate", scene, "-o", str(tmp_path / f"o{suffix}"), "--quiet", "--increments"]) == 0
    table = pq.read_table(tmp_path / "o.parquet")
    whole = np.load(tmp_path / "o.npz")
    for m in range(2):
        for i, axis in enumerate("xyz"):
            assert np.array_equal(table.column(f"dtheta_{axis}").to_numpy()[m::2], whole["dtheta"][m, :, i])
            assert np.array_equal(table.column(f"dvel_{axis}").to_numpy()[m::2], whole["dvel"][m, :, i])
