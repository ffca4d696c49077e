"""Helpers the streaming tests share: a small scene, the emulator as a subprocess, a pty reader, and
independent decoders (pymavlink, dronecan). Holds no tests itself."""
from __future__ import annotations

import os
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from tests.support.paths import REPO
from tests.support.timing import scaled


SCENE = """
[scene]
rate_hz = {rate}
duration_s = {duration}

[trajectory]
shape = "circle"
radius_m = 5.0
frequency_hz = 0.5
height_m = 0.0

[attitude]
mode = "tangent"

[[imu]]
name = "imu0"

[[imu]]
name = "imu1"
lever_arm_m = [0.0, 0.2, 0.0]
mounting_rpy_deg = [180.0, 0.0, 90.0]

[effects]
gravity = true
lever_arm = true
mounting = true
"""


def write_scene(directory: Path, rate: float = 200, duration: float = 5.0, extra: str = "") -> Path:
    path = Path(directory) / "scene.toml"
    path.write_text(SCENE.format(rate=rate, duration=duration) + extra)
    return path


# An ENU scene's body is forward-left-up; every stream sends the part's forward-right-down axes (issue 24): the
# half turn about x, y and z negated. NED scenes are forward-right-down already.
FRD_FROM_SCENE = {"ENU": np.array([1.0, -1.0, -1.0]), "NED": np.ones(3)}


def reference(scene_path: Path, imu: int = 0):
    """The samples the emulator should send, computed here in-process from the same scene, in the
    forward-right-down axes of firmware_protocols.Samples (a forward-left-up wire, Xsens, multiplies by
    FRD_FROM_SCENE["ENU"] again)."""
    from imu_emulator.scene.load import load_scene
    from imu_emulator.runtime.simulation import Simulation
    scene = load_scene(scene_path)
    block = Simulation(scene).block(0, scene.n_samples)
    signs = FRD_FROM_SCENE[scene.frame]
    return scene, block.t_s, block.accel[imu] * signs, block.gyro[imu] * signs


def emulator_command(*args) -> list[str]:
    return [sys.executable, "-m", "imu_emulator", "stream", *map(str, args)]


