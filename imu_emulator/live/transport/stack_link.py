"""What the flight-stack transports (px4_sim, ardupilot_sitl) share: the named lockstep timeout, the record of the
actuator outputs the stack sends (kept, never obeyed: the scene's motion is scripted), and their one-line notes."""
from __future__ import annotations

import csv
import socket
import sys

from imu_emulator.errors import TargetError

DEFAULT_TIMEOUT_S = 10.0


class LockstepTimeout(TargetError):
    """A flight stack in lockstep did not ask for the next step within the target's timeout."""


class ActuatorRecord:
    """The actuator outputs as CSV, one row per message the stack sent, flushed by row so a run that ends
    abruptly keeps what came. `columns` is the header; rows are written as given."""

    def __init__(self, path: str | None, columns: list[str], what: str):
        self.path, self.rows = path, 0
        self._file = None
        if path is None:
            return
        try:
            self._file = open(path, "w", newline="", encoding="utf-8")
        except OSError as exc:
            raise TargetError(f"{what}: record={path}: {exc.strerror or exc}") from None
        self._writer = csv.writer(self._file)
        self._writer.writerow(columns)

    def add(self, row) -> None:
        self.rows += 1
        if self._file is not None:
            self._writer.writerow(row)
            self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def note(text: str) -> None:
    """A line the user must see at once (a stack connecting, leaving, sending garbage), whatever --quiet says:
    each is a state change of the run, printed once, not per sample."""
    print(text, file=sys.stderr, flush=True)


def timeout_of(spec, default: float = DEFAULT_TIMEOUT_S) -> float:
    return float(dict(spec.params).get("timeout", default))


def record_path(spec) -> str | None:
    return dict(spec.params).get("record")


def bind(kind: str, host: str, port: int, socktype: int) -> socket.socket:
    """A socket bound to host:port for the stack to reach: UDP as it is, TCP listening for one connection (address
    reuse on, so a restarted run takes its port again at once). An OSError is a TargetError naming kind:host:port."""
    try:
        family, kind_, proto, _, address = socket.getaddrinfo(host, port, type=socktype, flags=socket.AI_PASSIVE)[0]
        sock = socket.socket(family, kind_, proto)
        if socktype == socket.SOCK_STREAM:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        if socktype == socket.SOCK_STREAM:
            sock.listen(1)
    except OSError as exc:
        raise TargetError(f"{kind}:{host}:{port}: {exc.strerror or exc}") from None
    return sock
