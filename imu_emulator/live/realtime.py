"""Pacing to absolute deadlines on the monotonic clock, how the sender is scheduled, and statistics of how
late we were.

Deadlines are computed from the sample index (start + k * period), never by adding periods or
sleeping fixed intervals, so lateness never accumulates into drift.

Scheduling modes (`--realtime`), chosen so that a consumer on the same machine (firmware in the loop, candump)
is never starved of CPU by the emulator:

    spin  wake under SCHED_FIFO shortly before the deadline and spin the rest: the most precise, costs up to
          _SPIN_SHARE of one core; only for a machine where a core is left for the consumer
    fifo  sleep to the deadline under SCHED_FIFO, no spin: prompt wake-ups, a few us of CPU per sample
    off   normal scheduling, plain sleep: the kernel shares the CPU fairly with everything else

Spinning at normal priority (SCHED_FIFO for the wake-up only) was measured and dropped: giving up SCHED_FIFO
makes the kernel reschedule at once, and on a loaded machine the spin then loses the CPU for milliseconds
(tools/bench_coexist.py: hundreds of deadlines a period late per 4000, against tens for a SCHED_FIFO spin).
SCHED_FIFO is held only while the sender keeps up: one that is _BEHIND_NS late (it will not sleep before
catching up) drops to normal priority until it sleeps again, and competes fairly instead of starving the reader. The priority is the lowest SCHED_FIFO
level, below any real-time thread of a flight stack (ArduPilot's Linux HAL uses 10-20).
"""
from __future__ import annotations

import ctypes
import os
import resource
import select
import time
from dataclasses import dataclass

import numpy as np

_PR_SET_TIMERSLACK = 29
# A plain sleep wakes 25-75 us late on these machines (measured p50 48 us, p99 114 us at 1 kHz under
# SCHED_FIFO), so `spin` sleeps to this far before each deadline and spins the rest.
_SPIN_NS = 200_000
# ... but never more than this share of a period: at 10 kHz a spin of 200 us would be the whole period, and
# RT throttling (95 % of each second) would stall an unbounded SCHED_FIFO spin for tens of milliseconds.
_SPIN_SHARE = 0.4
# Answering a command costs tens to hundreds of microseconds in Python: none is started this close to a
# deadline (a command then waits at most one sample period). Until answers have been timed the margin is
# _SERVE_MARGIN_NS; then twice the dearest answer's CPU time plus _SERVE_SLACK_NS, within
# [_MIN_SERVE_MARGIN_NS, _SERVE_MARGIN_NS]: input that arrives in the margin waits for the next send, so a
# margin sized to what answers really cost (a register read: ~20 us) shortens that wait for most commands.
_SERVE_MARGIN_NS = 300_000
_MIN_SERVE_MARGIN_NS = 50_000
_SERVE_SLACK_NS = 30_000
FIFO_PRIORITY = 1
# A sender this late (or a period, if longer) gives up SCHED_FIFO until it next sleeps: it cannot keep up, and
# catching up under SCHED_FIFO would take the CPU from the reader. Shorter stalls (the shared host takes the
# vCPU away for 0.2-5 ms, on a loaded day for tens of ms) are caught up under SCHED_FIFO: at 20 ms, a demoted
# sender beside two busy loops ended up 100 ms late (tools/bench_coexist.py). 100 ms is half of what a pty
# holds at 1 kHz.
_BEHIND_NS = 100_000_000
MODES = ("auto", "spin", "fifo", "off")
# A thread CPU clock that moves in steps above this is too coarse to time one sample's work by.
_FINE_CPU_CLOCK_NS = 100_000


def cpu_clock_step_ns(limit_ns: int = 50_000_000) -> int:
    """How far the thread CPU clock moves per step: nanoseconds on a kernel that accounts CPU time precisely,
    a whole tick (10 ms) in the User Mode Linux guest (clock_getres says 1 ns on both). Busy-waits up to two
    steps, at most limit_ns."""
    give_up = time.monotonic_ns() + limit_ns
    first = time.thread_time_ns()
    while (second := time.thread_time_ns()) == first:      # the first change may be a partial step
        if time.monotonic_ns() > give_up:
            return limit_ns
    while (third := time.thread_time_ns()) == second:
        if time.monotonic_ns() > give_up:
            return limit_ns
    return third - second


