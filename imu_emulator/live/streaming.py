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
"""
from __future__ import annotations

import gc
import json
import math
import multiprocessing
import os
import select
import signal
import sys
import threading
import time
import traceback
from dataclasses import dataclass, field, replace

import numpy as np

import firmware_protocols
from firmware_protocols import attitude
from firmware_protocols.base import EncodeError, can_bits_worst_case
from imu_emulator.errors import ImuEmulatorError, SceneError, TargetError
from imu_emulator.output.atomic import AtomicOutput
from imu_emulator.geo.geodesy import device_navigation
from imu_emulator.runtime.samples import counts_text
from imu_emulator.live.realtime import LatenessStats, Pacer, drop_realtime, enable_realtime
from imu_emulator.live.transport import TargetOptions, check_carries, link_capacity, open_target, parse_target

# Blocks hold about this much time: few pipe messages per second, and the sender's per-block work
# (one unpickle) stays far below a sample period.
_BLOCK_SECONDS = 0.02
_MAX_BLOCK = 500
# The first deadline lies this far after the producer starts, so the first block is ready in time.
_LEAD_NS = 30_000_000
_STATUS_INTERVAL_NS = 500_000_000

STREAM_TABLE_KEYS = {"imu", "format", "to", "options", "link", "pace_baud", "bitrate", "data_bitrate", "fd", "device"}
# Targets that cannot talk back: a device there would only change what is streamed, so none is made.
_ONE_WAY_TARGETS = ("file",)
# With a pacer, links are looked at after a send when the waits have had no room to (high rates).
_INPUT_STARVED_NS = 1_000_000
# Without a pacer (--speed 0) the links are looked at every this many samples.
_UNPACED_POLL_EVERY = 64


class StreamError(ImuEmulatorError):
    """A stream's format, IMU or encoder options are unusable."""


@dataclass(frozen=True)
class StreamConfig:
    imu: str
    format: str
    target: str
    options: dict = field(default_factory=dict)             # encoder (and device) options
    target_options: TargetOptions = TargetOptions()
    device: bool = True     # answer the driver when the format has a device and the link is two-way


@dataclass(frozen=True)
class RunOptions:
    speed: float = 1.0               # 0 = as fast as the link takes
    loop: bool = False
    epoch_time: bool = False
    duration_s: float | None = None
    count: int | None = None
    quiet: bool = False
    allow_overload: bool = False
    realtime: str = "auto"           # imu_emulator.live.realtime.MODES
    stats_json: "str | AtomicOutput | None" = None   # a path, or an output the caller created early


def streams_from_tables(tables, imu_names, defaults: TargetOptions = TargetOptions()) -> list[StreamConfig]:
    """Validate the scene's raw [[stream]] tables; errors name the table and key."""
    configs = []
    for i, table in enumerate(tables):
        where = f"stream[{i}]"
        unknown = sorted(set(table) - STREAM_TABLE_KEYS)
        if unknown:
            raise SceneError(f"{where}.{unknown[0]}: unknown key (allowed: {', '.join(sorted(STREAM_TABLE_KEYS))})")
        for key in ("format", "to"):
            if not isinstance(table.get(key), str) or not table[key]:
                raise SceneError(f"{where}.{key}: missing (a string is required)")
        imu = table.get("imu", imu_names[0])
        if imu not in imu_names:
            raise SceneError(f"{where}.imu: no IMU named {imu!r} (scene has: {', '.join(imu_names)})")
        options = table.get("options", {})
        if not isinstance(options, dict):
            raise SceneError(f"{where}.options: expected a table")
        overrides = {}
        device = table.get("device", True)
        if not isinstance(device, bool):
            raise SceneError(f"{where}.device: expected true or false, got {device!r}")
        for key, kind in (("link", str), ("pace_baud", int), ("bitrate", int), ("data_bitrate", int), ("fd", bool)):
            if key in table:
                value = table[key]
                if not isinstance(value, kind) or (kind is int and (isinstance(value, bool) or value <= 0)):
                    raise SceneError(f"{where}.{key}: expected {'a positive integer' if kind is int else kind.__name__}, "
                                     f"got {value!r}")
                overrides[key] = value
        configs.append(StreamConfig(imu, table["format"], table["to"], dict(options), replace(defaults, **overrides),
                                    device))
    return configs


