"""`imu-emulator plot`: a PNG of what a scene (or a `generate` output) does."""
from __future__ import annotations

import sys
from pathlib import Path


ORDER = 60     # place in `imu-emulator --help`


def register(subparsers) -> None:
    p = subparsers.add_parser("plot", help="draw the trajectory with the body along it and each IMU's signals (PNG)",
                              description="Draw the trajectory in 3-D with the body as triangles along it, the "
                                          "reference point and the IMUs marked, and per IMU specific force and "
                                          "angular rate against time. Needs the `plot` extra (matplotlib).")
    p.add_argument("source", metavar="SCENE|OUTPUT",
                   help="scene file (.toml), or an output of `generate` (.parquet/.npz/.csv; --truth for the "
                        "trajectory)")
    p.add_argument("-o", "--output", help="PNG to write (default: SOURCE with .png)")
    p.set_defaults(func=cmd_plot)


def cmd_plot(args) -> int:
    from imu_emulator.errors import ImuEmulatorError
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise ImuEmulatorError("plot: needs matplotlib; install the `plot` extra (pip install 'imu-emulator[plot]')") from None
    from imu_emulator.analysis import plotting

    source = Path(args.source)
    output = Path(args.output) if args.output else source.with_suffix(".png")
    if output.suffix.lower() != ".png":
        raise ImuEmulatorError(f"{output}: plot writes PNG; the output must end in .png")
    if not output.parent.exists():
        raise ImuEmulatorError(f"{output}: directory {output.parent} does not exist")
    if not source.exists():
        raise ImuEmulatorError(f"{source}: no such file")
    if source.suffix.lower() == ".toml":
        from imu_emulator.runtime.progress import CompileStatus
        from imu_emulator.scene.load import load_scene
        from imu_emulator.runtime.simulation import Simulation
        scene = load_scene(source)
        with CompileStatus(scene, attitude=False, truth=True):
            sim = Simulation(scene, attitude=False, truth=True)
        data = plotting.from_simulation(sim)
    else:
        data = plotting.from_output(str(source))
    plotting.draw(data, output)
    if data.position is None:
        print(f"note: {source} has no trajectory (write it with `generate --truth`); plotted the signals only",
              file=sys.stderr)
    print(f"wrote {output}", file=sys.stderr)
    return 0
