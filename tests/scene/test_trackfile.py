"""Loading sampled tracks from CSV and NPZ, and the errors that point at the file, row and column."""
import dataclasses

import numpy as np
import pytest

from imu_emulator.numerics.derivatives import wrap_angles
from imu_emulator.errors import DataError
from imu_emulator.scene.trackfile import load_track, track_from_arrays
from tests.support.paths import EXAMPLES

EXAMPLE = EXAMPLES / "data" / "loop_track.csv"


def write(tmp_path, text, name="track.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def rejects(path, match):
    with pytest.raises(DataError, match=match):
        load_track(path)


def test_example_loop_track_gives_the_analytic_derivatives():
    track = load_track(EXAMPLE)
    assert track.t.shape == (1001,) and track.position.shape == (1001, 3) and track.euler.shape == (1001, 3)
    assert track.t[-1] == 5.0 and track.row_label(0) == "row 2"
    w = 2 * np.pi
    t_out = np.linspace(0.5, 4.5, 777)     # 1 kHz-ish, off the 200 Hz grid
    out = track.position_series("spline5").evaluate(t_out, 3)
    jerk = np.column_stack([0.8 * w ** 3 * np.sin(w * t_out), -0.8 * w ** 3 * np.cos(w * t_out),
                            0.3 * (3 * w) ** 3 * np.sin(3 * w * t_out)])
    np.testing.assert_allclose(out[3], jerk, rtol=0, atol=1e-4 * np.abs(jerk).max())
    attitude = track.attitude_series("central6").evaluate(t_out, 2)
    np.testing.assert_allclose(attitude[1][:, 2], -0.3 * w * np.sin(w * t_out), atol=1e-7)
    np.testing.assert_array_equal(attitude[1][:, :2], 0.0)


def test_csv_layout_freedom_and_line_numbers(tmp_path):
    text = ("\ufeff# exported by hand\n"
            " Yaw , t,X,y , z,roll,PITCH\n"
            "\n"
            "0.3, 0.0, 1.0, 2.0, 3.0, 0.1, 0.2\n"
            "# a comment in the middle\n"
            "0.4, 0.1, 1.5, 2.5, 3.5, 0.1, 0.2\n"
            "0.5, 0.2, 2.0, 3.0, 4.0, 0.1, 0.2\n")
    track = load_track(write(tmp_path, text))
    np.testing.assert_array_equal(track.t, [0.0, 0.1, 0.2])
    np.testing.assert_array_equal(track.position[1], [1.5, 2.5, 3.5])
    np.testing.assert_array_equal(track.euler[2], [0.1, 0.2, 0.5])
    assert [track.row_label(i) for i in range(3)] == ["row 4", "row 6", "row 7"]
    assert track.source.name == "track.csv"


def test_csv_without_attitude(tmp_path):
    track = load_track(write(tmp_path, "t,x,y,z\n0,0,0,0\n1,1,1,1\n"))
    assert track.euler is None
    with pytest.raises(DataError, match=r"^track\.csv: no roll, pitch, yaw in this track$"):
        track.attitude_series("spline5")


def test_track_is_frozen_and_read_only():
    track = load_track(EXAMPLE)
    with pytest.raises(dataclasses.FrozenInstanceError):
        track.t = np.zeros(3)
    with pytest.raises(ValueError):
        track.position[0, 0] = 1.0


def test_npz_layouts_match_the_csv(tmp_path):
    csv = load_track(EXAMPLE)
    split = tmp_path / "split.npz"
    np.savez(split, t=csv.t, x=csv.position[:, 0], y=csv.position[:, 1], z=csv.position[:, 2],
             roll=csv.euler[:, 0], pitch=csv.euler[:, 1], yaw=csv.euler[:, 2])
    stacked = tmp_path / "stacked.npz"
    np.savez(stacked, t=csv.t, position=csv.position, euler=csv.euler)
    bare = tmp_path / "bare.npz"
    np.savez(bare, t=csv.t, position=csv.position)
    for path in (split, stacked, bare):
        track = load_track(path)
        np.testing.assert_array_equal(track.t, csv.t)
        np.testing.assert_array_equal(track.position, csv.position)
        if path is bare:
            assert track.euler is None
        else:
            np.testing.assert_array_equal(track.euler, csv.euler)
        assert track.row_label(5) == "index 5"


def test_yaw_through_pi_is_unwrapped_for_differentiation(tmp_path):
    t = 0.01 * np.arange(200)
    yaw = wrap_angles(3.0 + 0.9 * t)              # jumps from +pi to -pi at t ~ 0.16
    path = tmp_path / "spin.npz"
    np.savez(path, t=t, position=np.zeros((200, 3)), euler=np.column_stack([0 * t, 0 * t, yaw]))
    rate = load_track(path).attitude_series("spline5").evaluate(t[5:-5], 2)[1][:, 2]
    np.testing.assert_allclose(rate, 0.9, rtol=1e-9)


# --- bad CSV ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("text, match", [
    ("", r"^track\.csv: empty file"),
    ("# only a comment\n\n", r"^track\.csv: empty file"),
    ("t,x,y,z\n", r"^track\.csv: no data rows after the header$"),
    ("t,x,y\n0,0,0\n", r"^track\.csv: missing column z \(need t, x, y, z\)$"),
    ("x,y,z\n0,0,0\n", r"^track\.csv: missing column t "),
    ("t,x,y,z,speed\n0,0,0,0,1\n", r"^track\.csv: unexpected column 'speed' \(expected t, x, y, z and "
                                   r"optionally roll, pitch, yaw or qw, qx, qy, qz\)$"),
    ("t,x,y,z,yaw\n0,0,0,0,1\n", r"^track\.csv: roll, pitch and yaw come together: found yaw but not "
                                 r"roll, pitch$"),
    ("t,x,y,z,x\n0,0,0,0,1\n", r"^track\.csv: column 'x' appears twice$"),
    ("t x y z\n0 0 0 0\n", r"^track\.csv: row 1: header 't x y z' has a single column; columns are "
                            r"separated by commas$"),
    ("t,x,,z\n0,0,0,0\n", r"^track\.csv: row 1: empty column name in the header$"),
    ("t,x,y,z\n0,0,0,0\n0.1,0,0\n", r"^track\.csv: row 3: 3 fields, the header has 4$"),
    ("t,x,y,z\n0,0,0,0\n0.1,0,0,0,\n", r"^track\.csv: row 3: 5 fields, the header has 4$"),
    ("t,x,y,z\n0,0,0,0\n\n0.1,0,1.2.3,0\n", r"^track\.csv: row 4, column 'y': '1\.2\.3' is not a number$"),
    ("t,x,y,z\n0,0,0,0\n0.1,0,,0\n", r"^track\.csv: row 3, column 'y': '' is not a number$"),
    ("t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,0,0\n0.1,0,0,0,0,nan,0\n",
     r"^track\.csv: row 3, column 'pitch': value nan is not finite$"),
    ("t,x,y,z\n0,0,0,0\ninf,0,0,0\n", r"^track\.csv: row 3: time stamp inf is not finite$"),
    ("t,x,y,z\n0.3,0,0,0\n0.35,0,0,0\n0.35,0,0,0\n",
     r"^track\.csv: row 4: time stamp 0\.35 not after previous 0\.35$"),
    ("t,x,y,z\n0.3,0,0,0\n0.35,0,0,0\n0.32,0,0,0\n",
     r"^track\.csv: row 4: time stamp 0\.32 not after previous 0\.35$"),
])
def test_bad_csv(tmp_path, text, match):
    rejects(write(tmp_path, text), match)


