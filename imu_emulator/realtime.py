"""Pacing to absolute deadlines on the monotonic clock, and statistics of how late we were.

Deadlines are computed from the sample index (start + k * period), never by adding periods or
sleeping fixed intervals, so lateness never accumulates into drift.
"""
from __future__ import annotations

import ctypes
import os
import select
import time
from dataclasses import dataclass

import numpy as np

_PR_SET_TIMERSLACK = 29
# We sleep to shortly before each deadline and spin the rest: a plain sleep wakes 25-75 us late on
# these machines, even under SCHED_FIFO (measured p50 48 us, p99 114 us at 1 kHz).
_SPIN_NS = 200_000
# Under SCHED_FIFO the spin is bounded to a share of each period. An unbounded busy loop would hit RT
# throttling (95 % of each second) and stall for tens of milliseconds; this uses at most 40 %.
_FIFO_SPIN_NS = 100_000
_FIFO_SPIN_SHARE = 0.4
# Answering a command costs tens to hundreds of microseconds in Python: none is started this close to a
# deadline (a command then waits at most one sample period).
_SERVE_MARGIN_NS = 300_000


@dataclass(frozen=True)
class RealtimeSetup:
    fifo: bool          # SCHED_FIFO granted
    timer_slack: bool   # 1 ns timer slack set
    note: str           # why not, when not

    def describe(self) -> str:
        parts = ["SCHED_FIFO" if self.fifo else "normal scheduling",
                 "timer slack 1 ns" if self.timer_slack else "default timer slack"]
        return ", ".join(parts) + (f" ({self.note})" if self.note else "")


def enable_realtime(want_fifo: bool = True, priority: int = 20) -> RealtimeSetup:
    """Ask for SCHED_FIFO (calling thread only) and 1 ns timer slack; fall back quietly when refused."""
    notes = []
    slack = False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        slack = libc.prctl(_PR_SET_TIMERSLACK, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        notes.append("prctl unavailable")
    fifo = False
    if want_fifo and hasattr(os, "sched_setscheduler"):
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            fifo = True
        except (PermissionError, OSError) as exc:
            notes.append(f"SCHED_FIFO refused: {exc.strerror or exc}")
    return RealtimeSetup(fifo, slack, "; ".join(notes))


def drop_realtime() -> None:
    """Back to normal scheduling for the calling thread (helpers that compute must never run RT)."""
    if hasattr(os, "sched_setscheduler"):
        try:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            pass


class Pacer:
    """Wait until an absolute monotonic deadline: sleep to `spin_ns` before it, then spin.

    Under SCHED_FIFO the spin is short and a bounded share of the period (see _FIFO_SPIN_SHARE), so
    the thread never runs long enough for RT throttling to stall it.
    """

    def __init__(self, fifo: bool, period_ns: float = 1e6):
        self.spin_ns = int(min(_FIFO_SPIN_NS, _FIFO_SPIN_SHARE * period_ns)) if fifo else _SPIN_NS
        self.serve_margin_ns = _SERVE_MARGIN_NS
        # When the descriptors were last looked at: at high rates the whole period may be spin and margin,
        # and the caller then polls them itself after a send (see streaming).
        self.watched_ns = 0

    def sleep_until(self, wake_ns: int, fds=(), on_ready=None) -> None:
        """Sleep until `wake_ns` (monotonic) or a little after, but while any of `fds` is readable call
        on_ready(readable fds) at once (it returns whether it found any input) and go back to sleep: replies go out between two deadlines.
        Input arriving within _SERVE_MARGIN_NS of the wake time waits in the kernel until after the
        deadline's send, so answering never makes a sample late. select() rather than poll/epoll because its
        timeout has microsecond resolution (theirs is ms)."""
        while True:
            early = wake_ns - time.monotonic_ns()
            if early <= 0:
                return
            if not fds or early <= self.serve_margin_ns:
                time.sleep(early / 1e9)
                return
            ready, _, _ = select.select(fds, (), (), (early - self.serve_margin_ns) / 1e9)
            self.watched_ns = time.monotonic_ns()
            if ready and not on_ready(ready):
                # Readable but nothing to read: a hang-up (a pty whose reader has gone away stays readable).
                # Stop watching until this deadline instead of spinning on select.
                fds = ()

    def wait_until(self, deadline_ns: int, fds=(), on_ready=None) -> int:
        """Returns the time we woke (ns, monotonic), at or after the deadline; input on `fds` is handed to
        on_ready while sleeping (never while spinning)."""
        self.sleep_until(deadline_ns - self.spin_ns, fds, on_ready)
        now = time.monotonic_ns()
        while now < deadline_ns:
            now = time.monotonic_ns()
        return now


class LatenessStats:
    """Lateness against deadlines with bounded memory: a histogram of 1 us bins up to 65.5 ms
    (quantiles beyond that read as the bound) plus the exact maximum and a count of misses.

    `add` is O(1) plain Python on purpose: batching values into numpy every N samples cost up to a few
    hundred microseconds at once, which is several deadlines at 10 kHz."""

    BINS = 65536

    def __init__(self, period_ns: float):
        self.period_ns = period_ns
        self.hist = [0] * self.BINS
        self.count = 0
        self.max_ns = 0
        self.missed = 0       # later than one period

    def add(self, lateness_ns: int) -> None:
        self.count += 1
        if lateness_ns > self.max_ns:
            self.max_ns = lateness_ns
        if lateness_ns > self.period_ns:
            self.missed += 1
        self.hist[min(max(lateness_ns // 1000, 0), self.BINS - 1)] += 1

    def quantile_us(self, q: float) -> float:
        if not self.count:
            return 0.0
        rank = int(np.ceil(q * self.count))
        return float(np.searchsorted(np.cumsum(self.hist), max(rank, 1)))

    def summary(self) -> dict:
        return {"p50_us": self.quantile_us(0.5), "p99_us": self.quantile_us(0.99),
                "p999_us": self.quantile_us(0.999), "max_us": self.max_ns / 1000,
                "missed": self.missed, "missed_ratio": self.missed / self.count if self.count else 0.0}
