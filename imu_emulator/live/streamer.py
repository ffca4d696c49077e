"""Live streaming: scene blocks -> Samples -> wire format encoder or device -> transport, at wall-clock rate.

A producer process computes blocks ahead of time into a pipe (bounded by its buffer). For a stream without a
device it also encodes them, and the send loop only waits for each sample's deadline and hands prepared
packets to the transport. A stream with a device (a format whose real part answers its driver, and
`--device on`, the default) gets raw samples instead: the send loop asks the device for sample k's output
shortly before k's deadline, so a configuration command takes effect at the next sample. Encoding in the
sender rather than sending changes to the producer down a control channel was chosen because the producer
runs up to a pipe's worth of blocks ahead (tens of ms to seconds): a control channel would have to discard
and re-encode that queue and roll back sequence numbers, while one sample's encode costs a few microseconds
(tools/bench_device.py prints the figure).

While waiting for a deadline the loop watches every transport's descriptor (select): bytes a driver writes
are fed to the device at once and its replies go out between two deadlines, without moving the sample
clock. Input on a link without a device is read and counted as ignored, so the writer never blocks.
Several streams (one IMU, one format, one target each) share one clock and one simulation.
A link whose other end sets the pace (a flight stack's simulator interface, `Transport.sets_pace`) is asked
`await_turn()` before each sample: in lockstep (--speed 0) it returns when the stack asks for the next step.
"""
from __future__ import annotations

import gc
import json
import math
import signal
import sys
import threading
import time

import firmware_protocols
from firmware_protocols.devices.base import Device
from imu_emulator.errors import ImuEmulatorError, TargetError
from imu_emulator.live.budget import link_budget_problem, link_text
from imu_emulator.live.config import RunOptions, StreamConfig, StreamError, encoders_navigate
from imu_emulator.live.inputs import Inputs
from imu_emulator.live.producer import Producer, ProducerFailure, reap
from imu_emulator.live.realtime import (LatenessStats, Pacer, drop_realtime, enable_realtime,
                                         context_switches)
from imu_emulator.live.stream import Stream, build_streams
from imu_emulator.output.atomic import AtomicOutput
from imu_emulator.runtime.samples import counts_text

# The first deadline lies this far after the producer starts, so the first block is ready in time.
_LEAD_NS = 30_000_000
_STATUS_INTERVAL_NS = 500_000_000
# With a pacer, links are looked at after a send when the waits have had no room to (high rates).
_INPUT_STARVED_NS = 1_000_000
# The next block is taken early only after a send that leaves this long before the next deadline (the ring's
# handover costs the sender 10-20 us of CPU with its caches cold; ring.py).
_HANDOVER_SLACK_NS = 50_000
# Without a pacer (--speed 0) the links are looked at every this many samples.
_UNPACED_POLL_EVERY = 64


class _Stop(Exception):
    pass


_NOT_TAKEN = object()