# --- link budget --------------------------------------------------------------------------------

@dataclass(frozen=True)
class LinkBudget:
    """What a stream needs of its link: `load` is the fraction of the link's capacity (None: no limit known)."""
    need: str              # e.g. "15,000 B/s (75 B/sample)" or "1120 bits/sample (7 frames, ...) = 0.224 Mbit/s"
    capacity: str | None   # e.g. "11,520 B/s (baud/10)" or "1 Mbit/s bus"
    load: float | None


def link_budget(stream: "Stream", rate_hz: float) -> LinkBudget:
    """The stream's demand at rate_hz against its link's capacity (serial bytes, or CAN bits with worst-case
    stuffing)."""
    capacity, encoder = stream.capacity, stream.encoder
    if stream.info.kind == "serial":
        per_sample = getattr(encoder, "bytes_per_sample", stream.info.bytes_per_sample)
        need = per_sample * rate_hz
        text = f"{need:,.0f} B/s ({per_sample} B/sample)"
        if capacity.bytes_per_s is None:
            return LinkBudget(text, None, None)
        return LinkBudget(text, f"{capacity.bytes_per_s:,.0f} B/s (baud/10)", need / capacity.bytes_per_s)
    frames = getattr(encoder, "frames_per_sample", stream.info.frames_per_sample)
    bits = sum(can_bits_worst_case(length, extended, fd) for length, extended, fd in frames)
    text = (f"{bits} bits/sample ({len(frames)} frames, worst-case stuffing) = "
            f"{bits * rate_hz / 1e6:.3f} Mbit/s")
    if capacity.bits_per_s is None:
        return LinkBudget(text, None, None)
    seconds = 0.0
    for length, extended, fd in frames:
        total = can_bits_worst_case(length, extended, fd)
        if fd and capacity.data_bits_per_s:
            # Approximation: payload and CRC ride the data phase, the rest the nominal phase.
            data_bits = total - can_bits_worst_case(0, extended, fd)
            seconds += (total - data_bits) / capacity.bits_per_s + data_bits / capacity.data_bits_per_s
        else:
            seconds += total / capacity.bits_per_s
    return LinkBudget(text, f"{capacity.bits_per_s / 1e6:g} Mbit/s bus", seconds * rate_hz)


def link_budget_problem(stream: "Stream", rate_hz: float) -> str | None:
    """None when the stream fits its link at rate_hz, else a one-line message naming the numbers."""
    budget = link_budget(stream, rate_hz)
    if budget.load is None or budget.load <= 1.0:
        return None
    label = f"{stream.config.imu} {stream.config.format} at {rate_hz:g} Hz"
    if stream.info.kind == "serial":
        return (f"{label} needs {budget.need} but {stream.config.target} carries {budget.capacity}; "
                f"lower the rate, raise the baud or pass --allow-overload")
    return (f"{label} needs {budget.need}, {budget.load:.0%} of the {budget.capacity} of {stream.config.target}; "
            f"lower the rate, raise --bitrate or pass --allow-overload")


# --- one stream: encoder + transport + counters --------------------------------------------------

