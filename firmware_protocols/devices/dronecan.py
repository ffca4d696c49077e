"""A DroneCAN (UAVCAN v0) node: what every node on the bus must do beside publishing its data.

DSDL as shipped with pydronecan (dronecan/dsdl_specs/uavcan/protocol/): 341.NodeStatus (signature
0x0F0868D0C1A7C6F1): uint32 uptime_sec, uint2 health, uint3 mode, uint3 sub_mode, uint16
vendor_specific_status_code = 7 bytes; service 1.GetNodeInfo (signature 0xEE468A8121C46A9E): empty request;
response NodeStatus status, SoftwareVersion software_version (uint8 major, uint8 minor, uint8
optional_field_flags, uint32 vcs_commit, uint64 image_crc), HardwareVersion hardware_version (uint8 major,
uint8 minor, uint8[16] unique_id, uint8[<=255] certificate_of_authenticity), uint8[<=80] name. Bit fields are
packed from the most significant bit of each byte; integers little-endian; the final array uses the tail
array optimisation (no length prefix), the certificate inside HardwareVersion keeps its 8-bit length.

- NodeStatus goes out once per second of sample time (the first at the first sample), uptime counted in
  whole seconds of samples, health OK, mode OPERATIONAL; priority 24 (libcanard's "low").
- A GetNodeInfo request addressed to this node (service frame, request bit set, destination = node id) is
  answered with a multi-frame response: transfer CRC (CRC-16/CCITT-FALSE seeded with the signature) first,
  toggle bit alternating, same transfer id as the request, destination = the requester.
- Frames for other nodes or other services are ignored (counted); a GetNodeInfo with a malformed tail is
  an error (counted, no reply: DroneCAN has no error reply).

Dynamic node-ID allocation as a client (`node_id=0`; DSDL 1.dynamic_node_id.Allocation, signature
0x0B2A812620A11D40: uint7 node_id, bool first_part_of_unique_id, uint8[<=16] unique_id): until a node id is
allocated the node publishes nothing but anonymous single-frame Allocation requests (source 0, the 14-bit
discriminator = CRC-16 of the payload): the first 6 bytes of the unique id every 0.6-1.0 s of sample time
(pseudo-random, seeded by the unique id), then, each time an allocator's Allocation echoes the unique id
received so far, the next 6 (then 4) bytes at the next sample; a reply that does not match our unique id
restarts the exchange. When the allocator's reply carries the whole unique id and a node id, the node takes
that id (a note says which) and starts NodeStatus and data. `preferred_node_id` asks for one (default 0: any).
"""
from __future__ import annotations

import hashlib
import struct

import numpy as np

from firmware_protocols.base import CLASSIC_FRAME_DTYPE, Samples
from firmware_protocols.crc import crc16_ccitt_bytes
from firmware_protocols.devices.base import Device, Periodic, single
from firmware_protocols.dronecan import can_id_for
from firmware_protocols.registry import attach_device, get

NODE_STATUS_ID, NODE_STATUS_SIGNATURE = 341, 0x0F0868D0C1A7C6F1
ALLOCATION_ID, ALLOCATION_SIGNATURE = 1, 0x0B2A812620A11D40
GET_NODE_INFO_ID, GET_NODE_INFO_SIGNATURE = 1, 0xEE468A8121C46A9E
HEALTH_OK, MODE_OPERATIONAL = 0, 0
STATUS_PRIORITY, SERVICE_PRIORITY = 24, 30


def transfer_frames(payload: bytes, signature: int, transfer_id: int) -> list:
    """A transfer's CAN payloads: single frame up to 7 bytes, else CRC-prefixed and split in 7-byte chunks,
    each followed by the tail byte (start 0x80, end 0x40, toggle 0x20, transfer id)."""
    tid = transfer_id & 0x1F
    if len(payload) <= 7:
        return [payload + bytes([0xC0 | tid])]
    crc = crc16_ccitt_bytes(signature.to_bytes(8, "little") + payload, 0xFFFF)
    data = crc.to_bytes(2, "little") + payload
    chunks = [data[k:k + 7] for k in range(0, len(data), 7)]
    frames = []
    for index, chunk in enumerate(chunks):
        tail = (0x80 if index == 0 else 0) | (0x40 if index == len(chunks) - 1 else 0) | (0x20 if index % 2 else 0)
        frames.append(chunk + bytes([tail | tid]))
    return frames


