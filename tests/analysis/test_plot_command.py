"""`imu-emulator plot`: a PNG for every example, with axes that hold the whole trajectory."""
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from imu_emulator.analysis import plotting  # noqa: E402
from imu_emulator.cli import main  # noqa: E402
from tests.support.paths import REPO

ROOT = REPO
EXAMPLES = sorted((ROOT / "examples").glob("*.toml"))
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"



def _assert_png(path: Path):
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE and len(data) > 10_000


def _axes_hold(fig, position):
    ax3d = next(ax for ax in fig.axes if ax.name == "3d")
    for axis, limits in zip(range(3), (ax3d.get_xlim3d(), ax3d.get_ylim3d(), ax3d.get_zlim3d())):
        lo, hi = min(limits), max(limits)
        assert lo <= position[:, axis].min() and position[:, axis].max() <= hi, "xyz"[axis]


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_plot_every_example(path, tmp_path):
    data = plotting.from_scene(str(path))
    png = tmp_path / "out.png"
    fig = plotting.draw(data, png)
    _assert_png(png)
    _axes_hold(fig, data.position)
    # one 3-D view plus specific force and angular rate per IMU, and a realized-bias axis beside each triad whose
    # error effects make a bias (examples/drone_imu.toml, earth_turn.toml)
    twins = sum(bias is not None for bias in (data.accel_bias, data.gyro_bias)) * len(data.imu_names)
    assert len(fig.axes) == 1 + 2 * len(data.imu_names) + twins
    assert sum(ax.get_ylabel().startswith("realized bias") for ax in fig.axes) == twins


def test_plot_cli_on_scene_and_on_generate_outputs(tmp_path, capsys):
    scene = str(ROOT / "examples" / "two_imus.toml")
    assert main(["plot", scene, "-o", str(tmp_path / "scene.png")]) == 0
    _assert_png(tmp_path / "scene.png")
    for name, truth in (("run.npz", ["--truth"]), ("run.csv", ["--truth"]), ("bare.npz", [])):
        assert main(["generate", scene, "-o", str(tmp_path / name), "--quiet", *truth]) == 0
        assert main(["plot", str(tmp_path / name), "-o", str(tmp_path / (name + ".png"))]) == 0
        _assert_png(tmp_path / (name + ".png"))
    err = capsys.readouterr().err
    assert "bare.npz has no trajectory" in err
    csv = plotting.from_output(str(tmp_path / "run.csv"))
    npz = plotting.from_output(str(tmp_path / "run.npz"))
    assert csv.imu_names == npz.imu_names == ["imu0", "imu1"]
    np.testing.assert_allclose(csv.accel, npz.accel, rtol=1e-15)
    np.testing.assert_allclose(csv.position, npz.position, rtol=1e-15)


