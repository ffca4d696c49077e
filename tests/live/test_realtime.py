"""The pacer, its scheduling modes and statistics, what links report, and completeness at a reader that runs at
normal priority beside a CPU-bound competitor. Timing checks use medians with wide margins: the machine is
shared; figures come from tools/bench_stream.py and tools/bench_coexist.py."""
import json
import os
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from imu_emulator.live import realtime
from imu_emulator.live.realtime import LatenessStats, Pacer, drop_realtime, enable_realtime
from imu_emulator.live.transport import TargetOptions
from imu_emulator.live.transport.pty import PtyTransport
from imu_emulator.live.transport.udp import UdpTransport
from tests.support.stream import Emulator, mavlink_parse, open_pty_reader, read_for, read_until_closed, write_scene
from tests.support.timing import scaled

pytestmark = pytest.mark.realtime


def test_lateness_quantiles_from_histogram():
    stats = LatenessStats(period_ns=900_000)
    for us in range(1, 1001):
        stats.add(us * 1000)
    summary = stats.summary()
    assert summary["p50_us"] == 500
    assert summary["p99_us"] == 990
    assert summary["max_us"] == 1000
    assert summary["missed"] == 100


def test_lateness_beyond_histogram_keeps_exact_maximum():
    stats = LatenessStats(period_ns=1e6)
    stats.add(5_000_000_000)
    assert stats.summary()["max_us"] == 5_000_000


def test_lateness_beyond_the_fine_bins_is_measured_and_beyond_all_bins_is_not_a_number():
    """A stream 100 ms to minutes behind (issue 23, item 12: 'p50 65535 us p99 65535 us' for a stream 11-204 s
    late). 100 ms and 20 s land in the 1 ms bins; 200 s is beyond them: its quantile is None, shown as '> 65536000'."""
    stats = LatenessStats(period_ns=1e6)
    for lateness_s in [0.1] * 60 + [20.0] * 30 + [200.0] * 10:
        stats.add(int(lateness_s * 1e9))
    summary = stats.summary()
    assert summary["p50_us"] == 100_000                 # rank 50 of 100: the 100 ms samples' 1 ms bin
    assert summary["p99_us"] is None                   # rank 99: a 200 s sample, beyond 65.536 s
    assert stats.quantile_us(0.9) == 20_000_000          # rank 90: the last 20 s sample
    assert summary["max_us"] == 200_000_000 and summary["over_us"] == 65_536_000
    assert json.loads(json.dumps(summary))["p99_us"] is None     # --stats-json stays valid JSON
    assert [LatenessStats.shown(summary[k]) for k in ("p50_us", "p99_us")] == ["100000", "> 65536000"]


def _lateness(pacer, period_ns=5_000_000, count=60):
    start = time.monotonic_ns() + period_ns
    return [pacer.wait_until(start + k * period_ns) - (start + k * period_ns) for k in range(count)]


@pytest.mark.parametrize("spin", [True, False], ids=["sleep-then-spin", "sleep-only"])
def test_pacer_never_returns_before_its_deadline_at_200hz(spin):
    # A lower bound, true however loaded the machine: how late it returns is a figure (tools/bench_stream.py
    # prints the stream's lateness p50/p99 at each rate; tools/bench_coexist.py beside a competitor).
    assert min(_lateness(Pacer(fifo=False, spin=spin))) >= 0


@pytest.fixture
def scheduler_calls(monkeypatch):
    """sched_setscheduler recorded and granted, without changing this thread's scheduling."""
    calls = []
    monkeypatch.setattr("os.sched_setscheduler", lambda pid, policy, param: calls.append(policy))
    return calls


@pytest.mark.parametrize("cpus, mode, policies", [
    (1, "off", []),                      # one CPU: neither spin nor SCHED_FIFO by default
    (2, "spin", [os.SCHED_FIFO]),
    (8, "spin", [os.SCHED_FIFO]),
])
def test_default_mode_spins_only_when_a_core_is_left(scheduler_calls, cpus, mode, policies):
    setup = enable_realtime("auto", cpus=cpus)
    assert (setup.mode, setup.requested) == (mode, "auto")
    assert scheduler_calls == policies


@pytest.mark.parametrize("mode, fifo, spin", [("spin", True, True), ("fifo", True, False), ("off", False, False)])
def test_explicit_modes(scheduler_calls, mode, fifo, spin):
    setup = enable_realtime(mode, cpus=1)
    assert (setup.mode, setup.fifo, setup.spin) == (mode, fifo, spin)
    assert scheduler_calls == ([os.SCHED_FIFO] if fifo else [])
    assert ("takes it from the consumer" in setup.note) == (mode == "spin")   # spin on one CPU is warned about