class Stream:
    def __init__(self, config: StreamConfig, imu_index: int, info, rate_hz: float):
        self.config = config
        self.imu_index = imu_index
        self.info = info
        self.period_s = 1.0 / rate_hz
        self.spec = parse_target(config.target)   # malformed specs fail before anything is opened
        check_carries(self.spec, info.kind)
        self.capacity = link_capacity(self.spec, info.kind, config.target_options)
        self.device = None
        self.navigation = None     # (frame, gravity, origin, model, positions' frame) for navigation
        self.frame = "NED"          # the scene's navigation frame: attitude goes out NED-referenced (run_streams)
        try:
            if config.device and info.device is not None and self.spec.kind not in _ONE_WAY_TARGETS:
                # The device encodes too: budgets read its bytes_per_sample / frames_per_sample.
                self.device = self.encoder = info.device(rate_hz, **config.options)
            else:
                self.encoder = firmware_protocols.create_encoder(config.format, **config.options)
        except TypeError as exc:
            known = {**self.info.options, **(self.info.device_options if self.device or config.device else {})}
            raise StreamError(f"{config.format}: bad option ({exc}); known options: "
                              f"{', '.join(known) or 'none'}") from None
        except ValueError as exc:
            raise StreamError(f"{config.format}: {exc}") from None
        self.transport = None
        self.sent = 0
        self.dropped = 0
        self.saturated = 0
        self.idle = 0               # samples for which the device had nothing to send (paused, divided)
        self.replies_sent = 0
        self.replies_dropped = 0
        self.ignored_input = 0      # bytes or frames that arrived on a link without a device
        self.queue_max = None       # most bytes seen waiting in the link's queue (sampled twice a second)
        self.link = {}              # what the link itself reported, read just before closing it
        self._before = None         # (next k, attitude, increment) of the last sample: see _attitude_change
        self.exact_gyro = False     # the gyro senses the true attitude's rate exactly (run_streams)

    def open(self) -> None:
        self.transport = open_target(self.spec, self.info.kind, self.config.target_options)

    def samples(self, block, time_ns: np.ndarray):
        from firmware_protocols import Samples
        i = self.imu_index
        time_ns = time_ns + block.imu_offset_ns(i)      # the IMU's own clock ([[imu]] time_offset_s)
        # the simulated temperature (temperature effect) for formats that carry one
        temperature = None if block.temperature_c is None else block.temperature_c[i]
        # Wire formats reference attitude to NED (Samples.quat is sensor -> NED): an ENU scene's is converted.
        # (ECEF and ECI scenes give attitude relative to local NED already)
        quat = attitude.to_ned(block.quat[i], "ENU" if self.frame == "ENU" else "NED")
        increments = {}
        if block.dtheta is not None:   # over one sample period, by the sensor's own (nominal) clock
            increments = {"delta_theta": block.dtheta[i], "delta_velocity": block.dvel[i],
                          "delta_time_s": np.full(len(time_ns), self.period_s),
                          "attitude_change": self._attitude_change(block, quat)}
        if self.device is None:
            return Samples(time_ns, block.accel[i], block.gyro[i], quat=quat, temperature_c=temperature,
                           **increments)
        # imported here: rotations pulls in numba, which every command would pay for at start-up otherwise
        from imu_emulator.geo.rotations import quat_to_euler, quat_to_matrix
        # A device may be asked for any field its format knows at any moment: give it all we have.
        nav = {}
        if self.navigation is not None and block.truth is not None:
            specific_force = np.einsum("nij,nj->ni", quat_to_matrix(block.quat[i]), block.accel[i])
            nav = device_navigation(block.truth["position"], block.truth["velocity"], specific_force,
                                    *self.navigation)
        return Samples(time_ns, block.accel[i], block.gyro[i], quat=quat, euler=quat_to_euler(quat),
                       temperature_c=temperature, **nav, **increments)

    def _attitude_change(self, block, quat: np.ndarray) -> np.ndarray:
        """Each interval's attitude change from the true attitudes at its ends (attitude.attitude_change); the
        last sample of the previous block is kept for the next block's first interval. The stream's first
        sample, and the first after a loop restarts the scene, has no attitude before it: its change is the
        rotation by its increment."""
        dtheta = block.dtheta[self.imu_index]
        if self._before is not None and self._before[0] == block.k0:
            quat_first, dtheta_first = self._before[1], self._before[2]
        else:
            dtheta_first = dtheta[:1]
            quat_first = attitude.multiply(quat[:1], attitude.conjugate(attitude.from_rotation_vector(dtheta_first)))
        self._before = (block.k0 + len(block), quat[-1:].copy(), dtheta[-1:].copy())
        return attitude.attitude_change(quat, np.concatenate((quat_first, quat[:-1])), dtheta,
                                        np.concatenate((dtheta_first, dtheta[:-1])), not self.exact_gyro)

    def encode(self, block, time_ns: np.ndarray) -> tuple[list, int]:
        """Per-sample prepared payloads for one block, and the saturation count after it. A device stream
        gets the raw samples: its device encodes each one at its deadline, with the configuration then."""
        if self.device is not None:
            return self.samples(block, time_ns), 0
        encoded = self.encoder.encode(self.samples(block, time_ns))
        if self.info.kind == "serial":
            items = _Packets(bytes(encoded.data), encoded.offsets.tolist())
        else:
            prepare = self.transport.prepare
            bounds = np.searchsorted(encoded["sample"], np.arange(len(time_ns) + 1)).tolist()
            items = [prepare(encoded[bounds[j]:bounds[j + 1]], time_ns[j]) for j in range(len(time_ns))]
        return items, _saturation_total(self.encoder)

    def sample_queue(self) -> None:
        queued = self.transport.queued()
        if queued is not None:
            self.queue_max = max(queued, self.queue_max or 0)

    def close(self) -> None:
        if self.transport is not None:
            self.transport.finish()
            self.sample_queue()
            self.link = self.transport.link_report()
            if self.queue_max is not None:
                self.link["queue_max_bytes"] = self.queue_max
            self.transport.close()
            self.transport = None

    def device_item(self, samples, i: int):
        """What the device sends for sample i now, prepared for the transport; None when nothing is due."""
        out = self.device.output(samples, i)
        if not len(out):
            return None
        if self.info.kind == "serial":
            return out
        return self.transport.prepare(out, int(samples.time_ns[i]))

    def summary(self) -> dict:
        out = {"imu": self.config.imu, "format": self.config.format, "target": self.config.target,
               "sent": self.sent, "dropped": self.dropped, "saturated": self.saturated}
        if self.device is not None:
            out["device"] = {**self.device.stats.as_dict(), "replies_sent": self.replies_sent,
                             "replies_dropped": self.replies_dropped, "idle": self.idle}
        if self.ignored_input:
            out["ignored_input"] = self.ignored_input
        out["link"] = self.link
        return out


