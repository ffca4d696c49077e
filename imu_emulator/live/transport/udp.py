"""Serial-format packets as UDP datagrams, one datagram per sample (e.g. MAVLink to a ground station)."""
from __future__ import annotations

import errno
import socket

from imu_emulator.errors import TargetError
from imu_emulator.live.transport.base import TargetOptions, Transport, error_name, output_queue


class UdpTransport(Transport):
    datagrams = True

    def __init__(self, host: str, port: int, options: TargetOptions):
        try:
            family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
            self.sock = socket.socket(family, kind, proto)
            self.sock.connect(address)
        except OSError as exc:
            raise TargetError(f"udp:{host}:{port}: {exc.strerror or exc}") from None
        self.sock.setblocking(options.blocking)
        self.host, self.port = host, port

    def send(self, payload: bytes) -> bool:
        try:
            self.sock.send(payload)
        except (BlockingIOError, ConnectionRefusedError) as exc:
            # Refused = an earlier datagram met a closed port; UDP senders keep going regardless.
            self.count_refusal(error_name(exc))
            return False
        except OSError as exc:
            if exc.errno != errno.ENOBUFS:   # the interface's queue is full: a drop like any other
                raise
            self.count_refusal("ENOBUFS")
            return False
        return True

    def queued(self) -> int | None:
        """SIOCOUTQ: bytes in the socket's send queue (a receiver's own buffer is out of our sight)."""
        return output_queue(self.sock.fileno())

    def recv(self) -> bytes:
        """Datagrams from the peer (a connected socket receives from that address only)."""
        return b"".join(self.recv_datagrams())

    def recv_datagrams(self) -> list[bytes]:
        """The same, one bytes object per datagram: a device drops what a datagram leaves unfinished, since
        MAVLink over UDP puts whole frames in each datagram and the rest of a damaged one will never come."""
        chunks = []
        while True:
            try:
                chunks.append(self.sock.recv(65536, socket.MSG_DONTWAIT))
            except (BlockingIOError, InterruptedError, ConnectionRefusedError):
                return chunks

    def fileno(self) -> int:
        return self.sock.fileno()

    def describe(self) -> str:
        return f"udp {self.host}:{self.port}"

    def close(self) -> None:
        self.sock.close()
