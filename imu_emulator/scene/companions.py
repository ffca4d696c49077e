"""An [[imu]]'s companion sensors ([imu.magnetometer], [imu.barometer], [imu.gnss], [imu.ins]): named by their
sub-table, each key read with the units machinery the effects' parameters use (imu_emulator.scene.units), from
the declarations in imu_emulator.companions; and the scene-wide check that they have a place on the Earth."""
from __future__ import annotations

from typing import Mapping

from imu_emulator.errors import SceneError
from imu_emulator.scene.checks import no_unknown


def names() -> set[str]:
    """The [[imu]] sub-table names that are companion sensors."""
    from imu_emulator.companions import COMPANIONS
    return set(COMPANIONS)


def companion_specs(table: Mapping, where: str) -> dict[str, dict]:
    """{name: {key: value in the parameter's unit}} for each companion the [[imu]] table names."""
    from imu_emulator.companions import COMPANIONS
    from imu_emulator.scene import units
    found = {}
    for name, companion in COMPANIONS.items():
        if name not in table:
            continue
        sub, prefix = table[name], f"{where}.{name}"
        if not isinstance(sub, Mapping):
            raise SceneError(f"{prefix}: expected a table ([imu.{name}]), got {type(sub).__name__}")
        no_unknown(sub, {p.key for p in companion.params} | set(companion.extra), prefix)
        values = {}
        for param in companion.params:
            given = param.key in sub
            values[param.key] = units.parse(sub[param.key] if given else param.default, param.unit, param.shape,
                                            f"{prefix}.{param.key}")
        for key, parse in companion.extra.items():
            values[key] = parse(sub.get(key, []), f"{prefix}.{key}")
        if companion.validate is not None:
            companion.validate(values, where)
        found[name] = values
    return found


def check_origin(imus, frame: str, origin, trajectory) -> None:
    """A companion reads the Earth (its field, its air, its satellites): an ENU or NED scene naming one needs
    [scene] origin, as the Earth effects do (a geodetic trajectory or an ECEF/ECI frame is on the Earth already,
    for which earth_keys leaves origin None)."""
    from imu_emulator.scene.earth import GEODETIC_KEYS
    geodetic = getattr(trajectory, "keys", None) == GEODETIC_KEYS or getattr(trajectory, "geodetic", False)
    if frame not in ("ENU", "NED") or origin is not None or geodetic:
        return
    for i, imu in enumerate(imus):
        for name in sorted(imu.companions):
            raise SceneError(f"scene.origin: imu[{i}].{name} needs the point where the {frame} frame is tangent to "
                             "the Earth (origin = { lat_deg = ..., lon_deg = ..., height_m = ... })")