class Streamer:
    def __init__(self, sim, rate_hz: float, t0_s: float, streams: list[Stream], options: RunOptions):
        self.sim = sim
        self.rate_hz = rate_hz
        self.t0_s = t0_s
        self.streams = streams
        self.options = options
        self.scene_samples = int(sim.n_samples)
        limits = [n for n in (options.count,
                              None if options.duration_s is None else int(round(options.duration_s * rate_hz)),
                              None if options.loop else self.scene_samples) if n is not None]
        self.total = min(limits) if limits else None
        self.stats = LatenessStats(1e9 / rate_hz)
        self.samples_done = 0
        self.effect_counts: dict = {}    # the simulation's counters (range saturation), apart from the wire's
        self._time_offset_ns = 0
        self._first_ns = 0
        self._start_unix_ns = 0          # the wall clock at scene time t0's deadline (summary: started_unix_ns)
        self._last_ns = 0
        self.scheduling = None
        self.pacer = None
        self._sender_cpu_ns = 0

    # - sender -
    def run(self) -> dict:
        """Stream until the limit, the scene's end or SIGINT/SIGTERM/SIGHUP; returns the summary dict.
        A link or the producer failing mid-run still reports what was sent before the error is raised."""
        stats_out = self.options.stats_json
        if isinstance(stats_out, str):
            stats_out = AtomicOutput(stats_out)
        # A closed terminal (SIGHUP) ends the run like SIGTERM: ports closed, links removed, summary shown.
        old_handlers = {sig: signal.signal(sig, _raise_stop) for sig in (signal.SIGTERM, signal.SIGHUP)} \
            if threading.current_thread() is threading.main_thread() else {}
        failure = None
        try:
            self._check_budgets()
            for stream in self.streams:
                stream.open()
            self._warm_up()
            # Links made and announced once warm: a driver that opens the port at once finds a device that answers.
            for stream in self.streams:
                stream.transport.publish()
                print(f"{stream.config.imu} {stream.config.format} -> {stream.transport.describe()}", flush=True)
            paced = self.options.speed > 0
            start = time.monotonic_ns() + _LEAD_NS
            # A program comparing what a consumer made of the samples with the scene's truth (tools/interop)
            # needs the wall-clock instant of scene time t0: the first sample's deadline.
            self._start_unix_ns = time.time_ns() + (start - time.monotonic_ns())
            # One time base for every wire (firmware_protocols.gnss_time): UTC Unix ns = the run's start + scene time.
            self._time_offset_ns = int(self.options.start_ns)
            if self.options.epoch_time:
                # "now": sample k's time = the wall clock at its ideal deadline.
                self._time_offset_ns = self._start_unix_ns - int(round(self.t0_s * 1e9))
            for stream in self.streams:     # formats whose wire time counts since start subtract it (Samples.start_ns)
                stream.start_ns = self._time_offset_ns - stream.power_up_lead_ns()
            producer, blocks = Producer(self.sim, self.rate_hz, self.streams, self.total, self.options.loop,
                                         self._time_offset_ns).start()
            # RT only for paced runs: speed 0 never sleeps, and a busy SCHED_FIFO loop starves the machine.
            rt = self.scheduling = enable_realtime(self.options.realtime if paced else "off")
            self._note(f"scheduling: {rt.describe()}")
            try:
                period_ns = 1e9 / (self.rate_hz * self.options.speed) if paced else 0.0
                # The cyclic collector walking the heap (numba, sympy) stalls for milliseconds about once a
                # second; the send loop makes no reference cycles, so refcounting alone frees its garbage.
                gc.freeze()
                gc.disable()
                self.pacer = Pacer(rt.fifo, period_ns, spin=rt.spin) if paced else None
                cpu_before = time.thread_time_ns()
                try:
                    self._send_loop(blocks, self.pacer, start)
                finally:
                    self._sender_cpu_ns = time.thread_time_ns() - cpu_before
            except (KeyboardInterrupt, _Stop):
                pass
            except ImuEmulatorError as exc:
                failure = exc
            finally:
                gc.enable()
                gc.unfreeze()
                drop_realtime()
                blocks.close()
                reap(producer)
        except (KeyboardInterrupt, _Stop):
            pass            # stopped before the first sample: the summary says nothing was sent
        except BaseException:
            if stats_out is not None:
                stats_out.discard()
            raise
        finally:
            for sig, handler in old_handlers.items():
                signal.signal(sig, handler)
            failure = _close_all(self.streams) or failure
        summary = self.summary()
        stats_failure = None
        if stats_out is not None:
            try:
                stats_out.write(json.dumps(summary, indent=1))
                stats_out.close()
            except ImuEmulatorError as exc:
                stats_failure = exc
        if not self.options.quiet or stats_failure:     # figures a JSON file could not keep are shown
            self._print_summary(summary)
        if failure and stats_failure:
            raise StreamError(f"{failure}; and {stats_failure}")
        if failure or stats_failure:
            raise failure or stats_failure
        return summary

    def _print_summary(self, summary: dict) -> None:
        print(status_line(self._status_text("done"), sys.stderr.isatty())[0], file=sys.stderr, flush=True)
        for s in summary["streams"]:
            unread = s["link"].get("unread_lost", {}).get("packets", 0)
            print(f"  {s['imu']} {s['format']} -> {s['target']}: sent {s['sent']}"
                  + (f" ({unread} of them never read: lost)" if unread else "")
                  + f", dropped {s['dropped']}, saturated {s['saturated']}", file=sys.stderr, flush=True)
            if "device" in s:
                d = s["device"]
                print(f"    device: {d['commands']} commands answered, {d['errors']} error replies, "
                      f"{d['replies_sent']} replies sent ({d['replies_delayed']} after waiting for room), "
                      f"{d['replies_dropped']} dropped, {d['ignored_bytes']} "
                      f"input bytes ignored, {d['idle']} samples with nothing due", file=sys.stderr, flush=True)
            if s.get("ignored_input"):
                print(f"    input ignored (no device): {s['ignored_input']}", file=sys.stderr, flush=True)
            print(f"    link: {link_text(s['link'])}", file=sys.stderr, flush=True)
        late = summary["lateness"]
        if late["missed"]:
            print(f"  {late['missed']} deadlines missed by more than a period: "
                  f"{LatenessStats.causes_text(late['missed_by_cause'])}", file=sys.stderr, flush=True)

    def _check_budgets(self) -> None:
        if self.options.speed == 0:
            return
        for stream in self.streams:
            problem = link_budget_problem(stream, self.rate_hz * self.options.speed)
            if problem and not self.options.allow_overload:
                raise TargetError(problem)
            if problem:
                self._note("overload: " + problem.split(";")[0])

    def _warm_up(self) -> None:
        """Compile kernels and encoders now rather than inside the first deadlines (throwaway encoders and
        devices keep the real ones' sequence numbers and counters at zero; a throwaway simulation keeps the real one's
        noise state at the run's start)."""
        block = self.sim.fresh().block(0, 1)
        for stream in self.streams:
            samples = stream.samples(block, block.time_ns())
            if stream.device is not None:
                device = stream.info.device(self.rate_hz, **stream.config.options)
                device.output(samples, 0)
                device.warm_up(samples)     # what a driver's configuration could make it compile mid-run
            else:
                firmware_protocols.create_encoder(stream.config.format, **stream.config.options).encode(samples)

    def _send_loop(self, blocks, pacer: Pacer | None, start: int) -> None:
        """Per sample at 10 kHz this loop has 100 us, of which the sleep's wake-up takes tens: what it does per
        sample is kept to attribute reads of locals and no lists built (tools/bench_stream.py --profile shows
        where the rest goes). Each missed deadline is counted under its cause (realtime.MISS_CAUSES)."""
        period = 1e9 / (self.rate_hz * self.options.speed) if pacer else 0.0
        streams = self.streams
        # (stream, transport, device) per stream: a device answers its driver and is asked for each sample's output
        links = [(s, s.transport, s.device) for s in streams]
        single = links[0] if len(links) == 1 else None
        devices = [d for _, _, d in links]
        prepares = any(d is not None and type(d).prepare is not Device.prepare for d in devices)
        # links whose other end sets the pace (a flight stack stepping in lockstep) are waited for before each sample
        pacing = [s.transport for s in streams if s.transport.sets_pace]
        catch_up = not pacing       # behind, the samples already due go out together (not to a stepping stack)
        inputs = Inputs(streams, self._note)
        stats = self.stats
        classify = stats.classify
        next_status = start + _STATUS_INTERVAL_NS
        show_status = not self.options.quiet
        done = 0
        missed_before = False       # the previous deadline was missed (a miss now is catching up)
        switches, _ = context_switches()
        # voluntary context switches when the sender was last on time: one since means it blocked in the kernel (a
        # lock, a full buffer), its own doing, which the CPU clock does not count
        on_time_voluntary = 0
        if pacer:
            spin_ns, sleep_until, wait_until = pacer.spin_ns, pacer.sleep_until, pacer.wait_until
        fds, ready, unwatched = inputs.fds, inputs.ready, inputs.unwatched
        block = _NOT_TAKEN          # the next block (or the end, or a failure) when taken early, in slack
        try:
            while True:
                if block is _NOT_TAKEN:
                    block = inputs.next_block(blocks)
                    block_at = time.monotonic_ns()
                    waited = inputs.block_waited         # the producer's block was not there yet
                else:
                    waited = False
                if block is None:
                    break
                if isinstance(block, ProducerFailure):
                    block.raise_()
                items = block.items
                j0 = block.j0
                current, block = block, _NOT_TAKEN
                # The next block is taken in the second half of this one, after a send that leaves slack before the
                # next deadline: its handover is then never in a deadline's way (issue 25; at the block's end it
                # still is when the producer was late).
                n = len(current)
                take_from = n // 2 if pacer else n
                taken_at = -2       # the sample after which the next block was taken
                i = 0
                while i < n:
                    j = j0 + i
                    if pacer:
                        deadline = start + int(j * period)
                        # Commands are answered while waiting; the devices encode with the configuration in
                        # force just before the deadline, then the last stretch is spun.
                        sleep_until(deadline - spin_ns, fds, ready)
                        if unwatched:
                            inputs.poll_unwatched()
                    elif j % _UNPACED_POLL_EVERY == 0:
                        inputs.poll_all()
                    if single is not None:
                        stream, transport, device = single
                        payload = items[0][i] if device is None else stream.device_item(items[0], i)
                    else:
                        payloads = [p[i] if d is None else s.device_item(p, i) for (s, _, d), p in zip(links, items)]
                    upto = i + 1        # the samples up to this one go out now
                    if pacer:
                        now = wait_until(deadline)
                        late = now - deadline
                        if late > period and catch_up:
                            # Behind (the host took the CPU away, or earlier work ran long): the samples already
                            # due go out with this one, in one write per byte stream, as a UART's FIFO drains
                            # after a stall. One write each would cost a system call per sample and stay behind
                            # for longer than the machine's floor does (issue 25); a reader sees the same bytes.
                            while upto < n and start + int((j0 + upto) * period) <= now:
                                upto += 1
                            if upto > i + 1:
                                batch = self._catch_up(links, items, i, upto,
                                                       [payload] if single is not None else payloads)
                                now = time.monotonic_ns()
                                late = now - deadline
                        stats.add(late)
                        seen, voluntary = context_switches()
                        if pacer.on_time:
                            on_time_voluntary = voluntary
                        if late > period:
                            # a pacer with nothing to do is this much less late (none when the sender blocked)
                            own = pacer.own_cpu_ns() if voluntary == on_time_voluntary else late
                            classify(miss_cause(i == 0 and waited and block_at > deadline, inputs.served_ns > deadline,
                                                seen != switches, missed_before, pacer.arrived_ns > deadline,
                                                (i == 0 or i == taken_at + 1) and block_at > deadline,
                                                late - own > period))
                            missed_before = True
                        else:
                            missed_before = False
                        switches = seen
                        if upto > i + 1:
                            # the others of the batch, handed over now: late after a miss is catching up, unless
                            # a pacer with nothing to do would have been as late
                            for k in range(j + 1, j0 + upto):
                                late = now - start - int(k * period)
                                stats.add(late)
                                if late > period:
                                    classify("stalled" if late - own > period else "catching_up")
                                missed_before = late > period
                    for transport in pacing:
                        transport.await_turn()
                    if upto > i + 1:
                        for (stream, _, _), payloads in zip(links, batch):
                            stream.send_samples(payloads)
                    elif single is not None:
                        self._send(stream, transport, device, payload)
                    else:
                        for (stream, transport, device), payload in zip(links, payloads):
                            self._send(stream, transport, device, payload)
                    count, i, j = upto - i, upto, j0 + upto - 1     # j: the last sample sent
                    if pacer and fds and deadline - pacer.watched_ns > _INPUT_STARVED_NS:
                        # No slack left to watch the links while waiting (high rates): look right after the send.
                        inputs.poll_all()
                        pacer.watched_ns = deadline
                    if pacer and start + int((j + 1) * period) - time.monotonic_ns() > _HANDOVER_SLACK_NS:
                        # Slack before the next deadline: take the next block, or let the devices work ahead.
                        if block is _NOT_TAKEN and i > take_from and blocks.poll(0):
                            block = blocks.recv()
                            block_at = time.monotonic_ns()
                            taken_at = i - 1
                        elif prepares:
                            # the next sample: in this block, or the first of the next one when it is taken
                            ahead, at = (items, i) if i < n else (getattr(block, "items", None), 0)
                            for device, device_items in zip(devices, ahead or ()):
                                if device is not None:
                                    device.prepare(device_items, at)
                    if done == 0:
                        self._first_ns = time.monotonic_ns()
                    done += count
                    if not pacer or count > 1 or j % 64 == 0:
                        now = time.monotonic_ns()
                        if now >= next_status:
                            self.samples_done = done
                            next_status = now + _STATUS_INTERVAL_NS
                            for stream in streams:
                                stream.sample_queue()
                            if show_status:
                                text, end = status_line(self._status_text("streaming"), sys.stderr.isatty())
                                print(text, end=end, file=sys.stderr, flush=True)
                for stream, saturated in zip(streams, current.saturated):
                    stream.saturated = saturated if stream.device is None else stream.device.saturated
                self.effect_counts = current.counts
                self.samples_done = done
                self._last_ns = time.monotonic_ns()
        finally:
            self.samples_done = done

    @staticmethod
    def _catch_up(links, items, i: int, upto: int, first: list) -> list:
        """Per stream, the payloads of samples i to upto - 1 (sample i's already made: `first`, one per stream),
        a device asked for the others at once."""
        batch = []
        for (stream, _, device), block_items, payload in zip(links, items, first):
            if device is None:
                batch.append([payload, *(block_items[k] for k in range(i + 1, upto))])
            else:
                batch.append([payload, *stream.device_items(block_items, i + 1, upto)])
        return batch

    @staticmethod
    def _send(stream, transport, device, payload) -> None:
        if device is not None:
            stream.send_sample(payload)      # replies waiting for room go first
        elif payload is None:
            stream.idle += 1
        elif transport.send(payload):
            stream.sent += 1
        else:
            stream.dropped += 1

    # - reporting -
    def _note(self, text: str) -> None:
        if not self.options.quiet:
            print(text, file=sys.stderr, flush=True)

    def summary(self) -> dict:
        elapsed = ((self._last_ns or time.monotonic_ns()) - self._first_ns) / 1e9
        return {"samples": self.samples_done, "rate_hz": self.rate_hz, "speed": self.options.speed,
                "started_unix_ns": self._start_unix_ns,
                "achieved_hz": (self.samples_done - 1) / elapsed if self.samples_done > 1 and elapsed > 0 else 0.0,
                "scheduling": self.scheduling.mode if self.scheduling else None,
                # CPU the send loop used per second of streaming: what the scheduling mode costs.
                "sender_cpu_ratio": self._sender_cpu_ns / 1e9 / elapsed if elapsed > 0 else 0.0,
                "lateness": self.stats.summary(),
                "fifo_given_up": self.pacer.fifo_given_up if self.pacer else 0,
                "dropped": sum(s.dropped for s in self.streams),
                "saturated": sum(s.saturated for s in self.streams),
                "effect_counts": self.effect_counts,
                "streams": [s.summary() for s in self.streams]}

    def _status_text(self, state: str) -> str:
        s = self.summary()
        late = s["lateness"]
        shown = LatenessStats.shown
        return (f"{state}: {s['samples']} samples, {s['achieved_hz']:.1f} Hz, late p50 {shown(late['p50_us'])} us "
                f"p99 {shown(late['p99_us'])} us max {late['max_us']:.0f} us, dropped {s['dropped']}, "
                f"saturated {s['saturated']}" + (f"; {counts_text(self.effect_counts)}" if self.effect_counts else ""))


