"""`imu-emulator formats`: the wire formats, with their size per sample, whether a device answers the driver
([device]) and the named presets (`--option preset=NAME`)."""
from __future__ import annotations


def register(subparsers) -> None:
    p = subparsers.add_parser("formats", help="list wire formats")
    p.set_defaults(func=cmd_formats)


def cmd_formats(args) -> int:
    import firmware_protocols
    from firmware_protocols.base import can_bits_worst_case
    for name, info in firmware_protocols.formats().items():
        if info.kind == "serial":
            size = f"{info.bytes_per_sample} B/sample"
        else:
            bits = sum(can_bits_worst_case(*frame) for frame in info.frames_per_sample)
            size = f"{len(info.frames_per_sample)} frames/sample, {bits} bits worst case"
        talks = " [device]" if info.device is not None else ""
        print(f"{name:24} {info.kind:6} {size:40} {info.description}{talks}")
        for preset, (options, text) in info.presets.items():
            print(f"{'':24} preset={preset}: {text}")
    return 0
