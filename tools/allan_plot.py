"""The README's Allan-deviation figure: a preset's generated gyro and accelerometer (x axis, at rest, 2 h at
100 Hz, effects noise + bias_instability) against the datasheet lines N/sqrt(tau) and 0.664 B.

    .venv/bin/python tools/allan_plot.py [--model xsens-mti-3] [--hours 2] [--out docs/sensor_errors]

Allan deviation by allantools (overlapping ADEV). Needs the plot extra (matplotlib) and allantools (test extra).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from imu_emulator import scene_from_dict  # noqa: E402
from imu_emulator.scene import presets
from imu_emulator.runtime.simulation import Simulation  # noqa: E402

RATE_HZ = 100.0
FLOOR = 0.664


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", default="xsens-mti-3", choices=presets.names())
    parser.add_argument("--hours", type=float, default=2.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", default=str(ROOT / "docs" / "sensor_errors"))
    args = parser.parse_args()
    import allantools
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scene = scene_from_dict({"scene": {"rate_hz": RATE_HZ, "duration_s": args.hours * 3600.0, "seed": args.seed},
                             "trajectory": {"shape": "static"}, "imu": [{"name": "imu0", "model": args.model}],
                             "effects": {"noise": True, "bias_instability": True}})
    out = Simulation(scene, attitude=False).run()
    taus = np.logspace(np.log10(2 / RATE_HZ), np.log10(args.hours * 3600.0 / 8), 40)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    scales = {"gyro": (np.degrees(1.0) * 3600.0, "deg/h"), "accel": (1e6 / 9.80665, "µg")}
    for ax, (triad, data) in zip(axes, (("gyro", out.gyro), ("accel", out.accel))):
        scale, unit = scales[triad]
        t, adev, err, _ = allantools.oadev(data[0, :, 0], rate=RATE_HZ, data_type="freq", taus=taus)
        n, b = presets.datasheet_lines(args.model, triad)
        ax.errorbar(t, adev * scale, yerr=err * scale, fmt=".", label="generated (allantools oadev)")
        ax.loglog(t, n / np.sqrt(t) * scale, "--", label="datasheet N/√τ")
        if b:
            ax.loglog(t, np.full_like(t, FLOOR * b * scale), ":", label="datasheet 0.664·B")
            ax.loglog(t, np.sqrt(n ** 2 / t + (FLOOR * b) ** 2) * scale, "-", lw=0.8, label="sum of the lines")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("τ (s)")
        ax.set_ylabel(f"Allan deviation ({unit})")
        ax.set_title(f"{args.model} {triad} x")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{presets.describe(args.model)['part']}: {args.hours:g} h at {RATE_HZ:g} Hz, seed {args.seed}")
    fig.tight_layout()
    path = Path(args.out)
    path.mkdir(parents=True, exist_ok=True)
    target = path / f"allan_{args.model}.png"
    fig.savefig(target, dpi=110)
    print(f"wrote {target}")


if __name__ == "__main__":
    main()
