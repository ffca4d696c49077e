"""What a stream is asked to do: the `[[stream]]` tables and `--to` options as validated configurations, the run's
options, and what the configured formats need the simulation to compute (truth, integrated outputs)."""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import firmware_protocols
from imu_emulator.errors import ImuEmulatorError, SceneError
from imu_emulator.live.transport import TargetOptions
from imu_emulator.output.ros2.conventions import DEFAULT_START_NS

STREAM_TABLE_KEYS = {"imu", "format", "to", "options", "link", "pace_baud", "bitrate", "data_bitrate", "fd", "device"}


class StreamError(ImuEmulatorError):
    """A stream's format, IMU or encoder options are unusable."""


@dataclass(frozen=True)
class StreamConfig:
    imu: str
    format: str
    target: str
    options: dict = field(default_factory=dict)             # encoder (and device) options
    target_options: TargetOptions = TargetOptions()
    device: bool = True     # answer the driver when the format has a device and the link is two-way


@dataclass(frozen=True)
class RunOptions:
    speed: float = 1.0               # 0 = as fast as the link takes
    loop: bool = False
    epoch_time: bool = False         # True: start_ns is the wall clock at the first sample's deadline ("now")
    start_ns: int = DEFAULT_START_NS     # UTC Unix ns of scene time 0 (--start-time)
    duration_s: float | None = None
    count: int | None = None
    quiet: bool = False
    allow_overload: bool = False
    realtime: str = "auto"           # imu_emulator.live.realtime.MODES
    stats_json: "str | AtomicOutput | None" = None   # a path, or an output the caller created early


def streams_from_tables(tables, imu_names, defaults: TargetOptions = TargetOptions()) -> list[StreamConfig]:
    """Validate the scene's raw [[stream]] tables; errors name the table and key."""
    configs = []
    for i, table in enumerate(tables):
        where = f"stream[{i}]"
        unknown = sorted(set(table) - STREAM_TABLE_KEYS)
        if unknown:
            raise SceneError(f"{where}.{unknown[0]}: unknown key (allowed: {', '.join(sorted(STREAM_TABLE_KEYS))})")
        for key in ("format", "to"):
            if not isinstance(table.get(key), str) or not table[key]:
                raise SceneError(f"{where}.{key}: missing (a string is required)")
        imu = table.get("imu", imu_names[0])
        if imu not in imu_names:
            raise SceneError(f"{where}.imu: no IMU named {imu!r} (scene has: {', '.join(imu_names)})")
        options = table.get("options", {})
        if not isinstance(options, dict):
            raise SceneError(f"{where}.options: expected a table")
        overrides = {}
        device = table.get("device", True)
        if not isinstance(device, bool):
            raise SceneError(f"{where}.device: expected true or false, got {device!r}")
        for key, kind in (("link", str), ("pace_baud", int), ("bitrate", int), ("data_bitrate", int), ("fd", bool)):
            if key in table:
                value = table[key]
                if not isinstance(value, kind) or (kind is int and (isinstance(value, bool) or value <= 0)):
                    expected = "a positive integer" if kind is int else kind.__name__
                    raise SceneError(f"{where}.{key}: expected {expected}, got {value!r}")
                overrides[key] = value
        configs.append(StreamConfig(imu, table["format"], table["to"], dict(options), replace(defaults, **overrides),
                                    device))
    return configs


def needs_truth(configs: list[StreamConfig]) -> bool:
    """Whether a device among the streams reports navigation (then the simulation must compute truth)."""
    for config in configs:
        try:
            info = firmware_protocols.get(config.format)
        except KeyError:
            continue
        if reports_navigation(info, config):
            return True
    return False


def reports_navigation(info, config: StreamConfig) -> bool:
    """Whether the stream's wire carries position/velocity: a device that reports navigation, or an encoder (its
    own, or one a device sends beside its main message: MAVLink's also=) that says so with `uses_navigation`."""
    try:
        if config.device and info.device is not None:
            return info.device_navigation or encoders_navigate(info.device(100.0, **config.options).encoders())
        return encoders_navigate([info.encoder(**config.options)])
    except (TypeError, ValueError):
        return False        # build_streams reports it


def encoders_navigate(encoders) -> bool:
    return any(getattr(encoder, "uses_navigation", False) for encoder in encoders)


def needs_increments(configs: list[StreamConfig]) -> bool:
    """Whether a stream's wire fields carry integrated outputs (then the simulation computes them): an encoder
    whose selected fields read them, or a device of a format that has such fields (its driver may ask)."""
    for config in configs:
        try:
            info = firmware_protocols.get(config.format)
            if config.device and info.device is not None:
                device = info.device(100.0, **config.options)
                encoders = list(device.encoders())
                if getattr(device, "carries_increments", False):
                    return True
            else:
                encoders = [info.encoder(**config.options)]
        except (KeyError, TypeError, ValueError):
            continue    # build_streams reports it
        if any(getattr(encoder, "uses_increments", False) for encoder in encoders):
            return True
    return False
