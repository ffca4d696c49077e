"""The MicroStrain MIP device end to end: MicroStrain's own MSCL (pymscl) configures it over a pty from another
process; raw MIP commands (built here, Fletcher-16 computed here) cover NACKs and the filter / GNSS sets
ArduPilot's MicroStrain drivers need."""
import json
import os
import struct
import subprocess
import sys

import numpy as np
import pytest

from tests.support.stream import Emulator, read_for, reference, write_scene
from tests.support.paths import CLIENTS
from tests.support.timing import scaled

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

G = 9.80665


def test_mscl_pings_idles_reads_info_sets_format_and_gets_exactly_that(tmp_path):
    pytest.importorskip("mscl")
    rate, wanted = 200, 50
    scene_path = write_scene(tmp_path, rate=rate, duration=60.0)
    scene, _, accel, gyro = reference(scene_path)
    with Emulator(scene_path, "--format", "microstrain-mip", "--to", "pty", "--duration", "40") as emu:
        client = subprocess.run([sys.executable, str(CLIENTS / "mscl_client.py"),
                                 emu.targets[0], str(wanted), "1.0"], capture_output=True, text=True, timeout=scaled(120))
        code, err = emu.interrupt()
    assert code == 0, err
    assert client.returncode == 0, client.stderr
    result = json.loads(client.stdout.strip().splitlines()[-1])
    packets = result.pop("packets")
    assert result["ping"] is True and result["idle"] == "ok"
    assert (result["model_name"], result["model_number"], result["serial"]) == ("3DM-GQ7", "6284-4220", "6284.12345")
    assert result["base_rate"] == rate
    assert result["set_format"] == result["enable"] == result["resume"] == "ok"
    # MSCL's channel fields: 0x8004 scaled accel, 0x8005 scaled gyro, at the rate asked for
    assert result["read_format"] == [[0x8004, float(wanted)], [0x8005, float(wanted)]]
    assert 40 <= len(packets) <= 60
    for p in packets:
        assert p["set"] == 0x80
        assert p["channels"] == sorted(f"scaled{q}{a}" for q in ("Accel", "Gyro") for a in "XYZ")
    # every 4th sample of the scene (200 Hz / 50 Hz), in g, float32
    got = np.array([p["accel"] for p in packets], dtype=np.float32)
    want = (accel / G).astype(np.float32)
    # (the scene's body-frame accel repeats almost exactly: look for a start at which the whole run matches)
    assert any(np.array_equal(got, want[k0:k0 + 4 * len(got):4]) for k0 in range(len(want) - 4 * len(got)))
    assert "device: " in err and "0 error replies" in err


def mip(descriptor_set: int, fields: list) -> bytes:
    payload = b"".join(bytes([2 + len(data), desc]) + data for desc, data in fields)
    body = bytes([0x75, 0x65, descriptor_set, len(payload)]) + payload
    a = b = 0
    for byte in body:
        a = (a + byte) & 0xFF
        b = (b + a) & 0xFF
    return body + bytes([a, b])


def packets(data: bytes) -> list:
    """(set, [(descriptor, data)]) of every valid MIP packet."""
    out, pos = [], 0
    while True:
        pos = data.find(b"\x75\x65", pos)
        if pos < 0 or pos + 4 > len(data):
            return out
        total = 4 + data[pos + 3] + 2
        frame = data[pos:pos + total]
        if len(frame) == total and _valid(frame):
            fields, k = [], 4
            while k < total - 2:
                fields.append((frame[k + 1], frame[k + 2:k + frame[k]]))
                k += frame[k]
            out.append((frame[2], fields))
            pos += total
        else:
            pos += 1


def _valid(frame: bytes) -> bool:
    a = b = 0
    for byte in frame[:-2]:
        a = (a + byte) & 0xFF
        b = (b + a) & 0xFF
    return bytes([a, b]) == frame[-2:]


