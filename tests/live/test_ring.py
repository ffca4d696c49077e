"""Issue 25: the producer's blocks reach the sender through shared memory (imu_emulator/live/ring.py). Checked here:
every packet arrives whole and in order through the ring's wrap-around, its back-pressure and the pipe it falls back
to, with the next block taken before the current one is read (as the send loop takes it in slack); a stream sends
the same bytes with the ring as through the pipe alone (the code before the ring), and those bytes decode to the
scene (pymavlink); nothing is left behind when the sender is killed or the producer fails."""
from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from firmware_protocols.base import _FIELD_WIDTHS, Samples
from imu_emulator.live import producer as producer_module
from imu_emulator.live import ring as ring_module
from imu_emulator.live.producer import ProducerFailure, _Block
from imu_emulator.live.ring import Packets, Ring, RingBlock
from tests.support.stream import Emulator, check_highres_against_scene, mavlink_parse, reference, write_scene

pytestmark = pytest.mark.skipif(not ring_module.SHARED_RING, reason="the ring is used on x86 only")


def _blocks(rng, count: int) -> list:
    """Blocks of 1-3 streams of random packets, some with a device's random samples; some must go down the pipe:
    a list item (as CAN frames), changed effect counters, more bytes than a quarter of the 4 KiB ring."""
    blocks, j0 = [], 0
    counts = {}
    for b in range(count):
        n = int(rng.integers(1, 12))
        items = []
        for _ in range(int(rng.integers(1, 4))):
            lengths = rng.integers(1, 60 if b % 7 else 200, n)     # every 7th block: too large for the ring
            data = rng.integers(0, 256, int(lengths.sum()), dtype=np.uint8).tobytes()
            items.append(Packets(data, [0, *np.cumsum(lengths).tolist()]))
        if b % 3 == 1:          # a device's raw samples: a few fields present, a start
            fields = {name: rng.normal(size=(n, width) if width else n) for name, width in _FIELD_WIDTHS.items()
                      if rng.random() < 0.3}
            items.append(Samples(np.arange(n, dtype=np.int64) + b * 10**9, rng.normal(size=(n, 3)),
                                 rng.normal(size=(n, 3)), **{k: v for k, v in fields.items()
                                                             if k not in ("accel", "gyro")}, start_ns=b))
        if b % 11 == 5:
            items.append([bytes([b, k]) for k in range(n)])
        if b % 13 == 12:
            counts = {"imu0": {"range.gyro.x": b}}
        blocks.append(_Block(j0, n, items, [b * 10 + s for s in range(len(items))], counts))
        j0 += n
    return blocks


def _payloads(block) -> list:
    out = []
    for item in block.items:
        if isinstance(item, Samples):
            out.append({name: None if value is None else np.asarray(value).tolist()
                        for name, value in vars(item).items()})
        else:
            out.append([bytes(item[i]) for i in range(len(block))])
    return out


def test_blocks_cross_whole_and_in_order_through_wrap_back_pressure_and_the_pipe():
    rng = np.random.default_rng(25)
    sent = _blocks(rng, 80)
    expected = [(b.j0, b.n, _payloads(b), list(b.saturated), dict(b.counts)) for b in sent]
    ring = Ring(capacity=4096, max_blocks=4)
    receiver, sender = multiprocessing.Pipe(duplex=False)

    def produce():
        for block in sent:
            ring.put(block, sender)
        ring.put(None, sender)

    producer = threading.Thread(target=produce, daemon=True)
    producer.start()
    got, kinds = [], set()
    end = ring_module.BlockReceiver(ring, receiver)
    current = end.recv()
    while current is not None:
        following = end.recv()      # taken before the current block is read, as the send loop does in slack
        kinds.add(type(current))
        got.append((current.j0, len(current), _payloads(current), list(current.saturated), dict(current.counts)))
        current = following
    producer.join(10)
    assert got == expected
    assert kinds == {RingBlock, _Block}     # both ways were taken (ring and pipe)
    assert ring.header[1] == len(sent) + 1 and end.taken == len(sent) + 1


def _stream_file(tmp_path: Path, name: str, monkeypatch, ring: bool, capacity: int | None = None) -> bytes:
    from imu_emulator.cli import main
    monkeypatch.setattr(producer_module, "SHARED_RING", ring)
    if capacity:
        monkeypatch.setattr(ring_module, "RING_BYTES", capacity)
        monkeypatch.setattr(ring_module, "MAX_BLOCKS", 4)
    out = tmp_path / name
    scene = write_scene(tmp_path, rate=1000, duration=1.0)
    # Paced (the next block is taken early, in slack) and looped past the scene's end, through the ring's wrap.
    assert main(["stream", str(scene), "--format", "mavlink-highres", "--to", f"file:{out}", "--loop",
                 "--duration", "1.2", "--quiet"]) == 0
    return out.read_bytes()


def test_a_stream_sends_the_same_bytes_through_the_ring_as_through_the_pipe(tmp_path, monkeypatch):
    through_pipe = _stream_file(tmp_path, "pipe.bin", monkeypatch, ring=False)
    small_ring = _stream_file(tmp_path, "small.bin", monkeypatch, ring=True, capacity=8192)
    monkeypatch.undo()
    default_ring = _stream_file(tmp_path, "ring.bin", monkeypatch, ring=True)
    assert small_ring == through_pipe and default_ring == through_pipe
    scene, _, accel, gyro = reference(tmp_path / "scene.toml")
    messages, bad = mavlink_parse(through_pipe)
    assert not bad and len(messages) == 1200
    first = check_highres_against_scene(messages[:1000], scene, accel, gyro)
    assert list(first) == list(range(1000))


