"""The DroneCAN node's own frames checked against pydronecan: NodeStatus byte for byte as pydronecan encodes
it, and a GetNodeInfo request pydronecan builds answered with a response pydronecan decodes. (The same
conversation over a real SocketCAN bus runs inside User Mode Linux: tests/live/socketcan/.)"""
import can
import numpy as np
import pytest

import firmware_protocols
from firmware_protocols import Samples
from firmware_protocols.base import frame_bytes

dronecan = pytest.importorskip("dronecan")
from dronecan.transport import Frame, Transfer  # noqa: E402

protocol = dronecan.uavcan.protocol


def _samples(n=300, rate=100.0):
    t = (np.arange(n) * 1e9 / rate).astype(np.int64)
    return Samples(t, np.tile([0.1, -0.2, -9.8], (n, 1)), np.tile([0.01, 0.02, 0.03], (n, 1)))


def test_node_status_every_second_byte_for_byte_as_pydronecan_encodes_it():
    device = firmware_protocols.create_device("dronecan-rawimu", 100.0, node_id=42)
    samples = _samples()
    outputs = [device.output(samples, i) for i in range(300)]
    status_id = (24 << 24) | (341 << 8) | 42
    with_status = [i for i, frames in enumerate(outputs) if status_id in frames["can_id"]]
    assert with_status == [0, 100, 200]
    for transfer_id, i in enumerate(with_status):
        rows = outputs[i][outputs[i]["can_id"] == status_id]
        want = Transfer(payload=protocol.NodeStatus(uptime_sec=i // 100, health=0, mode=0, sub_mode=0,
                                                    vendor_specific_status_code=0),
                        source_node_id=42, transfer_id=transfer_id, transfer_priority=24)
        assert [frame_bytes(r) for r in rows] == [bytes(f.bytes) for f in want.to_frames()]
        assert all(int(r["can_id"]) == f.message_id for r, f in zip(rows, want.to_frames()))
    # the RawIMU transfer is still there, every sample
    assert all(((f["can_id"] >> 8) & 0xFFFF == 1003).sum() == 7 for f in outputs)


def test_get_node_info_request_answered_with_what_pydronecan_decodes():
    device = firmware_protocols.create_device("dronecan-rawimu", 100.0, node_id=42, node_name="org.test.imu",
                                              software_version="3.7")
    request = Transfer(payload=protocol.GetNodeInfo.Request(), source_node_id=100, dest_node_id=42,
                       transfer_id=9, transfer_priority=30, service_not_message=True,
                       request_not_response=True)
    messages = [can.Message(arbitration_id=f.message_id, data=bytes(f.bytes), is_extended_id=True)
                for f in request.to_frames()]
    # a request for another node and a stray frame are ignored
    other = Transfer(payload=protocol.GetNodeInfo.Request(), source_node_id=100, dest_node_id=43,
                     transfer_id=1, service_not_message=True, request_not_response=True).to_frames()[0]
    messages += [can.Message(arbitration_id=other.message_id, data=bytes(other.bytes), is_extended_id=True),
                 can.Message(arbitration_id=0x123, data=b"\x01", is_extended_id=False)]
    replies = device.receive(messages)
    assert len(replies) == 1
    frames = [Frame(int(r["can_id"]), bytearray(frame_bytes(r))) for r in replies[0]]
    response = Transfer()
    response.from_frames(frames)
    assert response.service_not_message and not response.request_not_response
    assert (response.source_node_id, response.dest_node_id, response.transfer_id) == (42, 100, 9)
    decoded = response.payload      # pydronecan checked the transfer CRC and decoded the DSDL response
    assert bytes(decoded.name).decode() == "org.test.imu"
    assert (decoded.software_version.major, decoded.software_version.minor) == (3, 7)
    assert decoded.status.mode == 0 and decoded.status.health == 0
    assert len(bytes(decoded.hardware_version.unique_id)) == 16
    assert device.stats.commands == 1 and device.stats.ignored_bytes > 0
