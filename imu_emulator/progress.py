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
        width = 40
        filled = int(width * done / max(total, 1))
        sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} samples")
        sys.stderr.flush()
        self.shown = True

    def close(self) -> None:
        if self.shown:
            sys.stderr.write("\n")