def run_emulator(*args, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(emulator_command(*args), capture_output=True, text=True, timeout=scaled(timeout), cwd=REPO)


class Emulator:
    """`imu-emulator stream ...` in a subprocess; `targets` are the paths it printed, one per stream."""

    def __init__(self, *args, streams: int = 1):
        self.proc = subprocess.Popen(emulator_command(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, cwd=REPO)
        self.targets = []
        for _ in range(streams):
            line = self.proc.stdout.readline()
            match = re.search(r"-> (?:slcan )?(\S+)", line)
            if not match:
                self.proc.kill()
                raise AssertionError(f"emulator printed {line!r}; stderr: {self.proc.stderr.read()}")
            self.targets.append(match.group(1))

    def interrupt(self, timeout: float = 10) -> tuple[int, str]:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        return self.wait(timeout)

    def wait(self, timeout: float = 30) -> tuple[int, str]:
        """(exit code, stderr); AssertionError if it runs past `timeout` (scaled to the machine)."""
        limit = scaled(timeout)
        try:
            _, err = self.proc.communicate(timeout=limit)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
            raise AssertionError(f"emulator did not finish within {limit:.0f} s; stderr: {err}")
        return self.proc.returncode, err

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


def open_pty_reader(path: str) -> int:
    return os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)


def read_for(fd: int, seconds: float, stop_after: int | None = None) -> bytes:
    """Everything the fd delivers within `seconds` (or until stop_after bytes)."""
    chunks, size = [], 0
    end = time.monotonic() + seconds
    while time.monotonic() < end and (stop_after is None or size < stop_after):
        ready, _, _ = select.select([fd], [], [], max(0.0, end - time.monotonic()))
        if ready:
            try:
                data = os.read(fd, 65536)
            except (BlockingIOError, OSError):
                continue
            chunks.append(data)
            size += len(data)
    return b"".join(chunks)


def mavlink_parse(data: bytes, types=("HIGHRES_IMU",)):
    """Messages of `types` (None: every valid one; the device interleaves HEARTBEAT) and the bad packets,
    by pymavlink's own parser."""
    from pymavlink.dialects.v20 import common as mavlink2
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    messages = mav.parse_buffer(data) or []
    good = [m for m in messages if m.get_type() != "BAD_DATA" and (types is None or m.get_type() in types)]
    bad = [m for m in messages if m.get_type() == "BAD_DATA"]
    return good, bad


def check_highres_against_scene(messages, scene, accel, gyro, k=None) -> np.ndarray:
    """Asserts each message equals the scene's sample at its time since start (or at indices k), to float32;
    returns the sample indices."""
    if k is None:
        k = np.array([round(m.time_usec * 1e-6 * scene.rate_hz) for m in messages]) % scene.n_samples
    got_acc = np.array([[m.xacc, m.yacc, m.zacc] for m in messages])
    got_gyro = np.array([[m.xgyro, m.ygyro, m.zgyro] for m in messages])
    np.testing.assert_array_equal(got_acc, accel[k].astype(np.float32))
    np.testing.assert_array_equal(got_gyro, gyro[k].astype(np.float32))
    return k


def candump_frames(text: str, data_type_id: int = 1003) -> list:
    """(can_id, data) of the frames of one DroneCAN data type (RawIMU by default: a device adds NodeStatus) in
    `candump -L` output; classic lines are ID#DATA, CAN FD lines ID##<flags nibble>DATA."""
    frames = []
    for line in text.splitlines():
        can_id, _, data = line.split()[2].partition("#")
        if data.startswith("#"):
            data = data[2:]
        if (int(can_id, 16) >> 8) & 0xFFFF == data_type_id:
            frames.append((int(can_id, 16), bytes.fromhex(data)))
    return frames


def dronecan_rawimu(frames, fd: bool = False):
    """Decode (can_id, data) pairs into RawIMU transfers with the dronecan library's own machinery (fd: the
    frames are CAN FD frames)."""
    import dronecan
    from dronecan.transport import Frame, Transfer
    transfers, pending = [], []
    for can_id, data in frames:
        if data[-1] & 0x80:   # start of transfer: whatever was pending is incomplete
            pending = []
        pending.append(Frame(can_id, bytearray(data), canfd=fd))
        if data[-1] & 0x40:   # end of transfer
            transfer = Transfer()
            try:
                transfer.from_frames(pending)
            except Exception:
                pending = []
                continue
            pending = []
            if transfer.data_type_id == dronecan.uavcan.equipment.ahrs.RawIMU.default_dtid:
                transfers.append(transfer)
    return transfers


def read_until_closed(fd, timeout=60.0) -> bytes:
    """Everything until the emulator closes its side (EIO), as a driver reading a port would; AssertionError if
    it is still open after `timeout` (scaled to the machine), never a silent partial read."""
    chunks = []
    limit = scaled(timeout)
    end = time.monotonic() + limit
    try:
        while True:
            if time.monotonic() >= end:
                raise AssertionError(f"the emulator's port was still open after {limit:.0f} s "
                                     f"({sum(map(len, chunks))} bytes read)")
            ready, _, _ = select.select([fd], [], [], 1.0)
            if ready:
                try:
                    data = os.read(fd, 65536)
                except OSError:
                    break
                if not data:
                    break
                chunks.append(data)
    finally:
        os.close(fd)
    return b"".join(chunks)


def wire_attitude(scene, quat):
    """The attitude a wire carries for the scene's attitude quaternions `quat` (n, 4; w first, body -> the scene's
    frame): the upright part's forward-right-down axes w.r.t. NED, as a scipy Rotation (the oracle: REP-free matrices,
    not firmware_protocols.axes). An ENU scene's body is forward-left-up: turned by pi about x."""
    from scipy.spatial.transform import Rotation
    body = Rotation.from_quat(np.asarray(quat)[..., [1, 2, 3, 0]])
    if scene.frame != "ENU":
        return body
    ned_from_enu = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    return Rotation.from_matrix(ned_from_enu) * body * Rotation.from_matrix(np.diag(FRD_FROM_SCENE["ENU"]))
