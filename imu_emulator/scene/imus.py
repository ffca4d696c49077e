"""[[imu]] tables: each IMU's name, clock offset and the value of every parameter the named effects declare
(imu_emulator.effects), from its own keys, a datasheet preset (imu_emulator.scene.presets) or the defaults."""
from __future__ import annotations

from typing import Mapping

from imu_emulator.errors import SceneError
from imu_emulator.scene.checks import check_bound, check_time_resolution, no_unknown, number, subtable
from imu_emulator.scene.model import BOUNDS, MAX_IMUS, MAX_TIME_OFFSET_S, ImuSpec


def imu_specs(raw: Mapping, effects: frozenset[str], t0: float, duration: float, rate: float,
              warnings: list[str]) -> tuple[ImuSpec, ...]:
    """The [[imu]] tables (at least one), each with its own clock offset checked against the scene's time span,
    and the effects' warnings that need the sample rate."""
    imu_list = raw.get("imu", [])
    if isinstance(imu_list, Mapping):
        imu_list = [imu_list]
    if not isinstance(imu_list, list) or not imu_list:
        raise SceneError("imu: at least one [[imu]] table is required")
    if len(imu_list) > MAX_IMUS:
        raise SceneError(f"imu: {len(imu_list)} [[imu]] tables; the limit is {MAX_IMUS} per scene")
    imus: list[ImuSpec] = []
    for i, table in enumerate(imu_list):
        imus.append(_imu(table, f"imu[{i}]", effects, {imu.name for imu in imus}, warnings))
        if imus[-1].time_offset_s:
            check_time_resolution(t0 + imus[-1].time_offset_s, duration, rate, f"imu[{i}].time_offset_s")
    from imu_emulator.effects import EFFECTS
    for i, imu in enumerate(imus):   # effects' warnings that need the sample rate (vibration above Nyquist)
        warnings += [line for effect in EFFECTS.values() if effect.name in effects and effect.warn is not None
                     for line in effect.warn(imu.values, f"imu[{i}]", rate)]
    return tuple(imus)


def _imu(table, where: str, effects: frozenset[str], taken: set[str], warnings: list[str]) -> ImuSpec:
    """An [[imu]] table: the keys and sub-tables ([imu.gyro], [imu.accel]) the effects declare, nothing else."""
    from imu_emulator.scene import units
    from imu_emulator.effects import all_params
    if not isinstance(table, Mapping):
        raise SceneError(f"{where}: expected a table")
    declared = all_params()
    subtables = {p.table.split(".", 1)[1] for _, p in declared if p.table != "imu"}
    from imu_emulator.scene.companions import companion_specs, names as companion_names
    no_unknown(table, {"name", "model", "time_offset_s", *subtables, *companion_names(),
                       *(k for _, p in declared if p.table == "imu" for k in (p.key, *p.aliases))}, where)
    name = table.get("name", where.replace("[", "").replace("]", ""))
    # names become CSV cells and labels on the wire: one printable line, no comma
    if not isinstance(name, str) or not name or "," in name or not name.isprintable() or len(name) > 64:
        raise SceneError(f"{where}.name: expected a printable name of 1 to 64 characters without commas, "
                         f"got {name!r}")
    if name in taken:
        raise SceneError(f"{where}.name: {name!r} is used twice")
    sources = {"imu": (table, where)}
    for sub in sorted(subtables):
        sources[f"imu.{sub}"] = (subtable(table, sub, f"{where}."), f"{where}.{sub}")
        no_unknown(sources[f"imu.{sub}"][0],
                   {k for _, p in declared if p.table == f"imu.{sub}" for k in (p.key, *p.aliases)}, f"{where}.{sub}")
    # a preset (model = "NAME") fills what the IMU's own keys leave open, without "ignored" warnings: it is a
    # datasheet, not a request for effects
    preset = {}
    if "model" in table:
        from imu_emulator.scene import presets
        for sub, keys in presets.load(table["model"], f"{where}.model").items():
            preset[f"imu.{sub}"] = (keys, f"{where}.model({table['model']}).{sub}")
            no_unknown(keys, {k for _, p in declared if p.table == f"imu.{sub}" for k in (p.key, *p.aliases)},
                       preset[f"imu.{sub}"][1])
    values = {}
    for effect, param in declared:
        source, prefix = sources[param.table]
        given = [key for key in (param.key, *param.aliases) if key in source]
        if len(given) > 1:
            raise SceneError(f"{prefix}.{given[1]}: give either {given[0]} or {given[1]}, not both")
        default = units.parse(param.default, param.unit, param.shape, f"{prefix}.{param.key}")
        values[param.path] = default
        from_preset = [key for key in (param.key, *param.aliases) if key in preset.get(param.table, ({},))[0]]
        if not given and from_preset:
            preset_table, preset_prefix = preset[param.table]
            values[param.path] = units.parse(preset_table[from_preset[0]], param.unit, param.shape,
                                             f"{preset_prefix}.{from_preset[0]}")
        elif given:
            bound = BOUNDS.get(param.path)
            try:
                values[param.path] = units.parse(source[given[0]], param.unit, param.shape, f"{prefix}.{given[0]}")
            except SceneError as exc:
                if bound is None:
                    raise
                raise SceneError(f"{exc} (each |value| <= {bound[0]:g}{bound[1]})") from None
            check_bound(values[param.path], bound, f"{prefix}.{given[0]}")
            # a value that changes nothing (the default, e.g. a zero lever arm) is not worth a warning
            if effect.name not in effects and values[param.path] != default:
                warnings.append(f"{prefix}.{given[0]} is ignored because effects.{effect.name} is not true")
    from imu_emulator.effects import EFFECTS
    for effect in EFFECTS.values():
        if effect.name in effects and effect.validate is not None:
            effect.validate(values, where)
    time_offset = number(table, "time_offset_s", where, default=0.0, bound=MAX_TIME_OFFSET_S, unit=" s")
    return ImuSpec(name, values, time_offset, companion_specs(table, where))
