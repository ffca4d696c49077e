"""The benchmark commands the docs quote run to the end with every option (not a figure: a figure comes from a
run of the command on a quiet machine, docs/performance.md). A comparison option that crashes the tool would
otherwise be found only when someone next takes the figure."""
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytestmark = [pytest.mark.realtime, pytest.mark.streams, pytest.mark.subprocess, pytest.mark.slow]


def test_bench_stream_comparison_runs_every_kind():
    """The interleaved comparison with both extra floors, briefly at 1 kHz, against this tree itself."""
    out = subprocess.run([sys.executable, "tools/bench_stream.py", "--baseline", ".", "--rates", "1000",
                          "--seconds", "0.3", "--pairs", "1", "--drift-seconds", "0", "--loaded-floor", "--pty-floor"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    for kind in ("floor", "base", "tree", "load", "pty"):
        assert f"round 1 {kind:>5s}: missed" in out.stdout, out.stdout
    assert "median misses above the pty floor" in out.stdout