def _stream_udp(tmp_path: Path, monkeypatch, ring: bool) -> list[bytes]:
    """A device stream (MAVLink answers its driver over UDP, so the producer hands it raw samples), received here."""
    import socket

    from imu_emulator.cli import main
    monkeypatch.setattr(producer_module, "SHARED_RING", ring)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    # Room for the whole run (1200 small datagrams take about 1.5 MB of socket memory): the receiving thread shares
    # the GIL with the sender, and on a loaded machine it once read nothing while a stalled sender caught up (94
    # datagrams lost in the kernel at a default 208 KiB buffer, CI 2026-12-02).
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.5)
    got = []

    def receive():
        while True:
            try:
                got.append(sock.recv(4096))
            except TimeoutError:
                if not streaming.is_alive():
                    return

    scene = write_scene(tmp_path, rate=1000, duration=1.0)
    streaming = threading.Thread(target=main, args=(["stream", str(scene), "--format", "mavlink-highres", "--to",
                                                       f"udp:127.0.0.1:{sock.getsockname()[1]}", "--loop",
                                                       "--duration", "1.2", "--quiet"],))
    receiver = threading.Thread(target=receive)
    streaming.start()
    receiver.start()
    streaming.join(60)
    receiver.join(60)
    sock.close()
    return got


def test_a_device_stream_sends_the_same_bytes_through_the_ring_as_through_the_pipe(tmp_path, monkeypatch):
    through_pipe = _stream_udp(tmp_path, monkeypatch, ring=False)
    read = []
    samples = ring_module._samples
    monkeypatch.setattr(ring_module, "_samples", lambda *args: read.append(1) or samples(*args))
    through_ring = _stream_udp(tmp_path, monkeypatch, ring=True)
    assert len(read) >= 50          # the samples came through the ring (60 blocks of 20)
    assert through_ring == through_pipe
    scene, _, accel, gyro = reference(tmp_path / "scene.toml")
    messages, bad = mavlink_parse(b"".join(through_ring))
    assert not bad and len(messages) == 1200
    assert list(check_highres_against_scene(messages[:1000], scene, accel, gyro)) == list(range(1000))


def _anonymous_shared_maps() -> int:
    """Shared anonymous mappings of this process (the kernel names them /dev/zero, deleted)."""
    return sum("/dev/zero" in line for line in Path("/proc/self/maps").read_text().splitlines())


def test_a_failing_producer_leaves_no_mapping_and_no_process(tmp_path, monkeypatch, capsys):
    import gc

    from imu_emulator.cli import main
    from imu_emulator.errors import ImuEmulatorError
    from imu_emulator.live.stream import Stream
    encode = Stream.encode
    calls = []

    def failing(self, block, time_ns):     # in the forked producer: its 6th block fails
        calls.append(1)
        if len(calls) == 6:
            raise ImuEmulatorError("encoder broke on purpose")
        return encode(self, block, time_ns)

    monkeypatch.setattr(Stream, "encode", failing)
    scene = write_scene(tmp_path, rate=1000, duration=1.0)
    shm_before = sorted(os.listdir("/dev/shm"))
    maps_before = _anonymous_shared_maps()
    children_before = _all_children(os.getpid())    # the suite's other tests may have left children of their own
    code = main(["stream", str(scene), "--format", "mavlink-highres", "--to", f"file:{tmp_path / 'o.bin'}",
                 "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "encoder broke on purpose" in err
    gc.collect()
    assert _anonymous_shared_maps() == maps_before
    assert sorted(os.listdir("/dev/shm")) == shm_before
    # the producer was collected: no child left beside those there before (a zombie would still be listed)
    assert _all_children(os.getpid()) <= children_before


def _all_children(pid: int) -> set[int]:
    """The children of every thread of process pid."""
    return {int(c) for task in Path(f"/proc/{pid}/task").iterdir()
            for c in (task / "children").read_text().split()}


def _children(pid: int) -> list[int]:
    text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    return [int(p) for p in text.split()]


def _gone(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


def test_a_killed_sender_leaves_no_shared_memory_and_its_producer_ends(tmp_path):
    scene = write_scene(tmp_path, rate=1000, duration=1.0)
    out = tmp_path / "o.bin"
    shm_before = sorted(os.listdir("/dev/shm"))
    with Emulator(scene, "--format", "mavlink-highres", "--to", f"file:{out}", "--loop", "--quiet") as emu:
        while not out.exists() or out.stat().st_size < 10_000:      # streaming (the producer is running ahead)
            assert emu.proc.poll() is None
            time.sleep(0.05)
        children = _children(emu.proc.pid)
        assert len(children) == 1
        emu.proc.send_signal(signal.SIGKILL)
        emu.proc.wait()
        producer, = children
        for _ in range(600):        # it notices when it next needs room (the ring holds about a second at 1 kHz)
            if _gone(producer):
                break
            time.sleep(0.05)
        assert _gone(producer)
    assert sorted(os.listdir("/dev/shm")) == shm_before
