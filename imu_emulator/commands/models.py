"""`imu-emulator models`: the presets (`model = "NAME"` in [[imu]]) with their headline figures."""
from __future__ import annotations

FIGURES = (("gyro", "noise_density", "arw"), ("gyro", "bias_instability"), ("gyro", "range"),
           ("accel", "noise_density", "vrw"), ("accel", "bias_instability"), ("accel", "range"))


ORDER = 110     # place in `imu-emulator --help`


def register(subparsers) -> None:
    p = subparsers.add_parser("models", help="list the sensor presets (model = NAME in [[imu]]) and their figures")
    p.add_argument("--sources", action="store_true", help="also print each preset's datasheet citation")
    p.set_defaults(func=cmd_models)


def _figure(table: dict, keys) -> str:
    for key in keys:
        if key in table:
            return f"{key} {table[key]}"
    return "—"


def cmd_models(args) -> int:
    from imu_emulator.scene import presets
    for name in presets.names():
        info = presets.describe(name)
        print(f"{name:18s} {info['part']}")
        for triad in ("gyro", "accel"):
            figures = [_figure(info[triad], keys) for t, *keys in FIGURES if t == triad]
            print(f"  {triad:5s}  " + "; ".join(f for f in figures if f != "—"))
        if args.sources:
            print(f"  source: {info['source']}")
    return 0