def miss_cause(block_late: bool, serving: bool, preempted: bool, missed_before: bool, arrived_late: bool,
               handover_late: bool = False, stalled: bool = False) -> str:
    """Why a deadline was missed: the first of realtime.MISS_CAUSES that applies. block_late: the producer's block
    came after the deadline; serving: input was served past it; preempted: involuntary context switches since the
    previous deadline; stalled: late by more than a period even without the sender's own CPU time since it was
    last on time (Pacer.own_cpu_ns); missed_before: the previous deadline was missed too; arrived_late: the loop
    came to wait for this deadline after it had passed; handover_late: this deadline, a block's first or the one
    after the next block was taken early, passed while that block was being taken."""
    if block_late:
        return "producer"
    if serving:
        return "input"
    if preempted:
        return "preempted"
    if stalled:
        return "stalled"
    if missed_before:
        return "catching_up"
    if handover_late:
        return "block_handover"
    if arrived_late:
        return "previous_work"
    return "woke_late"


def status_line(text: str, tty: bool) -> tuple[str, str]:
    """What to print for a status line, and how to end it. On a terminal the line is rewritten in place: it
    clears to its end (ESC [K), or a shorter line would leave the longer one's tail ("saturated 0ted 0")."""
    return (text + "\x1b[K", "\r") if tty else (text, "\n")