# The sender thread's CPU clock. With paravirtual steal-time accounting (KVM guests, as here) it stops while the
# host runs someone else on the vCPU: a bare loop here saw wall gaps of 0.1-3.7 ms with 2-3 us of CPU in them
# (tools/bench_catch_up.py, 2026-12-02). What it does not exclude counts as the sender's own work, so the
# "stalled" cause (MISS_CAUSES) is then not given and the attribution errs towards blaming the emulator:
# interrupts (charged to the running thread without CONFIG_IRQ_TIME_ACCOUNTING, as here), and host time that is
# not steal (the same loop: 2-4 gaps a second of 0.1-1.2 ms that the CPU clock counts in full).
_cpu_ns = time.thread_time_ns


def context_switches() -> tuple[int, int]:
    """(involuntary, voluntary) context switches of this thread so far (getrusage RUSAGE_THREAD ru_nivcsw,
    ru_nvcsw; about 1 us a call here). Involuntary: the kernel took the CPU for another runnable thread. Voluntary:
    the thread slept, in its waits or blocked in a system call (a lock, a full buffer). The host taking the vCPU
    from the whole guest is neither: the guest never sees it, and such a miss is told by the CPU clock instead
    ("stalled", see MISS_CAUSES)."""
    usage = resource.getrusage(resource.RUSAGE_THREAD)
    return usage.ru_nivcsw, usage.ru_nvcsw