def service_can_id(service_id: int, request: bool, destination: int, source: int, priority: int) -> int:
    return ((priority & 0x1F) << 24 | (service_id & 0xFF) << 16 | int(request) << 15 | (destination & 0x7F) << 8
            | 1 << 7 | (source & 0x7F))


class _Reassembler:
    """Multi-frame message transfers from other nodes -> payloads (transfer CRC checked)."""

    def __init__(self):
        self.partial = {}

    def feed(self, can_id: int, data: bytes, signature: int):
        if not data:
            return None
        tail, body, key = data[-1], data[:-1], (can_id & 0x7F, can_id >> 8 & 0xFFFF)
        if tail & 0x80 and tail & 0x40:
            self.partial.pop(key, None)
            return body
        if tail & 0x80:
            self.partial[key] = (tail & 0x1F, bytearray(body))
            return None
        entry = self.partial.get(key)
        if entry is None or entry[0] != tail & 0x1F:
            return None
        entry[1].extend(body)
        if not tail & 0x40:
            return None
        del self.partial[key]
        data = bytes(entry[1])
        if len(data) < 2 or crc16_ccitt_bytes(signature.to_bytes(8, "little") + data[2:], 0xFFFF) != \
                int.from_bytes(data[:2], "little"):
            return None
        return data[2:]


class _Allocation:
    """The client side of dynamic node-ID allocation (see the module docstring)."""

    def __init__(self, unique_id: bytes, preferred: int, rate_hz: float):
        self.uid, self.preferred, self.rate_hz = unique_id, preferred, rate_hz
        self.rng = np.random.default_rng(int.from_bytes(unique_id[:8], "little"))
        self.confirmed = 0          # unique-id bytes the allocator has echoed
        self.next_tick = 0
        self.node_id = 0
        self.reassembler = _Reassembler()

    def request(self, tick: int) -> bytes | None:
        """The anonymous Allocation payload due at this sample, if any."""
        if self.node_id or tick < self.next_tick:
            return None
        part = self.uid[self.confirmed:self.confirmed + (6 if self.confirmed < 12 else 4)]
        first = self.confirmed == 0
        self.next_tick = tick + int(self.rng.uniform(0.6, 1.0) * self.rate_hz)
        return bytes([(self.preferred if first else 0) << 1 | int(first)]) + part

    def response(self, payload: bytes, tick: int) -> None:
        node_id, received = payload[0] >> 1, payload[1:]
        if not received or received != self.uid[:len(received)]:
            self.confirmed = 0      # not ours (or a stale exchange): start over at the regular pace
            return
        if len(received) == len(self.uid) and node_id:
            self.node_id = node_id
            return
        self.confirmed = len(received)
        self.next_tick = tick       # the follow-up goes out with the next sample