def test_plot_bad_input_is_one_error_line(tmp_path, capsys):
    assert main(["plot", str(tmp_path / "missing.toml")]) == 2
    assert main(["plot", str(ROOT / "examples" / "helix.toml"), "-o", str(tmp_path / "x.jpg")]) == 2
    (tmp_path / "junk.txt").write_text("hello")
    assert main(["plot", str(tmp_path / "junk.txt"), "-o", str(tmp_path / "j.png")]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 3 and all(line.startswith("error: ") for line in lines)


def test_plot_of_a_truth_output_overlays_each_imus_realized_bias(tmp_path):
    """generate --truth of a scene with error effects writes the realized biases; the plot of that output (NPZ
    and CSV) holds them, per IMU and axis, as the dashed lines of a right-hand axis beside each signal."""
    scene = tmp_path / "biased.toml"
    scene.write_text(
        (ROOT / "examples" / "two_imus.toml").read_text().replace("[effects]", "[effects]\nbias = true\n"
                                                                  "random_walk = true")
        + '\n[imu.gyro]\nbias = ["0.1 deg/s", 0, "-0.2 deg/s"]\nrandom_walk = "20 deg/h/sqrt(h)"\n'
        + '[imu.accel]\nbias = [0.05, -0.02, 0.0]\n')
    for name in ("run.npz", "run.csv"):
        assert main(["generate", str(scene), "-o", str(tmp_path / name), "--quiet", "--truth"]) == 0
        data = plotting.from_output(str(tmp_path / name))
        with np.load(tmp_path / "run.npz") as npz:
            np.testing.assert_allclose(data.gyro_bias, npz["gyro_bias"], rtol=1e-15, atol=0)
            np.testing.assert_allclose(data.accel_bias, npz["accel_bias"], rtol=1e-15, atol=0)
        # imu0 has no error terms (its bias is 0, not imu1's); imu1's gyro x starts at its constant bias
        assert not data.gyro_bias[0].any() and not data.accel_bias[0].any()
        assert abs(data.gyro_bias[1, 0, 0] - np.radians(0.1)) < 1e-12 and data.accel_bias[1, 0, 0] == 0.05
        fig = plotting.draw(data, tmp_path / (name + ".png"))
        _assert_png(tmp_path / (name + ".png"))
        step = plotting._decimate(len(data.t))
        for m in range(len(data.imu_names)):
            for bias in (data.accel_bias, data.gyro_bias):
                for axis in range(3):
                    expected = bias[m, step, axis]
                    assert any(line.get_label() == f"bias {'xyz'[axis]}" and line.get_linestyle() == "--"
                               and np.array_equal(line.get_ydata(), expected)
                               for ax in fig.axes for line in ax.get_lines()), (name, m, axis)
        assert len(fig.axes) == 1 + 4 * len(data.imu_names)   # each signal axes has its bias twin


def test_plot_of_a_parquet_output_equals_that_of_its_csv(tmp_path):
    """`plot` reads Parquet (the large-run format, the only one `batch` writes) through the same column schema
    as the CSV: signals, trajectory, attitude and realized biases of the same run agree; time stamps to the ns
    Parquet stores them in."""
    scene = tmp_path / "biased.toml"
    scene.write_text(
        (ROOT / "examples" / "two_imus.toml").read_text().replace("[effects]", "[effects]\nbias = true\n")
        + '\n[imu.gyro]\nbias = ["0.1 deg/s", 0, "-0.2 deg/s"]\n')
    data = {}
    for name in ("run.csv", "run.parquet"):
        assert main(["generate", str(scene), "-o", str(tmp_path / name), "--quiet", "--truth"]) == 0
        assert main(["plot", str(tmp_path / name), "-o", str(tmp_path / (name + ".png"))]) == 0
        _assert_png(tmp_path / (name + ".png"))
        data[name] = plotting.from_output(str(tmp_path / name))
    csv, parquet = data["run.csv"], data["run.parquet"]
    assert parquet.imu_names == csv.imu_names == ["imu0", "imu1"] and parquet.frame == csv.frame
    np.testing.assert_allclose(parquet.t, csv.t, rtol=0, atol=1e-9)
    for field in ("accel", "gyro", "position", "euler", "accel_bias", "gyro_bias"):
        assert getattr(parquet, field) is not None, field
        np.testing.assert_array_equal(getattr(parquet, field), getattr(csv, field), err_msg=field)


def test_plot_of_an_output_draws_the_frame_its_conventions_state_and_says_when_none_is_stated(tmp_path):
    """examples/earth_turn.toml (NED, 1000 m up: pz = -1000) written with --truth states its frame in its
    conventions: down is drawn down (the z axis inverted, as for the scene itself). A flat scene's output states
    its frame too (issue 24: every file states its frames; two_imus.toml is NED); a file stating none gets a title
    that says so instead of naming a frame it cannot know."""
    import tomllib
    earth = tomllib.loads((ROOT / "examples" / "earth_turn.toml").read_text())
    earth["scene"]["duration_s"] = 2.0
    earth_path = tmp_path / "earth.toml"
    earth_path.write_text(_toml(earth))
    flat = str(ROOT / "examples" / "two_imus.toml")
    # the CSV also carries increments: its reader once refused the Earth and increment columns
    for scene, name, more in ((str(earth_path), "earth.csv", ["--increments"]), (str(earth_path), "earth.npz", []),
                              (flat, "flat.csv", [])):
        assert main(["generate", scene, "-o", str(tmp_path / name), "--quiet", "--truth", *more]) == 0
    for name in ("earth.csv", "earth.npz"):
        data = plotting.from_output(str(tmp_path / name))
        assert data.frame == "NED"
        fig = plotting.draw(data, tmp_path / (name + ".png"))
        ax3d = next(ax for ax in fig.axes if ax.name == "3d")
        low, high = ax3d.get_zlim3d()
        assert low > high and "NED frame" in ax3d.get_title()
    data = plotting.from_output(str(tmp_path / "flat.csv"))
    fig = plotting.draw(data, tmp_path / "flat.png")
    ax3d = next(ax for ax in fig.axes if ax.name == "3d")
    assert data.frame == "NED" and "NED frame" in ax3d.get_title()      # every output states its frame now


def _toml(table: dict) -> str:
    """Just enough TOML for a scene: tables of scalars, inline tables and lists, arrays of tables."""
    def value(v):
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, bool):
            return "true" if v else "false"
        return repr(v) if isinstance(v, (int, float)) else f'"{v}"'
    out = []
    for key, body in table.items():
        for item in (body if isinstance(body, list) else [body]):
            out.append(f"[[{key}]]" if isinstance(body, list) else f"[{key}]")
            out += [f"{k} = {value(v)}" for k, v in item.items()]
    return "\n".join(out) + "\n"
