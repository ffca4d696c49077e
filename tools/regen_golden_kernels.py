"""Regenerate the golden kernel sources of examples/*.toml under tests/data/kernels/ (what
`imu-emulator kernel SCENE` prints). Run after a change to the code generator, then review the diff:

    .venv/bin/python tools/regen_golden_kernels.py
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from imu_emulator.codegen.generate import generate_source  # noqa: E402
from imu_emulator.scene.load import load_scene  # noqa: E402

GOLDEN = ROOT / "tests" / "data" / "kernels"


def main() -> None:
    GOLDEN.mkdir(parents=True, exist_ok=True)
    for scene_path in sorted((ROOT / "examples").glob("*.toml")):
        target = GOLDEN / f"{scene_path.stem}.py.txt"
        source = generate_source(load_scene(scene_path), attitude=True, truth=False)
        changed = not target.exists() or target.read_text() != source
        target.write_text(source)
        print(f"{'updated' if changed else 'same   '} {target.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