def test_usable_cpus_follows_affinity():
    # The child restricts itself to one CPU first: the count is the affinity's, not the machine's.
    cpu = min(os.sched_getaffinity(0))
    out = subprocess.run([sys.executable, "-c", f"import os; os.sched_setaffinity(0, {{{cpu}}}); "
                          "from imu_emulator.live.realtime import usable_cpus; print(usable_cpus())"],
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "1"


def test_sender_that_falls_behind_gives_up_fifo_until_it_sleeps_again(scheduler_calls):
    period = 1_000_000
    pacer = Pacer(fifo=True, period_ns=period, spin=False)
    now = time.monotonic_ns()
    pacer.wait_until(now - 5 * period)              # a short stall (the vCPU taken away): caught up under FIFO
    assert scheduler_calls == []
    pacer.wait_until(now - 150 * period)            # 150 ms behind: it cannot keep up
    assert pacer.fifo_given_up == 1 and scheduler_calls == [os.SCHED_OTHER]
    pacer.wait_until(now - 149 * period)            # still behind: no further system call
    assert pacer.fifo_given_up == 1 and scheduler_calls == [os.SCHED_OTHER]
    pacer.wait_until(time.monotonic_ns() + 2 * period)   # on time again: SCHED_FIFO back for the sleep
    assert scheduler_calls == [os.SCHED_OTHER, os.SCHED_FIFO]


def test_sender_behind_at_normal_priority_catches_up_at_twice_the_rate_not_in_a_burst():
    # Deadlines long past: a burst would return at once; spaced, consecutive returns are at least half a period
    # apart (a lower bound time.sleep guarantees, so this holds however loaded the machine is).
    period = 2_000_000
    pacer = Pacer(fifo=False, period_ns=period, spin=False)
    past = time.monotonic_ns() - 1_000 * period
    woke = [pacer.wait_until(past + k * period) for k in range(10)]
    assert min(np.diff(woke)) >= period // 2


def test_sender_whose_work_exceeds_half_a_period_leaves_the_cpu_half_the_time():
    # Each sample costs W = 3 ms of CPU at a 2 ms period: spacing by half a period alone would never sleep.
    # The pacer sleeps at least as long as the sample's CPU time, so consecutive wakes are at least 2 W apart
    # (lower bounds again: busy CPU time cannot pass faster than wall time, sleeps never end early).
    period, work = 2_000_000, 3_000_000
    pacer = Pacer(fifo=False, period_ns=period, spin=False)
    past = time.monotonic_ns() - 1_000 * period
    woke = []
    for k in range(6):
        woke.append(pacer.wait_until(past + k * period))
        start = time.thread_time_ns()
        while time.thread_time_ns() - start < work:
            pass
    assert min(np.diff(woke[1:])) >= 2 * work


def test_realtime_request_falls_back_gracefully(monkeypatch):
    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr("os.sched_setscheduler", refuse)
    setup = enable_realtime("fifo")
    assert not setup.fifo
    assert "SCHED_FIFO refused: Operation not permitted" in setup.describe()


def test_realtime_granted_or_refused_without_error():
    result = {}

    def ask():   # in a thread: SCHED_FIFO applies to the calling thread only
        result["setup"] = enable_realtime("fifo")
        result["policy"] = os.sched_getscheduler(0)
        drop_realtime()

    thread = threading.Thread(target=ask)
    thread.start()
    thread.join()
    setup = result["setup"]
    assert setup.fifo or "refused" in setup.note
    if setup.fifo:
        assert result["policy"] == os.SCHED_FIFO
        assert os.sched_getparam(0).sched_priority == 0   # this (main) thread untouched
    assert realtime.FIFO_PRIORITY < 10   # below ArduPilot's Linux HAL threads (SCHED_FIFO 10-20)


# --- what the link reports ---------------------------------------------------------------------

def test_pty_refusals_counted_by_cause_and_unread_bytes_reported_at_close():
    transport = PtyTransport(TargetOptions())
    try:
        packet = b"x" * 60
        assert not transport.send(packet)                 # nobody has the port open
        fd = open_pty_reader(transport.pty.path)          # a reader that never reads
        refused = sum(not transport.send(packet) for _ in range(1000))   # 60 kB: the pty holds ~16 kB
        assert refused > 0
        assert transport.link_report()["send_errors"] == {"no-reader": 1, "EAGAIN": refused}
        transport.finish()      # the reader takes nothing: gives up after a short wait
        accepted = 1000 - refused
        assert transport.link_report()["unread_lost"] == {"packets": accepted, "bytes": 60 * accepted, "readers": 1}
        os.close(fd)
    finally:
        transport.close()


def test_pty_packets_a_reader_leaves_unread_when_it_closes_are_counted_exactly():
    """Issue 23 item 9: a reader that reads slowly and closes leaves packets the emulator counted as sent in the
    pty (about 20 kB); they were flushed uncounted. Sent minus received must equal the packets counted lost,
    for each of two readers one after the other, with packets of several sizes."""
    transport = PtyTransport(TargetOptions())
    sizes = [37, 101, 64, 250]
    received = sent = 0
    try:
        for reader in range(2):
            fd = open_pty_reader(transport.pty.path)
            got = bytearray()
            for k in range(300):
                size = sizes[k % len(sizes)]
                # Each packet is its size repeated: a parser of this toy format tells packets apart.
                if transport.send(bytes([size]) * size):
                    sent += 1
                if k % 10 == 0:
                    got += read_for(fd, 0.001, stop_after=300)    # a slow reader: far less than is sent
            os.close(fd)
            received += _whole_packets(bytes(got))
            assert not transport.send(b"\x01")      # the reader has gone: refused, and its leftovers counted
        lost = transport.link_report()["unread_lost"]
        assert lost["readers"] == 2
        assert sent - received == lost["packets"] > 0
    finally:
        transport.close()


def _whole_packets(data: bytes) -> int:
    """Whole packets of the toy format at the start of `data` (a packet the reader got only the head of is lost)."""
    count = at = 0
    while at < len(data) and at + data[at] <= len(data):
        assert data[at:at + data[at]] == bytes([data[at]]) * data[at]
        at += data[at]
        count += 1
    return count


def test_pty_reader_that_took_everything_leaves_nothing_unread():
    transport = PtyTransport(TargetOptions())
    try:
        fd = open_pty_reader(transport.pty.path)
        assert transport.send(b"y" * 500)
        got = read_for(fd, 2.0, stop_after=500)
        transport.finish()
        os.close(fd)
        assert got == b"y" * 500
        assert transport.link_report() == {}
    finally:
        transport.close()


def test_udp_refusal_carries_the_kernels_errno():
    closed = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closed.bind(("127.0.0.1", 0))
    port = closed.getsockname()[1]
    closed.close()   # nobody listens: the kernel answers ICMP port unreachable, the next send gets ECONNREFUSED
    transport = UdpTransport("127.0.0.1", port, TargetOptions())
    try:
        results = [transport.send(b"z") for _ in range(3)]
        time.sleep(0.05)
        results += [transport.send(b"z") for _ in range(3)]
        assert transport.link_report()["send_errors"] == {"ECONNREFUSED": results.count(False)}
        assert results.count(False) >= 1
        assert transport.queued() == 0
    finally:
        transport.close()


# --- completeness at a reader beside a CPU-bound competitor ---------------------------------------

def test_pty_reader_at_normal_priority_beside_a_busy_loop_receives_every_sample(tmp_path):
    """Default settings, mavlink-highres at 1 kHz; this process reads at normal priority while a busy loop
    runs. Every sample must arrive: each HIGHRES_IMU time stamp once, the MAVLink sequence (HEARTBEATs
    included) without a gap."""
    rate, seconds = 1000, 3
    scene_path = write_scene(tmp_path, rate=rate, duration=seconds + 1)
    stats = tmp_path / "stats.json"
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        with Emulator(scene_path, "--format", "mavlink-highres", "--to", "pty", "--duration", seconds,
                      "--stats-json", stats) as emu:
            fd = open_pty_reader(emu.targets[0])
            data = read_until_closed(fd)
            code, err = emu.wait()
    finally:
        busy.kill()
        busy.wait()
    assert code == 0, err
    summary = json.loads(stats.read_text())
    link = summary["streams"][0]["link"]
    every, bad = mavlink_parse(data, types=None)
    assert not bad
    assert set(np.diff([m.get_seq() for m in every]) % 256) == {1}
    k = sorted(round(m.time_usec * 1e-6 * rate) for m in every if m.get_type() == "HIGHRES_IMU")
    # Samples due before the reader opened the port are dropped as "no-reader" (a late reader gets current
    # samples); from then on, every one.
    before_reader = link.get("send_errors", {}).get("no-reader", 0)
    assert summary["dropped"] == before_reader and not link.get("unread_lost")
    assert k == list(range(before_reader, rate * seconds))


def test_serve_margin_follows_the_dearest_answer_within_its_bounds():
    """Input is not served within serve_margin_ns of a wake-up; the margin is twice the dearest answer's CPU time
    plus 30 us of slack, never under 50 us nor over the 300 us it starts at (module constants)."""
    from imu_emulator.live import realtime
    pacer = Pacer(fifo=False, period_ns=1_000_000)
    assert pacer.serve_margin_ns == realtime._SERVE_MARGIN_NS == 300_000
    pacer._answered(20_000)
    assert pacer.serve_margin_ns == 2 * 20_000 + 30_000
    pacer._answered(5_000)          # a cheaper answer later does not shrink it: the dearest one counts
    assert pacer.serve_margin_ns == 70_000
    pacer._answered(400_000)
    assert pacer.serve_margin_ns == 300_000
    fresh = Pacer(fifo=False)
    fresh._answered(1_000)
    assert fresh.serve_margin_ns == 50_000


def test_cpu_clock_step_is_fine_here_and_the_pacer_times_work_by_wall_time_where_it_is_coarse(monkeypatch):
    # This host accounts CPU time to the ns; the UML guest moves it in 10 ms ticks. There a behind sender
    # reading its CPU time would see 0 for most samples and never sleep: it must then sleep as long as the
    # wall time its previous sample took (2 ms of work here, at a 1 ms period).
    fine = time.thread_time_ns
    ticks = iter(range(0, 10**9, 7))          # a clock that moves 7 ns a read: precise accounting, on any host
    monkeypatch.setattr(realtime.time, "thread_time_ns", lambda: next(ticks))
    assert realtime.cpu_clock_step_ns() == 7 < realtime._FINE_CPU_CLOCK_NS
    reads = iter(range(10**9))                # 10 ms ticks, one every 1000 reads (the UML guest's accounting)
    monkeypatch.setattr(realtime.time, "thread_time_ns", lambda: next(reads) // 1000 * 10_000_000)
    assert realtime.cpu_clock_step_ns() == 10_000_000
    monkeypatch.setattr(realtime.time, "thread_time_ns", lambda: fine() // 10_000_000 * 10_000_000)
    period, work = 1_000_000, 2_000_000
    woke = []

    def send():
        pacer = Pacer(fifo=False, period_ns=period, spin=False)
        past = time.monotonic_ns() - 1_000 * period
        for k in range(6):
            woke.append(pacer.wait_until(past + k * period))
            start = time.monotonic_ns()
            while time.monotonic_ns() - start < work:
                pass

    thread = threading.Thread(target=send)
    thread.start()
    thread.join()
    assert min(np.diff(woke[1:])) >= 2 * work


def _terminal(writes: list[str]) -> str:
    """The line a terminal shows after `writes`: '\r' returns to column 0, ESC [K clears to the line's end,
    other characters overwrite."""
    line, col = [], 0
    for text in writes:
        i = 0
        while i < len(text):
            if text.startswith("\x1b[K", i):
                del line[col:]
                i += 3
                continue
            if text[i] == "\r":
                col = 0
            else:
                line[col:col + 1] = [text[i]]
                col += 1
            i += 1
    return "".join(line)


def test_a_status_line_rewritten_shorter_leaves_no_tail():
    """Issue 23, item 12: 'saturated 0ted 0' was the tail of a longer line left behind by a shorter one."""
    from imu_emulator.live.streamer import status_line
    long, short = "streaming: 10 samples, dropped 0, saturated 0", "streaming: 12 samples, saturated 0"
    shown = _terminal(["".join(status_line(long, tty=True)), "".join(status_line(short, tty=True))])
    assert shown == short
    assert status_line(short, tty=False) == (short, "\n")        # logs and pipes: one plain line each


# --- replies while the producer is late (issue 23 item 7) ---------------------------------------------------

def test_commands_are_answered_while_the_sender_waits_for_a_late_block():
    """The send loop waits for the producer's next block (at start-up, or when the simulation falls behind under
    load); a driver's command arriving then is answered at once, once, not when the block comes (on 35a2177 the
    reply waited for the block: later than a driver's timeout when the producer is slow)."""
    import multiprocessing

    from imu_emulator.live.config import StreamConfig
    from imu_emulator.live.inputs import Inputs
    from imu_emulator.live.stream import build_streams

    stream, = build_streams([StreamConfig("imu", "vectornav-binary", "pty")], ("imu",), 100.0)
    stream.open()
    receiver, sender = multiprocessing.Pipe(duplex=False)
    fd = os.open(stream.transport.pty.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)     # a driver: reads, writes
    try:
        late_ns = int(scaled(0.6) * 1e9)      # the driver reads for half of it: a reply must fit in that
        threading.Timer(late_ns / 1e9, lambda: sender.send("the block")).start()
        os.write(fd, b"$VNRRG,01*XX\r\n")
        replies = []

        def driver():
            got = read_for(fd, 0.5 * late_ns / 1e9, stop_after=20)
            replies.append((time.monotonic_ns(), got))

        reader = threading.Thread(target=driver)
        started = time.monotonic_ns()
        reader.start()
        assert Inputs([stream], lambda text: None).next_block(receiver) == "the block"
        block_at = time.monotonic_ns()
        reader.join()
        (answered_at, got), = replies
        assert got == b"$VNRRG,01,VN-100T-CR*32\r\n"           # answered once
        assert answered_at < block_at and block_at - started >= late_ns * 0.9
        assert stream.replies_sent == 1 and stream.device.stats.commands == 1
    finally:
        os.close(fd)
        stream.close()
