"""Companion sensors an IMU may carry, one module each (see _record.py for the record they declare): the
magnetometer, the barometer, the GNSS receiver and the unit's own navigation estimate (ins).

Off unless named: an [[imu]] table names one with its sub-table ([imu.magnetometer], [imu.barometer],
[imu.gnss], [imu.ins]; an empty table takes the defaults). The list is found, not kept: every module of this
package not starting with "_" must define COMPANION. Scene validation (imu_emulator.scene.companions) reads the
records' parameters; the simulation (imu_emulator.runtime.simulation) runs them after the kernel.
"""
from __future__ import annotations

import sys

from imu_emulator import extensions
from imu_emulator.companions._record import Companion, Runner, Truth


def _discover() -> dict[str, Companion]:
    return {c.name: c for c in sorted(extensions.declared(sys.modules[__name__], "COMPANION", Companion),
                                      key=lambda c: c.name)}


#: name -> record, by name
COMPANIONS: dict[str, Companion] = _discover()


def named(scene) -> set[str]:
    """The companions any IMU of the scene names."""
    return {name for imu in scene.imus for name in imu.companions}


def documentation_table() -> str:
    """The Markdown table of companion sensors and their parameters (docs/companions.md is generated from it; a test
    checks they agree)."""
    rows = ["| sensor | parameter | unit (plain numbers) | default | datasheet forms | what |",
            "|---|---|---|---|---|---|"]
    for companion in COMPANIONS.values():
        for param in companion.params:
            rows.append(f"| `[imu.{companion.name}]` | `{param.key}` | {param.unit} | `{_plain(param.default)}` | "
                        f"{param.datasheet or '—'} | {param.description} |")
        for key, parse in companion.extra.items():
            rows.append(f"| `[imu.{companion.name}]` | `{key}` | — | — | — | {(parse.__doc__ or '').strip()} |")
    return "\n".join(rows)


def _plain(value) -> str:
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_plain(v) for v in value) + "]"
    return f"{value:g}" if isinstance(value, float) else str(value)


__all__ = ["COMPANIONS", "Companion", "Runner", "Truth", "documentation_table", "named"]
