"""The first compile of a scene's kernel is announced (with its time) on a terminal, and only then."""
import shutil
import sys

import pytest

from imu_emulator.runtime import kernels as kernel_module
from tests.support.paths import REPO

ROOT = REPO


def test_first_compile_is_announced_with_its_time_on_a_terminal(fresh_cache, tmp_path, capsys, monkeypatch):
    from imu_emulator.cli import main
    scene = str(ROOT / "examples" / "orientation_only.toml")
    args = ["generate", scene, "-o", str(tmp_path / "o.npz")]
    assert main(args) == 0                      # stderr is not a terminal: no status line (errors stay one line)
    assert "compiling" not in capsys.readouterr().err
    kernel_module._loaded.clear()
    shutil.rmtree(fresh_cache)                        # cold again
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(args) == 0
    cold = capsys.readouterr().err
    assert f"compiling kernel for scene {scene} (first run) …" in cold and " compiled in " in cold
    kernel_module._loaded.clear()
    assert main(args) == 0                      # warm: nothing to announce
    assert "compiling" not in capsys.readouterr().err


@pytest.mark.parametrize("raised, outcome", [(KeyboardInterrupt, "interrupted"), (RuntimeError, "failed")])
def test_a_compile_cut_short_says_why(fresh_cache, capsys, monkeypatch, raised, outcome):
    """Ctrl-C during the first compile is the user's choice: "interrupted", not "failed" (issue 23, item 12)."""
    from imu_emulator.runtime.progress import CompileStatus
    from imu_emulator.scene import load_scene
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    status = CompileStatus(load_scene(ROOT / "examples" / "orientation_only.toml"), attitude=True, truth=False)
    assert status.active                        # an empty cache: the compile would be announced
    with pytest.raises(raised):
        with status:
            raise raised()
    assert capsys.readouterr().err.endswith(f"(first run) … {outcome} in 0.0 s\n")
