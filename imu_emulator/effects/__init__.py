"""The effects a kernel can compile in, one module each (see _record.py for the record they declare).

The list is found, not kept: every module of this package not starting with "_" must define EFFECT.
"""
from __future__ import annotations

import sys

from imu_emulator import extensions
from imu_emulator.effects._record import (AXES, FRAME_ORDERS, STAGE_CONTRACT, STAGE_TITLES, TRIADS, Effect,
                                          EmitContext, Param, Stage, triad_params)


def _discover() -> dict[str, Effect]:
    found = extensions.declared(sys.modules[__name__], "EFFECT", Effect)
    found.sort(key=lambda e: (e.stage, e.order, e.name))
    return {e.name: e for e in found}


#: name -> record, in execution order (stage, then order within the stage)
EFFECTS: dict[str, Effect] = _discover()


def all_params() -> list[tuple[Effect, Param]]:
    return [(effect, param) for effect in EFFECTS.values() for param in effect.params]


def documentation_table() -> str:
    """The Markdown table of effects and parameters (the docs site's effects table, docs/sensor-errors.md, is generated from it)."""
    rows = ["| effect | stage | parameter | unit (plain numbers) | datasheet forms | what |", "|---|---|---|---|---|---|"]
    for effect in EFFECTS.values():
        stage = f"{STAGE_TITLES[effect.stage]} ({effect.order})"
        if not effect.params:
            rows.append(f"| `{effect.name}` | {stage} | — | — | — | {effect.description} |")
        for param in effect.params:
            keys = " / ".join(f"`{k}`" for k in (param.key, *param.aliases))
            rows.append(f"| `{effect.name}` | {stage} | `[{param.table}]` {keys} | {param.unit} | "
                        f"{param.datasheet or '—'} | {param.description} |")
    return "\n".join(rows)


__all__ = ["AXES", "EFFECTS", "FRAME_ORDERS", "STAGE_CONTRACT", "STAGE_TITLES", "TRIADS", "Effect", "EmitContext",
           "Param", "Stage", "all_params", "documentation_table", "triad_params"]
