"""Issue 25: every deadline the send loop misses is counted under one cause (realtime.MISS_CAUSES), and the counts
add up to the misses. Doubles stand in for the producer's pipe and the transport: a block that comes three periods
after its first deadline, a send that takes three periods. The delays are sleeps of three periods, so each one surely
makes the next deadline late by more than a period (a sleep never returns early); nothing here asserts a duration,
and the kernel preempting the test is kept out of the causes by a constant context-switch count."""
from __future__ import annotations

import os
import select
import time
from types import SimpleNamespace

import pytest

from imu_emulator.live import realtime
from imu_emulator.live import streamer as streamer_module
from imu_emulator.live.config import RunOptions
from imu_emulator.live.realtime import MISS_CAUSES, LatenessStats, Pacer
from imu_emulator.live.stream import Stream
from imu_emulator.live.streamer import Streamer, miss_cause
from imu_emulator.live.transport.base import Transport

pytestmark = pytest.mark.realtime

RATE = 1000.0
PERIOD_NS = 1_000_000
BLOCK = 20
BLOCKS = 6


class _Transport(Transport):
    """A one-way link without a descriptor; every `slow_every`-th send takes `slow_periods` periods. What was sent
    is kept, one entry per send."""

    def __init__(self, slow_every: int = 0, slow_periods: int = 3, joins_writes: bool = False):
        self.slow_every, self.slow_periods = slow_every, slow_periods
        self.joins_writes = joins_writes
        self.sends = 0
        self.slow = 0
        self.slept_ns = 0       # wall time spent in the slow sends' sleeps
        self.payloads = []

    def fileno(self):
        return None

    def send(self, payload) -> bool:
        self.sends += 1
        self.payloads.append(payload)
        if self.slow_every and self.sends % self.slow_every == 0:
            self.slow += 1
            began = time.monotonic_ns()
            time.sleep(self.slow_periods * PERIOD_NS / 1e9)
            self.slept_ns += time.monotonic_ns() - began
        return True


class _Pipe:
    """The producer's pipe: blocks of BLOCK samples; the blocks listed in `late` are not there until three periods
    after their first deadline. Its descriptor (a real pipe's) is readable exactly when the next block is there."""

    def __init__(self, start_ns: int, late=()):
        self.start_ns = start_ns
        self.late = set(late)
        self.next = 0
        self.r, self.w = os.pipe()
        self._mark()

    def _mark(self):
        readable = bool(select.select((self.r,), (), (), 0)[0])
        if self.next in self.late and readable:
            os.read(self.r, 1)
        elif self.next not in self.late and not readable:
            os.write(self.w, b"x")

    def fileno(self):
        return self.r

    def poll(self, timeout=0) -> bool:
        return bool(select.select((self.r,), (), (), timeout)[0])

    def recv(self):
        n = self.next
        self.next += 1
        if n in self.late:
            wake = self.start_ns + (n * BLOCK + 3) * PERIOD_NS
            time.sleep(max(0, wake - time.monotonic_ns()) / 1e9 + 1e-4)
        self._mark()
        return None if n == BLOCKS else _Block(n * BLOCK)

    def close(self):
        os.close(self.r)
        os.close(self.w)


def _payload(j: int) -> bytes:
    """Sample j's packet: each sample's its own, so order and losses show."""
    return b"<%04d>" % j


class _Block:
    def __init__(self, j0):
        self.j0, self.saturated, self.counts = j0, [0], {}
        self.items = [[_payload(j) for j in range(j0, j0 + BLOCK)]]

    def __len__(self):
        return BLOCK


class _Stream:
    """A stream without a device around a double of a transport: the real stream's way of sending a catch-up."""
    device = None
    send_samples = Stream.send_samples

    def __init__(self, transport):
        self.transport = transport
        self.sent = self.dropped = self.idle = self.saturated = 0

    def send_waiting_replies(self) -> bool:
        return True

    def sample_queue(self) -> None:
        pass