def test_bad_cell_found_in_a_long_file(tmp_path):
    rows = [f"{0.001 * k:.3f},{k},0,0" for k in range(5000)]
    rows[3210] = "3.210,0,x,0"
    rejects(write(tmp_path, "t,x,y,z\n" + "\n".join(rows) + "\n"), r"^track\.csv: row 3212, column 'y': 'x' ")


def test_central_differences_on_irregular_csv_name_the_row(tmp_path):
    rows = [f"{0.01 * k + (0.003 if k >= 7 else 0):.3f},0,0,0" for k in range(20)]
    track = load_track(write(tmp_path, "t,x,y,z\n" + "\n".join(rows) + "\n"))
    with pytest.raises(DataError, match=r"^track\.csv: method 'central4' needs uniformly spaced time "
                                        r"stamps; row 9 is "):
        track.position_series("central4")


def test_unreadable_files(tmp_path):
    rejects(tmp_path / "absent.csv", r"^absent\.csv: cannot read: ")
    rejects(write(tmp_path, "t,x,y,z\n", name="track.txt"),
            r"^track\.txt: unsupported track file type '\.txt' \(expected \.csv or \.npz\)$")
    rejects(write(tmp_path, "not a zip", name="junk.npz"), r"^junk\.npz: not a readable NPZ archive")


