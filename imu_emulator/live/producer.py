"""The producer process: it computes and encodes blocks ahead of the sender into shared memory and a pipe
(ring.py), bounded by the ring's size, so the send loop's per-sample work is only waiting and handing prepared payloads to the transports."""
from __future__ import annotations

import gc
import multiprocessing
import os
import signal
import traceback
from dataclasses import dataclass

from firmware_protocols.base import EncodeError
from imu_emulator.errors import ImuEmulatorError
from imu_emulator.live.config import StreamError
from imu_emulator.live.realtime import drop_realtime
from imu_emulator.live.ring import SHARED_RING, BlockReceiver, PipeReceiver, Ring

# Blocks hold about this much time: few pipe messages per second, and the sender's per-block work
# (reading the block's description in the ring, ring.py) stays far below a sample period.
_BLOCK_SECONDS = 0.02
_MAX_BLOCK = 500


@dataclass
class ProducerFailure:
    """An exception raised in the producer process, carried to the sender to be raised there."""
    user_error: bool
    message: str

    @classmethod
    def from_exception(cls, exc: BaseException) -> "ProducerFailure":
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


class Producer:
    """The blocks of one run, from its first sample to its limit (`total`, None: forever when looping), and the
    process that computes them. Its attributes are read in the child after the fork: the time offset must be
    set before `start`."""

    def __init__(self, sim, rate_hz: float, streams: list, total: int | None, loop: bool, time_offset_ns: int):
        self.sim = sim
        self.rate_hz = rate_hz
        self.streams = streams
        self.total = total
        self.loop = loop
        self.time_offset_ns = time_offset_ns
        self.scene_samples = int(sim.n_samples)

    def _loop_period_ns(self) -> int:
        return int(round(self.scene_samples * 1e9 / self.rate_hz))

    def blocks(self):
        """Encoded blocks from the first sample to the limit (forever when looping without a limit)."""
        block_len = max(1, min(_MAX_BLOCK, int(self.rate_hz * _BLOCK_SECONDS)))
        j = 0
        while self.total is None or j < self.total:
            k = j % self.scene_samples if self.loop else j
            n = min(block_len, self.scene_samples - k) if self.loop else block_len
            if self.total is not None:
                n = min(n, self.total - j)
            block = self.sim.block(k, n, run_sample=j)   # noise follows the run, not the looped scene
            offset = self.time_offset_ns
            if self.loop:   # each pass is stamped one scene length later: time keeps increasing
                offset += (j // self.scene_samples) * self._loop_period_ns()
            time_ns = block.time_ns(offset)
            encoded = [stream.encode(block, time_ns) for stream in self.streams]
            yield _Block(j, n, [e[0] for e in encoded], [e[1] for e in encoded], self.sim.counts())
            j += n

    def start(self):
        """Fork a process that computes and encodes ahead into shared memory and a pipe (ring.py). A process, not
        a thread: a thread holding the GIL while descheduled by other load would stall the real-time sender for
        tens of milliseconds. The ring's size bounds how far ahead it runs. Returns its pid and the sender's end
        (ring.BlockReceiver)."""
        ring = Ring() if SHARED_RING else None
        receiver, sender = multiprocessing.Pipe(duplex=False)
        pid = os.fork()
        if pid == 0:   # child: never returns
            code = 0
            put = sender.send if ring is None else (lambda item: ring.put(item, sender))
            try:
                receiver.close()
                # A collection walking the whole inherited heap would also copy every page on write.
                gc.freeze()
                signal.signal(signal.SIGINT, signal.SIG_IGN)   # the parent decides when to stop
                signal.signal(signal.SIGHUP, signal.SIG_IGN)
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
                drop_realtime()
                for item in self.blocks():
                    put(item)
                put(None)
            except (BrokenPipeError, ConnectionResetError):
                pass
            except BaseException as exc:
                try:
                    put(ProducerFailure.from_exception(exc))
                except Exception:
                    code = 1
            finally:
                os._exit(code)
        sender.close()
        return pid, PipeReceiver(receiver) if ring is None else BlockReceiver(ring, receiver)


def reap(pid: int) -> None:
    """End the producer (it may be blocked writing to the pipe we just closed) and collect it."""
    try:
        os.kill(pid, signal.SIGTERM)
    except ProcessLookupError:
        pass
    os.waitpid(pid, 0)
