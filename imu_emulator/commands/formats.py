"""`imu-emulator formats`: the wire formats, with their size per sample, whether a device answers the driver
([device]) and the named presets (`--option preset=NAME`); `--details` adds each format's encoder options with the
defaults read from the encoder's signature, its device's options (defaults from the device class's signature),
and the body axes and reference frame the format declares (from its manual: firmware_protocols.axes)."""
from __future__ import annotations


ORDER = 70     # place in `imu-emulator --help`


def register(subparsers) -> None:
    p = subparsers.add_parser("formats", help="list wire formats (--details: their options)")
    p.add_argument("--details", nargs="?", const="", metavar="NAME",
                   help="also list each format's options, defaults and ranges (only NAME's if given)")
    p.set_defaults(func=cmd_formats)


def size_per_sample(info) -> str:
    """What one sample costs its link with the default options: bytes (serial) or frames and worst-case bits (CAN)."""
    from firmware_protocols.base import can_bits_worst_case
    if info.kind == "serial":
        return f"{info.bytes_per_sample} B/sample"
    bits = sum(can_bits_worst_case(*frame) for frame in info.frames_per_sample)
    return f"{len(info.frames_per_sample)} frames/sample, {bits} bits worst case"


def option_rows(info) -> list[tuple[str, str, str]]:
    """(option, default as the encoder's signature has it, help with the range) for each declared option."""
    from firmware_protocols.registry import option_defaults
    defaults = option_defaults(info)
    return [(name, _show(defaults[name]), text) for name, text in info.options.items()]


def device_option_rows(info) -> list[tuple[str, str, str]]:
    """(option, default as the device class's signature has it, help) for each option only the device takes
    (FormatInfo.device_options; `--option` on a stream with that device)."""
    from firmware_protocols.registry import device_option_defaults
    defaults = device_option_defaults(info)
    return [(name, _show(defaults[name]) if name in defaults else "-", text)
            for name, text in info.device_options.items()]


def axes_row(info) -> str:
    """`axes FRD, reference NED (source)`: what the format declares (firmware_protocols.axes)."""
    from firmware_protocols.axes import declared
    cls = getattr(info.encoder, "func", info.encoder)
    body, reference = declared(info.encoder)
    return (f"axes {body or 'undeclared'}, reference {reference or 'none (no attitude)'}"
            f" ({getattr(cls, 'axes_source', '') or 'no source'})")


def _show(value) -> str:
    # An AxisMap default is written the way a scene file gives it: (axes, signs).
    if hasattr(value, "axes") and hasattr(value, "signs"):
        value = (tuple(value.axes), tuple(value.signs))
    return repr(value)


def cmd_formats(args) -> int:
    import firmware_protocols
    from imu_emulator.live.config import StreamError
    known = firmware_protocols.formats()
    if args.details:
        if args.details not in known:
            raise StreamError(f"formats --details: unknown format {args.details!r}; known: {', '.join(known)}")
        known = {args.details: known[args.details]}
    for name, info in known.items():
        talks = " [device]" if info.device is not None else ""
        print(f"{name:24} {info.kind:6} {size_per_sample(info):40} {info.description}{talks}")
        for preset, (options, text) in info.presets.items():
            print(f"{'':24} preset={preset}: {text}")
        if args.details is None:
            continue
        print(f"    {axes_row(info)}")
        for option, default, text in option_rows(info):
            print(f"    {option:22} default {default:24} {text}")
        if not info.options:
            print("    (no options)")
        rows = device_option_rows(info)
        if rows:
            print("    device options (the device answering the driver takes these too):")
        for option, default, text in rows:
            print(f"    {option:22} default {default:24} {text}")
    return 0