def _saturation_total(encoder) -> int:
    return encoder.saturated.total


def build_streams(configs: list[StreamConfig], imu_names, rate_hz: float) -> list[Stream]:
    streams = []
    for config in configs:
        if config.imu not in imu_names:
            raise StreamError(f"--imu: no IMU named {config.imu!r} (scene has: {', '.join(imu_names)})")
        try:
            info = firmware_protocols.get(config.format)
        except KeyError as exc:
            raise StreamError(exc.args[0]) from None
        streams.append(Stream(config, list(imu_names).index(config.imu), info, rate_hz))
    return streams


# --- the run ------------------------------------------------------------------------------------

class _Packets:
    """One block's serial packets as one buffer: crossing the pipe as a single bytes object costs the
    sender a fraction of what a list of small ones would, and slicing happens only when sending."""

    __slots__ = ("data", "offsets")

    def __init__(self, data: bytes, offsets: list):
        self.data, self.offsets = data, offsets

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def __getitem__(self, j: int) -> bytes:
        return self.data[self.offsets[j]:self.offsets[j + 1]]

    def __getstate__(self):
        return self.data, self.offsets

    def __setstate__(self, state):
        self.data, self.offsets = state


@dataclass
class _ProducerFailure:
    """An exception raised in the producer process, carried to the sender to be raised there."""
    user_error: bool
    message: str

    @classmethod
    def from_exception(cls, exc: BaseException) -> "_ProducerFailure":
        if isinstance(exc, (ImuEmulatorError, EncodeError)):
            return cls(True, str(exc))
        return cls(False, "".join(traceback.format_exception(exc)))

    def raise_(self):
        if self.user_error:
            raise StreamError(self.message)
        raise RuntimeError("producer process failed:\n" + self.message)


@dataclass
class _Block:
    j0: int                  # run index of the first sample (0 = first sample streamed)
    n: int                   # samples in the block
    items: list              # per stream: prepared payloads, one per sample (or the raw Samples, for a device)
    saturated: list          # per stream: encoder saturation total after this block
    counts: dict             # the effects' counters after this block (range saturation per IMU and axis)

    def __len__(self) -> int:
        return self.n


