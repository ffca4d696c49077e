"""A J1939 electronic control unit: address claim, Requests, and losing an address contention.

SAE J1939-81 / J1939-21 as summarised in ../shared/specs/devices.md and as the `can-j1939` stack (PyPI,
j1939/electronic_control_unit.py, controller_application.py) implements them:

- Address Claimed, PGN 60928 (0xEE00, PDU1, destination global 0xFF), priority 6, data = the 8-byte NAME
  (little-endian u64). Sent at start; sent again in answer to a Request (PGN 59904, 0xEA00; data = the
  requested PGN, 3 bytes little-endian) for it, whether the Request is global or addressed to us.
- Contention: an Address Claimed from another NAME for our source address. The lower NAME wins: if ours is
  lower we claim again; if ours is higher we lose: the data stops, we send "Cannot Claim Address" (Address
  Claimed from the null address 254) and the streamer shows a note saying so.
- After a claim the data waits 250 ms (J1939-81's wait before a new address is used) of sample time.
- Requests for the IMU PGNs (61482 ARI, 61485 ACCS) are answered with that PGN's latest values. A Request for
  any other PGN addressed to us gets a NACK (Acknowledgement PGN 59392, 0xE800: control byte 1, group
  function 0xFF, 0xFF 0xFF, requester's address, requested PGN); a global one for a PGN we lack is left
  unanswered, as J1939-21 asks.

The default NAME (0x0000000000001234: identity number 0x1234, manufacturer code 0, not arbitrary-address
capable) is an example; give the `ecu_name` option (integer or 16 hex digits) for a real one.
"""
from __future__ import annotations

import numpy as np

from firmware_protocols.base import CLASSIC_FRAME_DTYPE, Samples
from firmware_protocols.devices.base import Device, single
from firmware_protocols.wire_formats.j1939 import PGN_ACCS, PGN_ARI, J1939Encoder, j1939_id
from firmware_protocols.registry import attach_device

PGN_ADDRESS_CLAIMED, PGN_REQUEST, PGN_ACKNOWLEDGEMENT = 0xEE00, 0xEA00, 0xE800
GLOBAL, NULL_ADDRESS = 0xFF, 0xFE
CLAIM_PRIORITY = 6
CLAIM_WAIT_S = 0.25


def pdu1_id(priority: int, pgn: int, destination: int, source: int) -> int:
    """PDU1 (PF < 240): the PS byte carries the destination address."""
    return j1939_id(priority, (pgn & 0x3FF00) | destination, source)


def parse_id(can_id: int) -> tuple[int, int | None, int]:
    """(PGN, destination or None for PDU2, source address)."""
    pf, ps, source = (can_id >> 16) & 0xFF, (can_id >> 8) & 0xFF, can_id & 0xFF
    pgn = (can_id >> 8) & 0x3FFFF
    if pf < 240:
        return pgn & 0x3FF00, ps, source
    return pgn, None, source


class J1939Device(Device):
    kind = "can"

    def __init__(self, rate_hz: float, ecu_name=0x1234, **encoder_options):
        super().__init__(rate_hz)
        self.encoder = J1939Encoder(**encoder_options)
        self.address = self.encoder.source_address
        name = int(ecu_name, 16) if isinstance(ecu_name, str) else int(ecu_name)
        if not 0 <= name < 1 << 64:
            raise ValueError(f"ecu_name: a 64-bit NAME, got {ecu_name!r}")
        self.name = name
        self.lost = False
        self.frames_per_sample = self.encoder.frames_per_sample
        self._claim_pending = True         # sent with the first sample
        self._quiet_until = 0
        self.tick = 0
        self.last = None                   # the latest sample's ARI and ACCS rows

    def _row(self, can_id: int, data: bytes) -> np.ndarray:
        row = np.zeros(1, dtype=CLASSIC_FRAME_DTYPE)
        row["can_id"], row["extended"], row["length"] = can_id, True, len(data)
        row["data"][0, :len(data)] = np.frombuffer(data, dtype=np.uint8)
        return row

    def _claim(self) -> np.ndarray:
        source = NULL_ADDRESS if self.lost else self.address
        self._quiet_until = self.tick + int(round(CLAIM_WAIT_S * self.rate_hz))
        return self._row(pdu1_id(CLAIM_PRIORITY, PGN_ADDRESS_CLAIMED, GLOBAL, source), self.name.to_bytes(8, "little"))

    # - output -
    def output(self, samples: Samples, i: int) -> np.ndarray:
        parts = []
        if self._claim_pending:
            parts.append(self._claim())
            self._claim_pending = False
        frames = self.encoder.encode(single(samples, i))
        self.last = frames
        if not self.lost and self.tick >= self._quiet_until:
            parts.append(frames)
        self.tick += 1
        return np.concatenate(parts) if parts else frames[:0]

    # - input -
    def _receive(self, messages, now_ns: int) -> list:
        replies = []
        for message in messages:
            if not message.is_extended_id:
                self.stats.ignored_bytes += len(message.data)
                continue
            pgn, destination, source = parse_id(message.arbitration_id)
            data = bytes(message.data)
            if pgn == PGN_ADDRESS_CLAIMED and source == self.address and len(data) == 8 and not self.lost:
                other = int.from_bytes(data, "little")
                if other == self.name:
                    continue                    # our own claim echoed back by the bus
                self.stats.commands += 1
                if other < self.name:
                    self.lost = True
                    self.notes.append(f"J1939 address {self.address:#04x} lost to NAME {other:#018x} (ours "
                                      f"{self.name:#018x}): data stopped, Cannot Claim Address sent")
                replies.append(self._claim())
            elif pgn == PGN_REQUEST and destination in (self.address, GLOBAL):
                if len(data) < 3:
                    self.stats.errors += 1
                    continue
                replies.extend(self._request(int.from_bytes(data[:3], "little"), destination, source))
            else:
                self.stats.ignored_bytes += len(data)
        return replies

    def _request(self, requested: int, destination: int, requester: int) -> list:
        if requested == PGN_ADDRESS_CLAIMED:
            self.stats.commands += 1
            return [self._claim()]
        if requested in (PGN_ARI, PGN_ACCS) and self.last is not None and not self.lost:
            self.stats.commands += 1
            return [self.last[1:2] if requested == PGN_ACCS else self.last[0:1]]
        if destination == GLOBAL or self.lost:
            self.stats.ignored_bytes += 3
            return []
        self.stats.errors += 1
        nack = bytes([1, 0xFF, 0xFF, 0xFF, requester]) + requested.to_bytes(3, "little")
        return [self._row(pdu1_id(CLAIM_PRIORITY, PGN_ACKNOWLEDGEMENT, GLOBAL, self.address), nack)]


attach_device("j1939", lambda rate_hz, **options: J1939Device(rate_hz, **options),
              {"ecu_name": "the 64-bit J1939 NAME claimed with the source address (integer or 16 hex digits; "
                           "default 0x1234)"}, device_class=J1939Device)