def test_nacks_and_the_filter_and_gnss_sets_ardupilot_needs(tmp_path):
    scene_path = write_scene(tmp_path, rate=100, duration=60.0)
    with Emulator(scene_path, "--format", "microstrain-mip", "--to", "pty", "--duration", "40") as emu:
        fd = os.open(emu.targets[0], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        assert read_for(fd, 30, stop_after=1)

        def ask(raw: bytes, seconds=0.5) -> list:
            os.write(fd, raw)
            return [p for p in packets(read_for(fd, seconds)) if p[0] in (0x01, 0x0C)]

        assert ask(mip(0x01, [(0x02, b"")])) == [(0x01, [(0xF1, bytes([0x02, 0]))])]          # idle
        assert ask(mip(0x01, [(0x55, b"")])) == [(0x01, [(0xF1, bytes([0x55, 1]))])]          # unknown
        bad = mip(0x01, [(0x01, b"")])
        assert ask(bad[:-1] + bytes([bad[-1] ^ 0xFF])) == [(0x01, [(0xF1, bytes([0x01, 2]))])]   # checksum
        # message format 0x0F for a set that has no field 0x77: invalid parameter
        assert ask(mip(0x0C, [(0x0F, bytes([1, 0x82, 1, 0x77, 0, 1]))])) == [(0x0C, [(0xF1, bytes([0x0F, 3]))])]
        # filter: status, quaternion, LLH, NED velocity, GPS time every 10th sample; GNSS: fix, LLH, velocity
        filter_fields = b"".join(bytes([d, 0, 10]) for d in (0x10, 0x03, 0x01, 0x02, 0xD3))
        gnss_fields = b"".join(bytes([d, 0, 20]) for d in (0x0B, 0x03, 0x05))
        assert ask(mip(0x0C, [(0x0F, bytes([1, 0x82, 5]) + filter_fields)]))[0][1] == [(0xF1, bytes([0x0F, 0]))]
        assert ask(mip(0x0C, [(0x0F, bytes([1, 0x81, 3]) + gnss_fields)]))[0][1] == [(0xF1, bytes([0x0F, 0]))]
        # read back
        assert ask(mip(0x0C, [(0x0F, bytes([2, 0x81]))]))[0][1] == [(0xF1, bytes([0x0F, 0])),
                                                                   (0x8F, bytes([0x81, 3]) + gnss_fields)]
        # only the filter and GNSS streams: switch the IMU stream off, resume
        assert ask(mip(0x0C, [(0x11, bytes([1, 0x80, 0]))]))[0][1] == [(0xF1, bytes([0x11, 0]))]
        assert ask(mip(0x01, [(0x06, b"")])) == [(0x01, [(0xF1, bytes([0x06, 0]))])]
        data = read_for(fd, 1.0)
        os.close(fd)
        code, err = emu.interrupt()
    assert code == 0, err
    streamed = packets(data)
    assert {s for s, _ in streamed} == {0x81, 0x82}
    filt = [f for s, f in streamed if s == 0x82]
    gnss = [f for s, f in streamed if s == 0x81]
    assert 8 <= len(filt) <= 12 and 4 <= len(gnss) <= 6        # 100 Hz / 10 and / 20 for about 1 s
    for fields in filt:
        assert [d for d, _ in fields] == [0x10, 0x03, 0x01, 0x02, 0xD3]
        state, dynamics, flags = struct.unpack(">3H", fields[0][1])
        assert state == 4                                        # full navigation
        lat, lon, height, valid = struct.unpack(">3dH", fields[2][1])
        assert abs(lat - 47.397742) < 1e-4 and abs(lon - 8.545594) < 1e-4 and valid == 1
    for fields in gnss:
        assert [d for d, _ in fields] == [0x0B, 0x03, 0x05]
        fix_type, num_sv, fix_flags, valid = struct.unpack(">BBHH", fields[0][1])
        assert fix_type == 0 and num_sv > 5                     # 3D fix
        north, east, down, speed, ground, heading = struct.unpack_from(">6f", fields[2][1])
        assert abs(ground - np.hypot(north, east)) < 1e-4
        assert abs(speed - np.linalg.norm([north, east, down])) < 1e-4


def test_presets_configure_the_sets_and_say_when_the_scene_is_too_slow():
    """The device as a driver would read its configuration back (message format, 0x0C 0x0F function 2): the preset's
    fields at the decimation that gives at least the preset's rate; bad preset options are refused by name."""
    from firmware_protocols.devices.microstrain import MipDevice
    device = MipDevice(200, preset="ardupilot")
    assert device.notes == []

    def read_format(descriptor_set: int) -> list:
        (reply_set, fields), = packets(b"".join(device.receive(mip(0x0C, [(0x0F, bytes([2, descriptor_set]))]))))
        assert reply_set == 0x0C and fields[0] == (0xF1, bytes([0x0F, 0]))
        data = fields[1][1]
        assert fields[1][0] == 0x8F and data[0] == descriptor_set
        return [struct.unpack_from(">BH", data, 2 + 3 * j) for j in range(data[1])]

    # 200 Hz scene: IMU and filter every 4th sample (50 Hz), each GNSS receiver every 100th (2 Hz)
    assert read_format(0x80) == [(0x04, 4), (0x05, 4), (0x06, 4), (0x17, 4)]
    assert read_format(0x91) == read_format(0x92) == [(0xD3, 100), (0x0B, 100), (0x03, 100), (0x05, 100), (0x07, 100)]
    assert read_format(0x82) == [(d, 4) for d in (0xD3, 0x10, 0x01, 0x02, 0x03, 0x08, 0x09)]
    assert read_format(0x81) == []
    info = b"".join(device.receive(mip(0x01, [(0x03, b"")])))
    assert b"3DM-GQ7" in info
    gx5 = MipDevice(100, preset="ardupilot-gx5")
    assert b"3DM-GX5-45" in b"".join(gx5.receive(mip(0x01, [(0x03, b"")])))
    slow = MipDevice(20, preset="ardupilot")
    assert any("0x80 wants 50 Hz" in note and "20 Hz" in note for note in slow.notes)
    with pytest.raises(ValueError, match="preset: unknown 'px4'.*ardupilot, ardupilot-gx5"):
        MipDevice(100, preset="px4")
    with pytest.raises(ValueError, match="preset and fields"):
        MipDevice(100, preset="ardupilot", fields="accel")
    # an option the user names wins over the preset's
    named = MipDevice(100, preset="ardupilot", model_name="3DM-GQ7-GNSS/INS")
    assert b"3DM-GQ7-GNSS/INS" in b"".join(named.receive(mip(0x01, [(0x03, b"")])))


def test_a_preset_device_takes_garbage_and_damaged_commands_and_keeps_every_set_streaming():
    """Random bytes and valid MIP commands with random bytes flipped, interleaved with output, never raise; the
    GNSS and filter sets (fed NaN-free samples without navigation fields: their documented defaults) keep going."""
    from firmware_protocols import Samples
    from firmware_protocols.devices.microstrain import MipDevice
    rng = np.random.default_rng(24)
    device = MipDevice(100, preset="ardupilot")
    n = 400
    samples = Samples(np.arange(n, dtype=np.int64) * 10_000_000, np.tile([0.0, 0.0, -G], (n, 1)), np.zeros((n, 3)))
    # reads and pings only, so the preset's configuration stands (a damaged copy fails Fletcher-16 but by chance)
    valid = [mip(0x0C, [(0x0F, bytes([2, s]))]) for s in (0x80, 0x82, 0x91, 0x92)] + [mip(0x01, [(0x01, b"")])]
    out = bytearray()
    for i in range(n):
        command = bytearray(valid[rng.integers(len(valid))])
        for _ in range(rng.integers(0, 3)):
            command[rng.integers(len(command))] = rng.integers(256)
        noise = rng.integers(0, 256, rng.integers(0, 40), dtype=np.uint8).tobytes()
        for reply in device.receive(noise + bytes(command)):
            assert isinstance(reply, bytes)
        out += device.output(samples, i)
    sets = [s for s, _ in packets(bytes(out))]
    assert {0x80, 0x82, 0x91, 0x92} <= set(sets)
    assert device.stats.errors > 0 and device.stats.commands > 0