class _Inputs:
    """The links' incoming side: which descriptors to watch, and what to do with what arrives. Bytes or
    frames go to the stream's device and its replies out at once; a link without a device has its input
    read and counted (so the writer never blocks) and otherwise ignored."""

    def __init__(self, streams: list[Stream], note):
        self.note = note
        self.by_fd = {}
        self.unwatched = []
        for stream in streams:
            fd = stream.transport.fileno()
            if fd is None:
                self.unwatched.append(stream)
            else:
                self.by_fd.setdefault(fd, []).append(stream)
        self.fds = list(self.by_fd)
        # Unwatched links that can talk are polled at each deadline; one-way ones not at all.
        self.unwatched = [s for s in self.unwatched if s.device is not None]

    def ready(self, fds) -> bool:
        """Serve the streams on these descriptors; whether any of them had input."""
        found = False
        for fd in fds:
            for stream in self.by_fd[fd]:
                found = self.serve(stream) or found
        return found

    def poll_unwatched(self) -> None:
        for stream in self.unwatched:
            self.serve(stream)

    def poll_all(self) -> None:
        if self.fds:
            ready, _, _ = select.select(self.fds, (), (), 0)
            self.ready(ready)
        self.poll_unwatched()

    def serve(self, stream: Stream) -> bool:
        data = stream.transport.recv()
        if not len(data):
            return False
        device = stream.device
        if device is None:
            stream.ignored_input += len(data)
            return True
        transport = stream.transport
        for reply in device.receive(data, time.monotonic_ns()):
            item = reply if stream.info.kind == "serial" else transport.prepare(reply, 0)
            if transport.send(item):
                stream.replies_sent += 1
            else:
                stream.replies_dropped += 1
        for request in device.take_link_requests():
            if request.baud:
                followed = transport.set_baud(request.baud)
                self.note(f"{stream.config.format}: baud rate {request.baud} "
                          + ("followed" if followed else "acknowledged (this link has no baud rate to follow)"))
        for text in device.take_notes():
            self.note(f"{stream.config.format}: {text}")
        return True


