"""The J1939 device end to end over python-can's udp_multicast bus (CAN frames between processes on the
host): the emulator in its own process, `can-j1939` (PyPI) controller applications in this one, and a plain
python-can bus beside them that sees every frame."""
import time

import can
import pytest

from tests.live.test_stream_can import _multicast_route_or_skip, free_udp_port
from tests.support.stream import Emulator, write_scene
from tests.support.timing import scaled

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

j1939 = pytest.importorskip("j1939")

GROUP = "239.74.163.7"
OUR_NAME = 0x00000000ABCD1234
ADDRESS = 0x90
PGN_ARI, PGN_ACCS, PGN_CLAIM, PGN_ACK = 61482, 61485, 60928, 59392


def _frames(bus, seconds):
    out, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        message = bus.recv(timeout=0.1)
        if message is not None:
            out.append((time.monotonic(), message.arbitration_id, bytes(message.data)))
    return out


def _pgn(can_id):
    pgn = (can_id >> 8) & 0x3FFFF
    return pgn & 0x3FF00 if (pgn >> 8) & 0xFF < 240 else pgn


def test_address_claim_requests_nack_and_a_lost_contention(tmp_path):
    _multicast_route_or_skip()
    scene_path = write_scene(tmp_path, rate=50, duration=60.0)
    port = free_udp_port()
    bus = can.Bus(interface="udp_multicast", channel=GROUP, port=port)
    ecu = j1939.ElectronicControlUnit()
    ecu.connect(interface="udp_multicast", channel=GROUP, port=port)
    try:
        with Emulator(scene_path, "--format", "j1939", "--to", f"can:udp_multicast:{GROUP}:{port}", "--duration", "40",
                      "--option", f"ecu_name={OUR_NAME}") as emu:
            first = bus.recv(timeout=scaled(30))          # the stream runs (start-up may take seconds under load)
            assert first is not None
            start = [(time.monotonic(), first.arbitration_id, bytes(first.data))] + _frames(bus, 2.0)
            # a tool with its own address asks, globally, who is there, then for an unknown PGN at 0x90
            tool = j1939.ControllerApplication(j1939.Name(value=0x2000), 0x20)
            ecu.add_ca(controller_application=tool)
            tool.start()
            end = time.monotonic() + scaled(5)
            while tool.state != j1939.ControllerApplication.State.NORMAL and time.monotonic() < end:
                time.sleep(0.05)
            tool.send_request(0, PGN_CLAIM, 0xFF)
            tool.send_request(0, 0xFEE6, ADDRESS)           # time/date: not ours
            answers = _frames(bus, 1.0)
            # a controller application with a lower NAME claims 0x90: the emulator must give way
            rival = j1939.ControllerApplication(j1939.Name(value=0x10), ADDRESS)
            ecu.add_ca(controller_application=rival)
            rival.start()
            after = _frames(bus, 2.0)
            code, err = emu.interrupt()
    finally:
        ecu.disconnect()
        bus.shutdown()
    assert code == 0, err
    claims = [(t, i & 0xFF, d) for t, i, d in start if _pgn(i) == PGN_CLAIM]
    assert claims and claims[0][1] == ADDRESS and int.from_bytes(claims[0][2], "little") == OUR_NAME
    data = [(t, i) for t, i, d in start if _pgn(i) in (PGN_ARI, PGN_ACCS) and i & 0xFF == ADDRESS]
    assert data and data[0][0] >= claims[0][0]              # no data before the claim
    ours = [d for t, i, d in answers if _pgn(i) == PGN_CLAIM and i & 0xFF == ADDRESS]
    assert OUR_NAME.to_bytes(8, "little") in ours, "the global Request for address claim was not answered"
    nacks = [d for t, i, d in answers if _pgn(i) == PGN_ACK and i & 0xFF == ADDRESS]
    assert nacks and nacks[0][0] == 1 and nacks[0][4] == 0x20 and int.from_bytes(nacks[0][5:8], "little") == 0xFEE6
    cannot = [(t, d) for t, i, d in after if _pgn(i) == PGN_CLAIM and i & 0xFF == 0xFE]
    assert cannot and int.from_bytes(cannot[0][1], "little") == OUR_NAME
    late = [t for t, i, d in after if _pgn(i) in (PGN_ARI, PGN_ACCS) and i & 0xFF == ADDRESS and t > cannot[0][0] + 0.2]
    assert not late, "data kept coming after the address was lost"
    assert "lost to NAME" in err


def test_request_for_an_imu_pgn_is_answered_with_its_latest_values():
    import firmware_protocols
    from firmware_protocols import Samples
    from firmware_protocols.base import frame_bytes
    device = firmware_protocols.create_device("j1939", 100.0)
    samples = Samples([0, 10_000_000], [[0.1, -0.2, 9.80665]] * 2, [[0.01, -0.02, 0.03]] * 2)
    streamed = [device.output(samples, i) for i in range(2)]
    # (inside the 250 ms after the claim nothing but the claim is streamed, yet a Request is answered)
    assert [len(s) for s in streamed] == [1, 0]
    # Request (PGN 59904) from 0x20 to 0x90 for ARI: data = requested PGN, 3 bytes little-endian
    request = can.Message(arbitration_id=(6 << 26) | (0xEA << 16) | (ADDRESS << 8) | 0x20,
                          data=PGN_ARI.to_bytes(3, "little"), is_extended_id=True)
    (reply,) = device.receive([request])
    # the spec's ARI vector for this sample (wire-formats.md): id 0x0CF02A90, data 6d7c497ddc7dc005
    assert [(int(r["can_id"]), frame_bytes(r).hex()) for r in reply] == [(0x0CF02A90, "6d7c497ddc7dc005")]
