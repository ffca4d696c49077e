"""A progress bar on stderr for long runs."""
from __future__ import annotations

import sys
import time


class Progress:
    """A progress bar on stderr for long runs; silent for short ones and with --quiet."""

    def __init__(self, quiet: bool, min_seconds: float = 1.0):
        self.quiet = quiet or not sys.stderr.isatty()
        self.start = time.monotonic()
        self.min_seconds = min_seconds
        self.shown = False

    def __call__(self, done: int, total: int) -> None:
        if self.quiet or time.monotonic() - self.start < self.min_seconds:
            return
        sys.stderr.write("\r" + bar(done, total, time.monotonic() - self.start, "samples") + "\x1b[K")
        sys.stderr.flush()
        self.shown = True

    def close(self) -> None:
        if self.shown:
            sys.stderr.write("\n")


def bar(done: int, total: int, elapsed: float, what: str, width: int = 40) -> str:
    """"[#####.....] 1200/5000 samples, 3.1e+04 samples/s, 2:03 left": the rate is the mean since the start."""
    filled = int(width * done / max(total, 1))
    text = f"[{'#' * filled}{'.' * (width - filled)}] {done}/{total} {what}"
    if done > 0 and elapsed > 0:
        rate = done / elapsed
        left = int(round((total - done) / rate))
        text += f", {rate:.3g} {what}/s, {left // 3600}:{left // 60 % 60:02d}:{left % 60:02d} left"
    return text


class CompileStatus:
    """Around a Simulation's construction: when the scene's kernel is not in the cache yet, a status line on the
    terminal ("compiling kernel for scene X (first run) … 3.5 s", updated in place) and the total when done. Like
    the progress bar, silent when stderr is not a terminal (logs, pipes, tests: errors stay one line) or --quiet."""

    def __init__(self, scene, attitude: bool, truth: bool, quiet: bool = False, increments: int = 0):
        from imu_emulator.runtime.kernels import cached_kernel
        self.active = (not quiet and sys.stderr.isatty()
                       and not cached_kernel(scene, attitude=attitude, truth=truth, increments=increments)[1])
        self.label = f"compiling kernel for scene {scene.path or '<in code>'} (first run) …"
        self._stop = None

    def __enter__(self):
        if not self.active:
            return self
        import threading
        self.start = time.monotonic()
        sys.stderr.write(self.label)
        sys.stderr.flush()
        self._stop = threading.Event()
        threading.Thread(target=self._tick, daemon=True).start()
        return self

    def _tick(self) -> None:
        while not self._stop.wait(0.5):
            sys.stderr.write(f"\r{self.label} {time.monotonic() - self.start:.1f} s")
            sys.stderr.flush()

    def __exit__(self, *exc) -> None:
        if not self.active:
            return
        self._stop.set()
        # Ctrl-C is the user's choice, not a compile that failed
        outcome = ("compiled" if exc[0] is None else "interrupted" if issubclass(exc[0], KeyboardInterrupt)
                   else "failed")
        sys.stderr.write(f"\r{self.label} {outcome} in {time.monotonic() - self.start:.1f} s\n")
        sys.stderr.flush()