class _Stop(Exception):
    pass


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
        self._last_ns = 0
        self.scheduling = None
        self.pacer = None
        self._sender_cpu_ns = 0

    # - producer -
    def _loop_period_ns(self) -> int:
        return int(round(self.scene_samples * 1e9 / self.rate_hz))

    def _blocks(self):
        """Encoded blocks from the first sample to the limit (forever when looping without a limit)."""
        block_len = max(1, min(_MAX_BLOCK, int(self.rate_hz * _BLOCK_SECONDS)))
        j = 0
        while self.total is None or j < self.total:
            k = j % self.scene_samples if self.options.loop else j
            n = min(block_len, self.scene_samples - k) if self.options.loop else block_len
            if self.total is not None:
                n = min(n, self.total - j)
            block = self.sim.block(k, n, run_sample=j)   # noise follows the run, not the looped scene
            offset = self._time_offset_ns
            if self.options.loop:   # each pass is stamped one scene length later: time keeps increasing
                offset += (j // self.scene_samples) * self._loop_period_ns()
            time_ns = block.time_ns(offset)
            encoded = [stream.encode(block, time_ns) for stream in self.streams]
            yield _Block(j, n, [e[0] for e in encoded], [e[1] for e in encoded], self.sim.counts())
            j += n

    def _start_producer(self):
        """Fork a process that computes and encodes ahead into a pipe. A process, not a thread: a
        thread holding the GIL while descheduled by other load would stall the real-time sender for
        tens of milliseconds. The pipe's buffer bounds how far ahead it runs."""
        receiver, sender = multiprocessing.Pipe(duplex=False)
        pid = os.fork()
        if pid == 0:   # child: never returns
            code = 0
            try:
                receiver.close()
                # A collection walking the whole inherited heap would also copy every page on write.
                gc.freeze()
                signal.signal(signal.SIGINT, signal.SIG_IGN)   # the parent decides when to stop
                signal.signal(signal.SIGHUP, signal.SIG_IGN)
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
                drop_realtime()
                for item in self._blocks():
                    sender.send(item)
                sender.send(None)
            except (BrokenPipeError, ConnectionResetError):
                pass
            except BaseException as exc:
                try:
                    sender.send(_ProducerFailure.from_exception(exc))
                except Exception:
                    code = 1
            finally:
                os._exit(code)
        sender.close()
        return pid, receiver

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
            # Announced once warm: a driver that opens the port at once finds a device that answers.
            for stream in self.streams:
                print(f"{stream.config.imu} {stream.config.format} -> {stream.transport.describe()}", flush=True)
            paced = self.options.speed > 0
            start = time.monotonic_ns() + _LEAD_NS
            if self.options.epoch_time:
                # Sample k's time = the wall clock at its ideal deadline.
                self._time_offset_ns = time.time_ns() + (start - time.monotonic_ns()) - int(round(self.t0_s * 1e9))
            producer, blocks = self._start_producer()
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
                _reap(producer)
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
        print(self._status_text("done"), file=sys.stderr, flush=True)
        for s in summary["streams"]:
            print(f"  {s['imu']} {s['format']} -> {s['target']}: sent {s['sent']}, dropped {s['dropped']}, "
                  f"saturated {s['saturated']}", file=sys.stderr, flush=True)
            if "device" in s:
                d = s["device"]
                print(f"    device: {d['commands']} commands answered, {d['errors']} error replies, "
                      f"{d['replies_sent']} replies sent, {d['replies_dropped']} dropped, {d['ignored_bytes']} "
                      f"input bytes ignored, {d['idle']} samples with nothing due", file=sys.stderr, flush=True)
            if s.get("ignored_input"):
                print(f"    input ignored (no device): {s['ignored_input']}", file=sys.stderr, flush=True)
            print(f"    link: {_link_text(s['link'])}", file=sys.stderr, flush=True)

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
                stream.info.device(self.rate_hz, **stream.config.options).output(samples, 0)
            else:
                firmware_protocols.create_encoder(stream.config.format, **stream.config.options).encode(samples)

    def _send_loop(self, blocks, pacer: Pacer | None, start: int) -> None:
        period = 1e9 / (self.rate_hz * self.options.speed) if pacer else 0.0
        streams = self.streams
        transports = [s.transport for s in streams]
        devices = [s.device for s in streams]
        inputs = _Inputs(streams, self._note)
        stats = self.stats
        next_status = start + _STATUS_INTERVAL_NS
        show_status = not self.options.quiet
        done = 0
        items = None
        while True:
            block = blocks.recv()
            if block is None:
                break
            if isinstance(block, _ProducerFailure):
                block.raise_()
            items = block.items
            for i in range(len(block)):
                j = block.j0 + i
                if pacer:
                    deadline = start + int(j * period)
                    # Commands are answered while waiting; the devices encode with the configuration in
                    # force just before the deadline, then the last stretch is spun.
                    pacer.sleep_until(deadline - pacer.spin_ns, inputs.fds, inputs.ready)
                    inputs.poll_unwatched()
                elif j % _UNPACED_POLL_EVERY == 0:
                    inputs.poll_all()
                payloads = [p[i] if d is None else s.device_item(p, i)
                            for s, d, p in zip(streams, devices, items)]
                if pacer:
                    now = pacer.wait_until(deadline)
                    stats.add(now - deadline)
                for stream, transport, payload in zip(streams, transports, payloads):
                    if payload is None:
                        stream.idle += 1
                    elif transport.send(payload):
                        stream.sent += 1
                    else:
                        stream.dropped += 1
                if pacer and inputs.fds and deadline - pacer.watched_ns > _INPUT_STARVED_NS:
                    # No slack left to watch the links while waiting (high rates): look right after the send.
                    inputs.poll_all()
                    pacer.watched_ns = deadline
                done += 1
                self.samples_done = done
                if done == 1:
                    self._first_ns = time.monotonic_ns()
                if not pacer or j % 64 == 0:
                    now = time.monotonic_ns()
                    if now >= next_status:
                        next_status = now + _STATUS_INTERVAL_NS
                        for stream in streams:
                            stream.sample_queue()
                        if show_status:
                            print(self._status_text("streaming"), end="\r" if sys.stderr.isatty() else "\n",
                                  file=sys.stderr, flush=True)
            for stream, saturated in zip(streams, block.saturated):
                stream.saturated = saturated if stream.device is None else stream.device.saturated
            self.effect_counts = block.counts
            self._last_ns = time.monotonic_ns()

    # - reporting -
    def _note(self, text: str) -> None:
        if not self.options.quiet:
            print(text, file=sys.stderr, flush=True)

    def summary(self) -> dict:
        elapsed = ((self._last_ns or time.monotonic_ns()) - self._first_ns) / 1e9
        return {"samples": self.samples_done, "rate_hz": self.rate_hz, "speed": self.options.speed,
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
        return (f"{state}: {s['samples']} samples, {s['achieved_hz']:.1f} Hz, late p50 {late['p50_us']:.0f} us "
                f"p99 {late['p99_us']:.0f} us max {late['max_us']:.0f} us, dropped {s['dropped']}, "
                f"saturated {s['saturated']}" + (f"; {counts_text(self.effect_counts)}" if self.effect_counts else ""))


def _link_text(link: dict) -> str:
    """One line of what the link reported: refusals by cause, interface counters that moved, queue."""
    parts = [f"{n} {cause}" for cause, n in sorted(link.get("send_errors", {}).items())]
    parts = ["send refused: " + ", ".join(parts)] if parts else ["no send refused"]
    moved = {name: n for name, n in link.get("interface", {}).items() if n}
    if "interface" in link:
        parts.append("interface " + (", ".join(f"{name} +{n}" for name, n in moved.items()) or "counters unchanged"))
    if "queue_max_bytes" in link:
        parts.append(f"queue up to {link['queue_max_bytes']} B")
    if link.get("unread_at_close_bytes"):
        parts.append(f"{link['unread_at_close_bytes']} B or more unread by the reader when the link closed")
    return "; ".join(parts)


def _reap(pid: int) -> None:
    """End the producer (it may be blocked writing to the pipe we just closed) and collect it."""
    try:
        os.kill(pid, signal.SIGTERM)
    except ProcessLookupError:
        pass
    os.waitpid(pid, 0)


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


def needs_truth(configs: list[StreamConfig]) -> bool:
    """Whether a device among the streams reports navigation (then the simulation must compute truth)."""
    for config in configs:
        try:
            info = firmware_protocols.get(config.format)
        except KeyError:
            continue
        if config.device and info.device is not None and info.device_navigation:
            return True
    return False


def needs_increments(configs: list[StreamConfig]) -> bool:
    """Whether a stream's wire fields carry integrated outputs (then the simulation computes them): an encoder
    whose selected fields read them, or a device of a format that has such fields (its driver may ask)."""
    for config in configs:
        try:
            info = firmware_protocols.get(config.format)
            if config.device and info.device is not None:
                device = info.device(100.0, **config.options)
                encoders = list(device.encoders())
                if getattr(device, "carries_increments", False):
                    return True
            else:
                encoders = [info.encoder(**config.options)]
        except (KeyError, TypeError, ValueError):
            continue    # build_streams reports it
        if any(getattr(encoder, "uses_increments", False) for encoder in encoders):
            return True
    return False


# Effects that leave the gyro's increment the integral of the true attitude's rate (they act on the
# accelerometer, or on the rate outputs only, not on increments): with no other, a delta quaternion is the true
# attitude change alone (attitude.attitude_change).
_TRUE_RATE_EFFECTS = frozenset({"gravity", "lever_arm", "range", "resolution"})


def run_streams(scene, sim, configs: list[StreamConfig], options: RunOptions) -> dict:
    streams = build_streams(configs, tuple(sim.imu_names), float(scene.rate_hz))
    for stream in streams:
        stream.frame = scene.frame
        stream.exact_gyro = scene.effects <= _TRUE_RATE_EFFECTS
        if stream.device is not None and stream.info.device_navigation:
            from imu_emulator.motion.earth import position_frame
            stream.navigation = (scene.frame, float(scene.gravity_mps2), scene.origin, scene.gravity_model,
                                 position_frame(scene))
    if not math.isfinite(options.speed) or options.speed < 0:
        raise StreamError(f"--speed: expected a number >= 0, got {options.speed}")
    return Streamer(sim, float(scene.rate_hz), float(scene.t0_s), streams, options).run()