def _raise_stop(signum, frame):
    raise _Stop()


def _close_all(streams) -> ImuEmulatorError | None:
    """Close every stream even when one fails to (a pty's link must still go). The first failure is
    returned when it is the user's (a full disk), raised when it is a bug."""
    first = None
    for stream in streams:
        try:
            stream.close()
        except Exception as exc:
            first = first or exc
    if first is not None and not isinstance(first, ImuEmulatorError):
        raise first
    return first


# Effects that leave the gyro's increment the integral of the true attitude's rate (they act on the
# accelerometer, or on the rate outputs only, not on increments): with no other, a delta quaternion is the true
# attitude change alone (attitude.attitude_change).
_TRUE_RATE_EFFECTS = frozenset({"gravity", "lever_arm", "range", "resolution"})


def run_streams(scene, sim, configs: list[StreamConfig], options: RunOptions) -> dict:
    streams = build_streams(configs, tuple(sim.imu_names), float(scene.rate_hz))
    for stream in streams:
        stream.frame = scene.frame
        stream.exact_gyro = scene.effects <= _TRUE_RATE_EFFECTS
        if (stream.info.device_navigation or encoders_navigate(stream.device.encoders()) if stream.device is not None
                else encoders_navigate([stream.encoder])):
            from imu_emulator.scene.earth import position_frame
            stream.navigation = (scene.frame, float(scene.gravity_mps2), scene.origin, scene.gravity_model,
                                 position_frame(scene))
    if not math.isfinite(options.speed) or options.speed < 0:
        raise StreamError(f"--speed: expected a number >= 0, got {options.speed}")
    return Streamer(sim, float(scene.rate_hz), float(scene.t0_s), streams, options).run()