# --- bad NPZ ------------------------------------------------------------------------------------------------

def npz(tmp_path, **arrays):
    path = tmp_path / "track.npz"
    np.savez(path, **arrays)
    return path


def test_bad_npz(tmp_path):
    t = np.arange(4.0)
    p = np.zeros((4, 3))
    rejects(npz(tmp_path, t=t, x=t, y=t), r"^track\.npz: missing array z \(need t, x, y, z\)$")
    rejects(npz(tmp_path, t=t, x=t, y=t, z=t, heading=t), r"^track\.npz: unexpected array 'heading' ")
    rejects(npz(tmp_path, t=t, x=t, y=t, z=t, roll=t, pitch=t),
            r"^track\.npz: roll, pitch and yaw come together: found roll, pitch but not yaw$")
    rejects(npz(tmp_path, t=t, position=p, x=t), r"^track\.npz: unexpected array 'x' next to 'position'")
    rejects(npz(tmp_path, position=p), r"^track\.npz: missing array t$")
    rejects(npz(tmp_path, t=t, position=p[:3]), r"^track\.npz: array position has shape \(3, 3\), "
                                                 r"expected \(4, 3\) to match t$")
    rejects(npz(tmp_path, t=t, x=t, y=t[:3], z=t), r"^track\.npz: array y has shape \(3,\), expected \(4,\)")
    rejects(npz(tmp_path, t=p, position=p), r"^track\.npz: array t has shape \(4, 3\), expected one dimension$")
    rejects(npz(tmp_path, t=np.array(["a", "b"]), position=p[:2]), r"^track\.npz: array t has dtype <U1, "
                                                                   r"expected numbers$")
    rejects(npz(tmp_path, t=t[:0], position=p[:0]), r"^track\.npz: array t is empty$")
    q = p.copy()
    q[2, 1] = np.nan
    rejects(npz(tmp_path, t=t, position=q), r"^track\.npz: index 2, column 'y': value nan is not finite$")
    rejects(npz(tmp_path, t=np.array([0.0, 1.0, 1.0, 2.0]), position=p),
            r"^track\.npz: index 2: time stamp 1\.0 not after previous 1\.0$")


def test_tracks_from_arrays_are_checked_like_files():
    track = track_from_arrays(np.arange(10), np.zeros((10, 3)))
    assert track.euler is None and track.t.dtype == float and not track.t.flags.writeable
    assert track.position_series("gradient").evaluate([2.5], 3).shape == (4, 1, 3)
    with pytest.raises(DataError, match=r"^<arrays>: array euler has shape \(10, 2\), expected \(10, 3\)"):
        track_from_arrays(np.arange(10), np.zeros((10, 3)), np.zeros((10, 2)))
    t = np.arange(10.0)
    t[4] = 2.0
    with pytest.raises(DataError, match=r"^mine: index 4: time stamp 2\.0 not after previous 3\.0$"):
        track_from_arrays(t, np.zeros((10, 3)), source="mine")
