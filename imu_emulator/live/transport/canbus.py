"""Any python-can interface by name: socketcan, virtual, slcan, udp_multicast, pcan, kvaser, ..."""
from __future__ import annotations

import errno
from pathlib import Path

import can

from imu_emulator.errors import TargetError
from imu_emulator.live.transport.base import TargetOptions, Transport, error_name, output_queue
from imu_emulator.live.transport.frames import to_messages
from imu_emulator.live.transport.socketcan_frames import FrameSender, pack

# Interface counters of a SocketCAN device that tell of frames lost after `send` returned (vcan loops frames
# back through the receive path, so a full backlog shows as rx_dropped). A receiving socket's own full
# buffer shows in none of them: only its owner can see that (SO_RXQ_OVFL).
_INTERFACE_COUNTERS = ("tx_dropped", "tx_errors", "tx_fifo_errors", "rx_dropped", "rx_errors", "rx_over_errors")
# How long a blocking send (--speed 0) waits for room on the bus before calling the frame dropped.
_BLOCKING_TIMEOUT_S = 1.0


class CanBusTransport(Transport):

    def __init__(self, interface: str, channel: str, options: TargetOptions, port: int = 0):
        if interface not in can.interfaces.VALID_INTERFACES:
            raise TargetError(f"can:{interface}: unknown python-can interface "
                              f"(known: {', '.join(sorted(can.interfaces.VALID_INTERFACES))})")
        kwargs = {"fd": options.fd}
        # socketcan's bit rate is set with `ip link`; passing it would only be ignored, so we do not pretend.
        if options.bitrate and interface not in ("socketcan", "virtual", "udp_multicast"):
            kwargs["bitrate"] = options.bitrate
        if options.data_bitrate and interface not in ("socketcan", "virtual", "udp_multicast"):
            kwargs["data_bitrate"] = options.data_bitrate
        if port:
            kwargs["port"] = port    # udp_multicast only: the target parser takes a port for nothing else
        if interface == "slcan":
            kwargs["sleep_after_open"] = 0.1   # python-can waits 2 s for Arduino-style resets by default
        try:
            self.bus = can.Bus(interface=interface, channel=channel, **kwargs)
        except OSError as exc:
            raise TargetError(f"can:{interface}:{channel}: {_os_reason(exc)}") from None
        except (can.CanError, ValueError, ImportError, TypeError) as exc:
            cause = exc.__cause__ if isinstance(exc.__cause__, OSError) else None
            reason = _os_reason(cause) if cause else (str(exc).splitlines() or [type(exc).__name__])[0]
            raise TargetError(f"can:{interface}:{channel}: {reason}") from None
        self.interface, self.channel = interface, channel
        self._brs = bool(options.data_bitrate)
        self._timeout = _BLOCKING_TIMEOUT_S if options.blocking else 0.0
        self._counters_at_open = self._interface_counters()
        # SocketCAN without waiting (the real-time case): a sample's frames packed once, one system call
        # (see socketcan_frames). Blocking sends (--speed 0) keep python-can's select-and-retry.
        self._frames = (FrameSender(self.bus.socket)
                        if interface == "socketcan" and not self._timeout and hasattr(self.bus, "socket") else None)

    def prepare(self, payload, time_ns: int):
        if self._frames is not None:
            return pack(payload, bitrate_switch=self._brs)
        return to_messages(payload, bitrate_switch=self._brs)

    def send(self, messages) -> bool:
        if self._frames is not None:
            code = self._frames.send(*messages)
            if code is not None:
                self.count_refusal(errno.errorcode.get(code, f"errno {code}"))
                return False
            return True
        for message in messages:
            try:
                self.bus.send(message, timeout=self._timeout)
            except can.CanError as exc:
                # The rest of this sample's frames go too: a receiver gets an incomplete transfer at
                # worst, which it discards, never frames from two different samples interleaved.
                # python-can's "Transmit buffer full" (select said not writable) carries no errno.
                self.count_refusal("would-block" if getattr(exc, "error_code", None) is None
                                   and "buffer full" in str(exc) else error_name(exc))
                return False
        return True

    def recv(self) -> list:
        messages = []
        while True:
            try:
                message = self.bus.recv(timeout=0)
            except can.CanError:
                return messages
            if message is None:
                return messages
            messages.append(message)

    def fileno(self) -> int | None:
        try:
            fd = self.bus.fileno()
        except NotImplementedError:   # virtual and some vendor interfaces: polled at each deadline instead
            return None
        return fd if isinstance(fd, int) and fd >= 0 else None

    def describe(self) -> str:
        return f"can:{self.interface}:{self.channel}"

    def _interface_counters(self) -> dict | None:
        if self.interface != "socketcan":
            return None
        folder = Path("/sys/class/net") / self.channel / "statistics"
        try:
            return {name: int((folder / name).read_text()) for name in _INTERFACE_COUNTERS}
        except (OSError, ValueError):
            return None

    def queued(self) -> int | None:
        sock = getattr(self.bus, "socket", None)
        return output_queue(sock.fileno()) if sock is not None else None

    def link_report(self) -> dict:
        report = super().link_report()
        now = self._interface_counters()
        if now is not None and self._counters_at_open is not None:
            # Interface-wide: other senders on the same interface count here too.
            report["interface"] = {name: now[name] - self._counters_at_open[name] for name in now}
        return report

    def close(self) -> None:
        self.bus.shutdown()


def _os_reason(exc: OSError) -> str:
    if exc.errno == errno.EAFNOSUPPORT:
        return "this kernel has no SocketCAN support (AF_CAN unavailable)"
    if exc.errno in (errno.ENODEV, errno.ENXIO):
        return "no such CAN device"
    return exc.strerror or str(exc)
