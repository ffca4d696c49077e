"""A picture of what a scene does (the original tool's Figure 1 and its signal plots), for `imu-emulator plot`.

Left: the trajectory of the reference point S in 3-D with the body drawn as a triangle (nose along body x) at
intervals along it, S and each IMU (S + R·lever arm) marked. Right: per IMU, specific force and angular rate against
time, with each IMU's realized bias (the error effects' terms, from `--truth`) overlaid dashed on a right-hand axis
when the run has one. Needs matplotlib (the `plot` extra); always renders with the Agg backend, so no display is needed.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from imu_emulator.errors import ImuEmulatorError
from imu_emulator.output.columns import BIAS, TRUTH

_MAX_LINE_POINTS = 20_000     # plotted per curve; more only blurs the line and slows the PNG
_TRIANGLES = 12


UNSTATED = "unstated"      # PlotData.frame of an output that does not say which frame its positions are in


@dataclass
class PlotData:
    t: np.ndarray                           # (n,)
    imu_names: list[str]
    accel: np.ndarray                       # (n_imu, n, 3)
    gyro: np.ndarray                        # (n_imu, n, 3)
    position: np.ndarray | None = None      # (n, 3) of S, navigation frame
    euler: np.ndarray | None = None         # (n, 3) roll, pitch, yaw of the body
    lever_arms: list | None = None          # per IMU, body frame (known only when plotting a scene)
    frame: str = "ENU"
    title: str = ""
    accel_bias: np.ndarray | None = None    # (n_imu, n, 3) realized bias of each triad (--truth, error effects on)
    gyro_bias: np.ndarray | None = None


def from_scene(path: str) -> PlotData:
    from imu_emulator.scene.load import load_scene
    from imu_emulator.runtime.simulation import Simulation
    return from_simulation(Simulation(load_scene(path), attitude=False, truth=True))


def from_simulation(sim) -> PlotData:
    """A whole run of a Simulation built with truth=True."""
    scene = sim.scene
    out = sim.run()
    arms = [imu.lever_arm_m if "lever_arm" in scene.effects else (0.0, 0.0, 0.0) for imu in scene.imus]
    return PlotData(out.t_s, list(scene.imu_names), out.accel, out.gyro, out.truth["position"], out.truth["euler"],
                    arms, scene.frame, f"{scene.path} ({scene.frame})", out.truth.get("accel_bias"),
                    out.truth.get("gyro_bias"))


def from_output(path: str) -> PlotData:
    """A Parquet, NPZ or CSV written by `generate` (with --truth for the trajectory), or a plain IMU log
    (imu_emulator.analysis.imulog reads and checks the signals; the trajectory comes from the truth columns when
    present)."""
    from imu_emulator.analysis.imulog import read_logs
    logs = read_logs(path)
    records = list(logs.values())
    n = min(len(r.t) for r in records)
    names = [name or Path(path).stem for name in logs]
    position, euler = _truth(Path(path), len(records))
    accel_bias, gyro_bias = _bias_truth(Path(path), len(records))
    return PlotData(records[0].t[:n], names, np.stack([r.accel[:n] for r in records]),
                    np.stack([r.gyro[:n] for r in records]), position, euler, title=str(path),
                    frame=_stated_frame(Path(path)),
                    accel_bias=None if accel_bias is None else accel_bias[:, :n],
                    gyro_bias=None if gyro_bias is None else gyro_bias[:, :n])


def _read_columns(path: Path, names: tuple[str, ...]):
    """The columns `names` of a `generate` output as one (rows, columns) array, rows IMU-fastest, read by the
    output's format (imu_emulator.output.formats); None when it lacks any of them."""
    from imu_emulator.output.formats import format_of
    record = format_of(path)
    found = record.read_columns(path, names) if record is not None and record.read_columns else None
    return None if found is None else np.column_stack([found[name] for name in names])


def _stated_frame(path: Path) -> str:
    """The frame the file's conventions state for px py pz (CSV '#' lines, NPZ "conventions", Parquet's footer:
    written for Earth scenes, imu_emulator.motion.earth_truth), else UNSTATED: a flat scene's output does not
    say whether z is up."""
    from imu_emulator.output.formats import format_of
    record = format_of(path)
    lines = record.read_conventions(path) if record is not None and record.read_conventions else []
    stated = next((line for line in lines if line.startswith("frame:")), "")
    return next((frame for frame in ("ECEF", "ECI", "NED", "ENU") if frame in stated), UNSTATED)


def _truth(path: Path, n_imu: int):
    """Position and roll, pitch, yaw of S from a `generate --truth` output, else (None, None)."""
    found = _read_columns(path, TRUTH.names[:3] + TRUTH.names[6:9])        # px py pz, roll pitch yaw
    if found is None:
        return None, None
    # rows run IMU-fastest (sample k of every IMU, then k+1): every n_imu-th row is one per sample
    return found[::n_imu, :3], found[::n_imu, 3:]