def _run(monkeypatch, transport, late_blocks=(), host_stalls=False, switches=lambda: (0, 0)) -> LatenessStats:
    """One run of the send loop. The thread's CPU clock is the wall clock (a machine whose host never takes the
    vCPU: the doubles' sleeps are the sender's own work), or with host_stalls the wall clock less the slow sends'
    sleeps (they stand for the host taking the vCPU: the clock stops, and nothing else can look like it). `switches`:
    the thread's (involuntary, voluntary) context switches, constant unless given (so the kernel preempting the
    test changes no cause)."""
    monkeypatch.setattr(streamer_module, "context_switches", switches)
    monkeypatch.setattr(realtime, "_cpu_ns", (lambda: time.monotonic_ns() - transport.slept_ns) if host_stalls
                        else time.monotonic_ns)
    sim = SimpleNamespace(n_samples=BLOCK * BLOCKS)
    streamer = Streamer(sim, RATE, 0.0, [_Stream(transport)], RunOptions(quiet=True))
    streamer.pacer = pacer = Pacer(False, PERIOD_NS, spin=False)
    start = time.monotonic_ns() + 5 * PERIOD_NS
    pipe = _Pipe(start, late_blocks)
    try:
        streamer._send_loop(pipe, pacer, start)
    finally:
        pipe.close()
    assert streamer.samples_done == BLOCK * BLOCKS
    return streamer.stats


def test_late_blocks_are_counted_as_the_producers_and_the_causes_add_up(monkeypatch):
    stats = _run(monkeypatch, _Transport(), late_blocks=(2, 4))
    causes = stats.summary()["missed_by_cause"]
    assert set(causes) == set(MISS_CAUSES)
    assert sum(causes.values()) == stats.missed >= 2
    assert causes["producer"] == 2            # each late block's first deadline, once


def test_a_send_longer_than_a_period_makes_the_next_deadline_the_previous_works(monkeypatch):
    transport = _Transport(slow_every=25)
    stats = _run(monkeypatch, transport)
    causes = stats.summary()["missed_by_cause"]
    assert sum(causes.values()) == stats.missed
    assert transport.slow == BLOCK * BLOCKS // 25
    # The sample after each slow send is missed first for the previous work (unless the kernel also delayed the
    # wake of the slow one: then that one was missed and this one is catching up); none is the producer's.
    assert causes["previous_work"] + causes["catching_up"] >= transport.slow
    assert causes["previous_work"] >= 1 and causes["producer"] == 0


def test_the_samples_a_stall_made_due_go_out_in_one_write_in_order(monkeypatch):
    """Send 25 takes five periods: when it returns, the next five samples are due (a sleep never returns early) and
    go out in one write (all of them the block still holds), each counted late by its own deadline; a byte
    stream's reader sees every sample's packet, in order, as if they had been written one by one."""
    transport = _Transport(slow_every=25, slow_periods=5, joins_writes=True)
    stats = _run(monkeypatch, transport)
    size = len(_payload(0))
    assert b"".join(transport.payloads) == b"".join(map(_payload, range(BLOCK * BLOCKS)))
    after = transport.payloads[25]      # the write after the slow one
    first = int(after[1:5])
    assert len(after) >= size * min(5, BLOCK - first % BLOCK)
    assert transport.sends < BLOCK * BLOCKS
    assert stats.count == BLOCK * BLOCKS              # every sample's lateness, batched or not
    causes = stats.summary()["missed_by_cause"]
    assert sum(causes.values()) == stats.missed
    assert causes["catching_up"] >= 3                 # samples 26-28 at least: each more than a period late


def test_a_link_that_cannot_join_writes_gets_one_send_per_sample(monkeypatch):
    transport = _Transport(slow_every=25, slow_periods=5, joins_writes=False)
    stats = _run(monkeypatch, transport)
    assert transport.payloads == list(map(_payload, range(BLOCK * BLOCKS)))
    assert stats.count == BLOCK * BLOCKS