class DroneCanNode(Device):
    kind = "can"

    def __init__(self, rate_hz: float, format_name: str, node_name: str = "org.imu_emulator.imu",
                 software_version: str = "1.0", hardware_version: str = "1.0", unique_id: str | None = None,
                 preferred_node_id: int = 0, **encoder_options):
        super().__init__(rate_hz)
        self._format, self._encoder_options = format_name, encoder_options
        dynamic = int(encoder_options.get("node_id", 42)) == 0
        if not 0 <= int(preferred_node_id) <= 127:
            raise ValueError(f"preferred_node_id: 0..127, got {preferred_node_id}")
        # with dynamic allocation a provisional node id 1 only sizes the frames until the real one arrives
        self.encoder = get(format_name).encoder(**{**encoder_options, **({"node_id": 1} if dynamic else {})})
        self.node_id = 0 if dynamic else self.encoder.node_id
        self.name = str(node_name).encode("ascii")[:80]
        sw, hw = (tuple(int(p) & 0xFF for p in str(v).split(".")[:2]) for v in (software_version, hardware_version))
        if unique_id is None:      # stable per node id and name, so a restarted emulator is the same node
            uid = hashlib.sha256(b"%d:" % self.node_id + self.name).digest()[:16]
        else:
            uid = bytes.fromhex(unique_id)
            if len(uid) != 16:
                raise ValueError(f"unique_id: 16 bytes (32 hex digits), got {len(uid)}")
        self.software = bytes(sw) + bytes([0]) + struct.pack("<IQ", 0, 0)
        self.hardware = bytes(hw) + uid + bytes([0])
        self.status = Periodic.every(1.0, rate_hz)
        self.status_tid = 0
        self.tick = 0
        self.frames_per_sample = self.encoder.frames_per_sample
        self.allocation = _Allocation(uid, int(preferred_node_id), rate_hz) if dynamic else None
        self._anonymous_tid = 0

    def node_status(self) -> bytes:
        uptime = int(self.tick / self.rate_hz)
        return struct.pack("<IBH", uptime & 0xFFFFFFFF, HEALTH_OK << 6 | MODE_OPERATIONAL << 3, 0)

    def _rows(self, can_id: int, payloads: list, dtype) -> np.ndarray:
        rows = np.zeros(len(payloads), dtype=dtype)
        for row, payload in zip(rows, payloads):
            row["can_id"], row["extended"], row["length"] = can_id, True, len(payload)
            row["data"][:len(payload)] = np.frombuffer(payload, dtype=np.uint8)
        return rows

    # - output -
    def output(self, samples: Samples, i: int) -> np.ndarray:
        if not self.node_id:
            return self._allocating()
        frames = self.encoder.encode(single(samples, i))
        if self.status.due():
            status = self._rows(can_id_for(NODE_STATUS_ID, self.node_id, STATUS_PRIORITY),
                                transfer_frames(self.node_status(), NODE_STATUS_SIGNATURE, self.status_tid),
                                frames.dtype)
            self.status_tid = (self.status_tid + 1) & 0x1F
            frames = np.concatenate((status, frames))
        self.tick += 1
        return frames

    def _allocating(self) -> np.ndarray:
        payload = self.allocation.request(self.tick)
        self.tick += 1
        if payload is None:
            return np.zeros(0, dtype=CLASSIC_FRAME_DTYPE)
        discriminator = crc16_ccitt_bytes(payload, 0xFFFF) & 0x3FFF
        can_id = STATUS_PRIORITY << 24 | discriminator << 10 | (ALLOCATION_ID & 0x3) << 8
        frames = self._rows(can_id, [payload + bytes([0xC0 | self._anonymous_tid])], CLASSIC_FRAME_DTYPE)
        self._anonymous_tid = (self._anonymous_tid + 1) & 0x1F
        return frames

    def _allocation_message(self, can_id: int, data: bytes) -> None:
        payload = self.allocation.reassembler.feed(can_id, data, ALLOCATION_SIGNATURE)
        if payload:
            self.allocation.response(payload, self.tick)
            if self.allocation.node_id:
                self.node_id = self.allocation.node_id
                self.encoder = get(self._format).encoder(**{**self._encoder_options, "node_id": self.node_id})
                self.notes.append(f"DroneCAN node id {self.node_id} allocated by node {can_id & 0x7F}")

    # - input -
    def _receive(self, messages, now_ns: int) -> list:
        replies = []
        for message in messages:
            can_id, data = message.arbitration_id, bytes(message.data)
            if (not self.node_id and message.is_extended_id and not can_id >> 7 & 1 and can_id & 0x7F
                    and (can_id >> 8) & 0xFFFF == ALLOCATION_ID):
                self._allocation_message(can_id, data)
                self.stats.commands += 1
                continue
            service = message.is_extended_id and can_id >> 7 & 1
            if not (service and can_id >> 15 & 1 and (can_id >> 8) & 0x7F == self.node_id
                    and (can_id >> 16) & 0xFF == GET_NODE_INFO_ID):
                self.stats.ignored_bytes += len(data)
                continue
            if len(data) != 1 or data[0] & 0xC0 != 0xC0:      # the request is empty: one frame, tail only
                self.stats.errors += 1
                continue
            requester, tid = can_id & 0x7F, data[0] & 0x1F
            payload = self.node_status() + self.software + self.hardware + self.name
            reply_id = service_can_id(GET_NODE_INFO_ID, False, requester, self.node_id, SERVICE_PRIORITY)
            replies.append(self._rows(reply_id, transfer_frames(payload, GET_NODE_INFO_SIGNATURE, tid),
                                      CLASSIC_FRAME_DTYPE))
            self.stats.commands += 1
        return replies


_OPTIONS = {"node_name": "node name answered to GetNodeInfo (default org.imu_emulator.imu)",
            "software_version": "major.minor (default 1.0)", "hardware_version": "major.minor (default 1.0)",
            "unique_id": "32 hex digits (default: derived from node id and name)",
            "preferred_node_id": "with node_id=0 (dynamic allocation): the node id to ask for (default 0: any)"}
for _format in ("dronecan-rawimu", "dronecan-solution", "dronecan-mag2"):
    attach_device(_format, lambda rate_hz, _f=_format, **options: DroneCanNode(rate_hz, _f, **options), _OPTIONS)