def _bias_truth(path: Path, n_imu: int):
    """Each IMU's realized accelerometer and gyro bias (n_imu, n, 3) from a `generate --truth` output of a scene
    with error effects (the bias columns bax..bgz), else (None, None)."""
    found = _read_columns(path, BIAS.names)
    if found is None:
        return None, None
    per_imu = found.reshape(-1, n_imu, 6).transpose(1, 0, 2)   # row k * n_imu + m: sample k of IMU m
    return per_imu[:, :, :3], per_imu[:, :, 3:]


def _decimate(n: int) -> slice:
    return slice(None, None, max(1, -(-n // _MAX_LINE_POINTS)))


def _rotations(euler: np.ndarray) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), body to navigation, for each row."""
    from imu_emulator.geo.rotations import euler_to_matrix
    return np.stack([euler_to_matrix(e) for e in euler])


def draw(data: PlotData, output: str | Path):
    """Render the figure to `output` (PNG) and return it (the test reads its axes)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    n_imu = len(data.imu_names)
    fig = plt.figure(figsize=(14, max(6, 3.2 * n_imu)))
    grid = fig.add_gridspec(2 * n_imu, 2, width_ratios=(1, 1.3))
    fig.suptitle(data.title)
    axes3d = None
    if data.position is not None:
        axes3d = fig.add_subplot(grid[:, 0], projection="3d")
        pos = data.position
        step = _decimate(len(pos))
        axes3d.plot(*pos[step].T, lw=1, color="0.4", label="path of S")
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        size = 0.06 * max(float(np.max(hi - lo)), 1.0)   # a body standing still is drawn 6 cm long
        picks = np.linspace(0, len(pos) - 1, _TRIANGLES).astype(int)
        rot = _rotations(data.euler[picks])
        body = np.array([[size, 0, 0], [-size / 2, size / 2, 0], [-size / 2, -size / 2, 0]])
        triangles = [pos[i] + body @ R.T for i, R in zip(picks, rot)]
        axes3d.add_collection3d(Poly3DCollection(triangles, facecolor="tab:orange", edgecolor="k", alpha=0.6))
        for R, i in zip(rot, picks):   # body x (nose) as a short red line
            axes3d.plot(*np.stack([pos[i], pos[i] + R[:, 0] * 1.5 * size]).T, color="tab:red", lw=1)
        axes3d.scatter(*pos[0], color="k", s=30, label="S (reference point), start")
        if data.lever_arms:
            R0 = rot[0]
            for name, arm in zip(data.imu_names, data.lever_arms):
                axes3d.scatter(*(pos[0] + R0 @ np.asarray(arm)), marker="^", s=40, label=f"IMU {name}")
        # Axes that contain the whole path and the triangles, equal scale on all three.
        centre, half = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2, 2 * size) + 2 * size
        axes3d.set_xlim3d(centre[0] - half, centre[0] + half)
        axes3d.set_ylim3d(centre[1] - half, centre[1] + half)
        z_limits = (centre[2] - half, centre[2] + half)
        axes3d.set_zlim3d(*(z_limits[::-1] if data.frame == "NED" else z_limits))   # NED: down is down
        axes3d.set_xlabel("x (m)")
        axes3d.set_ylabel("y (m)")
        axes3d.set_zlabel("z (m)")
        axes3d.set_title("trajectory (the file does not state its frame: z drawn up), body as triangles"
                         if data.frame == UNSTATED else f"trajectory ({data.frame} frame), body as triangles")
        axes3d.legend(loc="upper left", fontsize=7)
    step = _decimate(len(data.t))
    t = data.t[step]
    col = 1 if axes3d is not None else slice(None)
    for m, name in enumerate(data.imu_names):
        for row, (values, bias, label, unit) in enumerate(((data.accel, data.accel_bias, "specific force", "m/s²"),
                                                           (data.gyro, data.gyro_bias, "angular rate", "rad/s"))):
            ax = fig.add_subplot(grid[2 * m + row, col])
            for axis, color in zip(range(3), ("tab:red", "tab:green", "tab:blue")):
                ax.plot(t, values[m, step, axis], color=color, lw=1, label="xyz"[axis])
            ax.set_ylabel(f"{unit}")
            ax.set_title(f"IMU {name}: {label} (sensor frame)", fontsize=9)
            ax.legend(loc="upper right", fontsize=7, ncol=3)
            if bias is not None:   # far smaller than the signal: its own scale, on the right
                twin = ax.twinx()
                for axis, color in zip(range(3), ("tab:red", "tab:green", "tab:blue")):
                    twin.plot(t, bias[m, step, axis], color=color, lw=1, ls="--", label=f"bias {'xyz'[axis]}")
                twin.set_ylabel(f"realized bias ({unit})", fontsize=8)
                twin.legend(loc="lower right", fontsize=7, ncol=3)
            if m == n_imu - 1 and row == 1:
                ax.set_xlabel("t (s)")
    fig.tight_layout()
    from imu_emulator.output.atomic import save_figure
    save_figure(fig, output, dpi=90)
    plt.close(fig)
    return fig