def test_a_stall_the_sender_did_not_spend_is_counted_as_the_floors(monkeypatch):
    """The same five-period sends, but the CPU clock stands still while they sleep: as if the host had taken the
    vCPU. A pacer with nothing to do stopped alike would have missed those deadlines
    too, so they are "stalled", not the sender's previous work or catching up; nothing else changes."""
    transport = _Transport(slow_every=25, slow_periods=5, joins_writes=True)
    stats = _run(monkeypatch, transport, host_stalls=True)
    causes = stats.summary()["missed_by_cause"]
    assert sum(causes.values()) == stats.missed
    assert causes["stalled"] >= 3 * transport.slow     # four deadlines passed in each sleep: 3 of them by > 1 period
    assert b"".join(transport.payloads) == b"".join(map(_payload, range(BLOCK * BLOCKS)))


def test_a_sender_that_blocked_in_the_kernel_is_not_stalled(monkeypatch):
    """The same sleeping sends and CPU clock, but each sleep is seen as what it is, a voluntary context switch (as
    a write blocked on a lock would be): the sender's own doing, whatever its CPU clock says."""
    transport = _Transport(slow_every=25, slow_periods=5, joins_writes=True)
    sample_causes = {}
    classify = LatenessStats.classify
    monkeypatch.setattr(LatenessStats, "classify",
                        lambda self, cause: sample_causes.setdefault(self.count - 1, cause) and classify(self, cause))
    stats = _run(monkeypatch, transport, host_stalls=True, switches=lambda: (0, transport.slow))
    causes = stats.summary()["missed_by_cause"]
    assert sum(causes.values()) == stats.missed >= 3 * transport.slow
    # the sample after each slow send (its first sample is in the payload): the sender's doing. (A wait the loaded
    # machine overslept elsewhere is "stalled", rightly: the floor's kind.)
    slow_sends = transport.payloads[transport.slow_every - 1::transport.slow_every]
    after = [sample_causes[int(payload[1:5]) + len(payload) // len(_payload(0))] for payload in slow_sends]
    assert len(after) == transport.slow and "stalled" not in after


def test_own_cpu_is_counted_from_the_end_of_the_last_wait_begun_in_time(monkeypatch):
    clock = [1_000]
    monkeypatch.setattr(realtime, "_cpu_ns", lambda: clock[0])
    pacer = Pacer(False, PERIOD_NS, spin=True)
    assert pacer.own_cpu_ns() == 1_000                  # never waited yet: all of the thread's CPU is its own
    clock[0] = 5_000
    pacer.wait_until(time.monotonic_ns() + 300_000)     # begun in time: the clock is read at its end
    clock[0] = 55_000
    pacer.wait_until(time.monotonic_ns() - PERIOD_NS)   # begun after its deadline: not read
    assert pacer.own_cpu_ns() == 50_000


_PRECEDENCE = [
    ((True, True, True, True, True, True, True), "producer"),
    ((False, True, True, True, True, True, True), "input"),
    ((False, False, True, True, True, True, True), "preempted"),
    ((False, False, False, True, True, True, True), "stalled"),
    ((False, False, False, False, True, True, True), "catching_up"),
    ((False, False, False, False, False, True, True), "block_handover"),
    ((False, False, False, False, False, True, False), "previous_work"),
    ((False, False, False, False, False, False, False), "woke_late"),
]


@pytest.mark.parametrize("flags, cause", _PRECEDENCE)
def test_the_first_cause_that_applies_is_counted(flags, cause):
    block_late, serving, preempted, stalled, missed_before, arrived_late, handover_late = flags
    assert miss_cause(block_late, serving, preempted, missed_before, arrived_late, handover_late, stalled) == cause


def test_causes_are_documented_in_the_order_they_are_tried():
    assert [cause for _, cause in _PRECEDENCE] == list(MISS_CAUSES)


def test_summary_text_names_each_cause_with_misses():
    assert LatenessStats.causes_text({"producer": 2, "input": 0, "catching_up": 5}) == "2 producer, 5 catching up"
    assert LatenessStats.causes_text(dict.fromkeys(MISS_CAUSES, 0)) == ""
