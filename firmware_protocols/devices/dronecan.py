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

The same node serves every DroneCAN format here, the GNSS/compass/baro node ("dronecan-gnss-compass-baro",
wire_formats.dronecan_sensors) included: NodeStatus and GetNodeInfo are what ArduPilot's and PX4's DroneCAN
stacks need to list the node; the sensors' drivers then register it from its first message.

Not done here: dynamic node-ID allocation as a client (the node needs its `node_id` option).
"""
from __future__ import annotations

import hashlib
import struct

import numpy as np

from firmware_protocols.base import CLASSIC_FRAME_DTYPE, Samples
from firmware_protocols.devices.base import Device, Periodic, single
from firmware_protocols.wire_formats.dronecan import can_id_for, transfer_frames
from firmware_protocols.registry import attach_device, get

NODE_STATUS_ID, NODE_STATUS_SIGNATURE = 341, 0x0F0868D0C1A7C6F1
GET_NODE_INFO_ID, GET_NODE_INFO_SIGNATURE = 1, 0xEE468A8121C46A9E
HEALTH_OK, MODE_OPERATIONAL = 0, 0
STATUS_PRIORITY, SERVICE_PRIORITY = 24, 30


def service_can_id(service_id: int, request: bool, destination: int, source: int, priority: int) -> int:
    return ((priority & 0x1F) << 24 | (service_id & 0xFF) << 16 | int(request) << 15 | (destination & 0x7F) << 8
            | 1 << 7 | (source & 0x7F))


class DroneCanNode(Device):
    kind = "can"

    def __init__(self, rate_hz: float, format_name: str, node_name: str = "org.imu_emulator.imu",
                 software_version: str = "1.0", hardware_version: str = "1.0", unique_id: str | None = None,
                 **encoder_options):
        super().__init__(rate_hz)
        self.encoder = get(format_name).encoder(**encoder_options)
        self.node_id = self.encoder.node_id
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
        frames = self.encoder.encode(single(samples, i))
        if self.status.due():
            status = self._rows(can_id_for(NODE_STATUS_ID, self.node_id, STATUS_PRIORITY),
                                transfer_frames(self.node_status(), NODE_STATUS_SIGNATURE, self.status_tid),
                                frames.dtype)
            self.status_tid = (self.status_tid + 1) & 0x1F
            frames = np.concatenate((status, frames))
        self.tick += 1
        return frames

    # - input -
    def _receive(self, messages, now_ns: int) -> list:
        replies = []
        for message in messages:
            can_id, data = message.arbitration_id, bytes(message.data)
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
            "unique_id": "32 hex digits (default: derived from node id and name)"}
for _format in ("dronecan-rawimu", "dronecan-solution", "dronecan-mag2", "dronecan-static-pressure",
                "dronecan-static-temperature"):
    attach_device(_format, lambda rate_hz, _f=_format, **options: DroneCanNode(rate_hz, _f, **options), _OPTIONS,
                  device_class=DroneCanNode)
# a GNSS receiver node: the streamer computes the navigation its fix falls back on
for _format in ("dronecan-fix2", "dronecan-gnss-compass-baro"):
    attach_device(_format, lambda rate_hz, _f=_format, **options: DroneCanNode(rate_hz, _f, **options), _OPTIONS,
                  navigation=True, device_class=DroneCanNode)