def usable_cpus() -> int:
    """CPUs this process may run on (affinity, cgroup cpusets), not the machine's count."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def default_mode(cpus: int) -> str:
    """`auto`: spin only when a core is left for the consumer. With one CPU, spinning or even a
    SCHED_FIFO sender takes the CPU from the program it feeds (issue 16: candump at normal priority
    in a one-CPU guest lost 22-47 % of the frames); tools/bench_coexist.py prints the figures behind this."""
    return "spin" if cpus >= 2 else "off"


@dataclass(frozen=True)
class RealtimeSetup:
    mode: str           # spin, fifo or off: what runs
    requested: str      # what was asked (auto or one of the modes)
    fifo: bool          # SCHED_FIFO granted for the wake-ups
    timer_slack: bool   # 1 ns timer slack set
    note: str           # why not, when not

    @property
    def spin(self) -> bool:
        return self.mode == "spin"

    def describe(self) -> str:
        chosen = self.mode if self.requested == self.mode else f"{self.mode} ({self.requested})"
        parts = [f"realtime {chosen}",
                 f"SCHED_FIFO priority {FIFO_PRIORITY}" if self.fifo else "normal scheduling",
                 "sleep then spin" if self.spin else "sleep, no spin",
                 "timer slack 1 ns" if self.timer_slack else "default timer slack"]
        return ", ".join(parts) + (f" ({self.note})" if self.note else "")


def enable_realtime(mode: str = "auto", cpus: int | None = None) -> RealtimeSetup:
    """Set up the calling thread for `mode` (auto: see default_mode); falls back quietly to normal
    scheduling when SCHED_FIFO is refused (not root, no CAP_SYS_NICE, RT budget exhausted)."""
    if mode not in MODES:
        raise ValueError(f"realtime mode {mode!r} (known: {', '.join(MODES)})")
    cpus = usable_cpus() if cpus is None else cpus
    chosen = default_mode(cpus) if mode == "auto" else mode
    notes = []
    if chosen == "spin" and cpus < 2:
        notes.append(f"spinning on {cpus} usable CPU takes it from the consumer")
    slack = False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        slack = libc.prctl(_PR_SET_TIMERSLACK, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        notes.append("prctl unavailable")
    fifo = False
    if chosen in ("spin", "fifo"):
        fifo, why = _set_fifo(True)
        if not fifo:
            notes.append(f"SCHED_FIFO refused: {why}")
    return RealtimeSetup(chosen, mode, fifo, slack, "; ".join(notes))


def _set_fifo(on: bool) -> tuple[bool, str]:
    if not hasattr(os, "sched_setscheduler"):
        return False, "not on this system"
    try:
        if on:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(FIFO_PRIORITY))
        else:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except OSError as exc:
        return False, exc.strerror or str(exc)
    return True, ""


def drop_realtime() -> None:
    """Back to normal scheduling for the calling thread (helpers that compute must never run RT)."""
    _set_fifo(False)


class Pacer:
    """Wait until an absolute monotonic deadline: sleep (watching the links' descriptors), then with
    `spin` busy-wait the last stretch.

    fifo: the thread was granted SCHED_FIFO. The pacer gives it up while the sender is behind and takes it
    back before sleeping.
    """

    def __init__(self, fifo: bool = False, period_ns: float = 1e6, spin: bool = True):
        self.fifo = fifo
        self.period_ns = period_ns
        self.spin_ns = int(min(_SPIN_NS, _SPIN_SHARE * period_ns)) if spin else 0
        self._normal = False        # fifo granted but given up for now
        self._behind_ns = max(period_ns, _BEHIND_NS)
        self.fifo_given_up = 0      # times the sender fell _BEHIND_NS behind and gave SCHED_FIFO up
        self._sent_ns = 0            # when the last wait ended
        self._spaced = not fifo      # catch up spaced out (normal scheduling from the start)
        self._behind_cpu_ns = 0      # thread CPU time at the previous sample, while behind and spaced
        self._cpu_step_ns = None     # the thread CPU clock's step, measured the first time the sender is behind
        self.serve_margin_ns = _SERVE_MARGIN_NS
        self.serve_cost_ns = 0       # the dearest answer's thread CPU time so far
        # When the descriptors were last looked at: at high rates the whole period may be spin and margin,
        # and the caller then polls them itself after a send (see streamer).
        self.watched_ns = 0
        # When the sender last came to sleep_until: past the wake time, the previous sample's work (or a
        # block's arrival) made it late before any waiting began (the miss classification reads it).
        self.arrived_ns = 0
        # The thread's CPU clock at the end of its last wait for a deadline begun in time (own_cpu_ns), whether the
        # last wait_until was one (the caller then notes its voluntary context switches), and the wake time of the
        # last sleep begun in time
        self._on_time_cpu_ns = 0
        self.on_time = False
        self._slept_for_ns = None

    def _normal_priority(self) -> None:
        if self.fifo and not self._normal:
            self._normal = True
            _set_fifo(False)

    def _wake_priority(self) -> None:
        if self._normal:
            self._normal = False
            self.fifo = _set_fifo(True)[0]   # refused now (RT budget): stay normal for good

    def sleep_until(self, wake_ns: int, fds=(), on_ready=None) -> None:
        """Sleep until `wake_ns` (monotonic) or a little after, but while any of `fds` is readable call
        on_ready(readable fds) at once (it returns whether it found any input) and go back to sleep: replies go out between two deadlines.
        Input arriving within serve_margin_ns of the wake time waits in the kernel until after the
        deadline's send, so answering never makes a sample late. select() rather than poll/epoll because its
        timeout has microsecond resolution (theirs is ms)."""
        now = self.arrived_ns = time.monotonic_ns()
        early = wake_ns - now
        if early <= 0:
            return
        self._slept_for_ns = wake_ns
        self._wake_priority()
        while early > 0:
            if not fds or early <= self.serve_margin_ns:
                time.sleep(early / 1e9)
                return
            ready, _, _ = select.select(fds, (), (), (early - self.serve_margin_ns) / 1e9)
            self.watched_ns = time.monotonic_ns()
            if ready:
                cpu = time.thread_time_ns()
                if not on_ready(ready):
                    # Readable but nothing to read: a hang-up (a pty whose reader has gone away stays
                    # readable). Stop watching until this deadline instead of spinning on select.
                    fds = ()
                self._answered(time.thread_time_ns() - cpu)
            early = wake_ns - time.monotonic_ns()

    def _answered(self, cpu_ns: int) -> None:
        """Size the serve margin to the dearest answer so far (CPU time: a preemption is not its cost)."""
        if cpu_ns > self.serve_cost_ns or self.serve_margin_ns == _SERVE_MARGIN_NS:
            self.serve_cost_ns = max(self.serve_cost_ns, cpu_ns)
            self.serve_margin_ns = min(_SERVE_MARGIN_NS, max(_MIN_SERVE_MARGIN_NS,
                                                             2 * self.serve_cost_ns + _SERVE_SLACK_NS))

    def own_cpu_ns(self) -> int:
        """CPU time the calling thread has used since the end of its last wait for a deadline begun in time (all of
        it, before the first): the sender's own work since it was last on time. A pacer with nothing to do (the
        machine's floor), stopped alike, would hand a sample over now late by this much less."""
        return _cpu_ns() - self._on_time_cpu_ns

    def wait_until(self, deadline_ns: int, fds=(), on_ready=None) -> int:
        """Returns the time we woke (ns, monotonic), at or after the deadline; input on `fds` is handed to
        on_ready while sleeping (never while spinning)."""
        wake_ns = deadline_ns - self.spin_ns
        self.sleep_until(wake_ns, fds, on_ready)
        now = time.monotonic_ns()
        self.on_time = now < deadline_ns or self._slept_for_ns == wake_ns
        if self.on_time:
            while now < deadline_ns:
                now = time.monotonic_ns()
            # It waited for this deadline (here, or in the caller's sleep_until to the same wake time): the
            # sender's own work is counted from now (a read of about 0.5 us, before the send).
            self._on_time_cpu_ns = _cpu_ns()
        if now - deadline_ns > self._behind_ns and self.fifo and not self._normal:
            self.fifo_given_up += 1
            self._normal_priority()
        if now - deadline_ns > self.period_ns and self._spaced:
            # Behind in `off` mode: catch up at twice the rate, not in one burst, so that a reader sharing the
            # CPU runs between samples (in the one-CPU guest a burst overflowed candump's receive buffer).
            # Not for a sender that gave SCHED_FIFO up: it had a core of its own, and a long catch-up after
            # answering a flood of commands would miss hundreds of deadlines.
            # A sender whose own work per sample exceeds half a period (the one-CPU guest at 1 kHz, where a
            # system call costs tens of microseconds) would never sleep: then it sleeps as long as it worked
            # (its CPU time since the previous sample, read only while behind), so a reader sharing the CPU
            # keeps at least half of it and the sender ends late instead.
            # Where CPU time is accounted per tick (the User Mode Linux guest: thread CPU time moves in 10 ms
            # steps), the CPU clock reads 0 for most samples and the sender would not sleep at all, bursting
            # through candump's receive buffer: there the work is the wall time since the previous wake.
            cpu = time.thread_time_ns()
            if self._cpu_step_ns is None:
                self._cpu_step_ns = cpu_clock_step_ns()
            if self._cpu_step_ns > _FINE_CPU_CLOCK_NS:
                worked = now - self._sent_ns
            else:
                worked = cpu - self._behind_cpu_ns if self._behind_cpu_ns else 0
            gap = max(self._sent_ns + self.period_ns // 2 - now, min(worked, self._behind_ns))
            if gap > 0:
                time.sleep(gap / 1e9)
                now = time.monotonic_ns()
            self._behind_cpu_ns = cpu
        else:
            self._behind_cpu_ns = 0
        self._sent_ns = now
        return now


# Why a deadline was missed (later than one period), as the send loop tells it apart; the first that applies is
# counted, in this order, so the counts add up to the misses:
MISS_CAUSES = {
    "producer": "the producer's block was not there by the deadline",
    "input": "input from a link was being served when the deadline passed",
    "preempted": "preempted: the kernel ran another thread on this CPU since the previous deadline "
                 "(involuntary context switch)",
    "stalled": "stalled: a pacer with nothing to do, stopped alike, would have missed it too (the lateness less the "
               "sender's own CPU time since it was last on time is still more than a period, and it did not block "
               "in the kernel since): the host took the vCPU, the floor's kind",
    "catching_up": "still behind after the previous deadline's miss",
    "block_handover": "taking the producer's next block (early, after a send that left slack, or at the current "
                      "block's end; it was there) ended after the deadline that followed",
    "previous_work": "the previous sample's work (send, status, taking the next block) ended after this deadline",
    "woke_late": "woke late with nothing above seen: the timer, or the host where its time counts as the sender's",
}


class LatenessStats:
    """Lateness against deadlines with bounded memory: a histogram of 1 us bins up to 65.5 ms, then of 1 ms bins up
    to 65.5 s, plus the exact maximum and a count of misses. A quantile beyond the histogram is None ("more than
    OVER_US"), never the bound read as a measurement: a stream minutes behind once printed p50 65535 us.

    `add` is O(1) plain Python on purpose: batching values into numpy every N samples cost up to a few
    hundred microseconds at once, which is several deadlines at 10 kHz."""

    BINS = 65536
    OVER_US = BINS * 1000                 # the coarse bins' end: 65.536 s

    def __init__(self, period_ns: float):
        self.period_ns = period_ns
        self.hist = [0] * self.BINS       # 1 us bins
        self.coarse = [0] * (self.BINS + 1)   # 1 ms bins from 0 (the first 65 hold nothing), the last: beyond
        self.count = 0
        self.max_ns = 0
        self.missed = 0       # later than one period
        self.missed_by_cause = dict.fromkeys(MISS_CAUSES, 0)   # for senders that classify (classify)

    def classify(self, cause: str) -> None:
        """Count one miss (already counted by add) under its cause, one of MISS_CAUSES."""
        self.missed_by_cause[cause] += 1

    def add(self, lateness_ns: int) -> None:
        self.count += 1
        if lateness_ns > self.max_ns:
            self.max_ns = lateness_ns
        if lateness_ns > self.period_ns:
            self.missed += 1
        us = max(lateness_ns // 1000, 0)
        if us < self.BINS:
            self.hist[us] += 1
        else:
            self.coarse[min(us // 1000, self.BINS)] += 1

    def quantile_us(self, q: float) -> float | None:
        """The q-quantile's bin, in us (its lower edge); None when it lies beyond OVER_US."""
        if not self.count:
            return 0.0
        rank = max(int(np.ceil(q * self.count)), 1)
        fine = np.cumsum(self.hist)
        if rank <= fine[-1]:
            return float(np.searchsorted(fine, rank))
        coarse = int(np.searchsorted(np.cumsum(self.coarse), rank - fine[-1]))
        return None if coarse >= self.BINS else float(coarse * 1000)

    @classmethod
    def shown(cls, us: float | None) -> str:
        """A quantile as a status line prints it."""
        return f"> {cls.OVER_US}" if us is None else f"{us:.0f}"

    def summary(self) -> dict:
        return {"p50_us": self.quantile_us(0.5), "p99_us": self.quantile_us(0.99),
                "p999_us": self.quantile_us(0.999), "max_us": self.max_ns / 1000,
                "over_us": self.OVER_US,        # a quantile of None: later than this
                "missed": self.missed, "missed_ratio": self.missed / self.count if self.count else 0.0,
                "missed_by_cause": dict(self.missed_by_cause)}

    @staticmethod
    def causes_text(by_cause: dict) -> str:
        """The non-zero miss counts by cause, as the summary prints them ("" when none)."""
        return ", ".join(f"{n} {cause.replace('_', ' ')}" for cause, n in by_cause.items() if n)
