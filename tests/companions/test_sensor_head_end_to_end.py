"""The sensor head end to end (issue 24): examples/companions.toml, cut to a few seconds, is generated to NPZ (its
columns are the reference: the truth plus the named errors, as the companion sensors compute them) and streamed
with `--speed 0` to capture files in every format that carries the companions' fields. Each capture is decoded
with an oracle - pymavlink, pydronecan, decoders written here from the vendors' layouts (MicroStrain MIP DCP /
mip_sdk data_gnss.h, VectorNav ICD binary output, Xsens MT Low-Level Communication Protocol through the transcription
of ArduPilot's parser in test_xsens.py) - and every new field must equal the NPZ column, turned into the wire's axes
and units, at the wire's resolution; GNSS messages only where the receiver had a new solution (gnss_new)."""
import calendar
import math
import re
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from dronecan.transport import Frame, Transfer
from pymavlink.dialects.v20 import common as mavlink2

from tests.firmware_protocols.wire_formats.test_xsens import ap_parse_mtdata2
from tests.support.paths import REPO
from tests.support.timing import scaled

pytestmark = [pytest.mark.subprocess, pytest.mark.streams]

ROOT = REPO
RATE = 200.0
LATENCY_US = 50_000      # examples/companions.toml [imu.gnss] latency_s
# `stream`'s default --start-time (README conventions: 2024-01-01T00:00:00Z): UTC fields count from it
START_NS = calendar.timegm((2024, 1, 1, 0, 0, 0)) * 10**9

# Capture files: (name, [[stream]] format, options as TOML, file suffix)
STREAMS = (
    ("hil_sensor", "mavlink-hil-sensor", "{}", "bin"),
    ("hil_gps", "mavlink-hil-gps", "{}", "bin"),
    ("scaled_pressure", "mavlink-scaled-pressure", "{}", "bin"),
    ("dronecan", "dronecan-gnss-compass-baro", "{ node_id = 42 }", "log"),
    ("mip_sensor", "microstrain-mip", "{ fields = 'mag,pressure' }", "bin"),
    ("mip_gnss", "microstrain-mip", "{ descriptor_set = 0x91, fields = 'fix_info,position_llh,velocity_ned,dop' }",
     "bin"),
    ("mip_filter", "microstrain-mip", "{ descriptor_set = 0x82, fields = 'position_llh,velocity_ned,quaternion,euler,"
     "position_uncertainty,velocity_uncertainty,euler_uncertainty,status' }", "bin"),
    ("vectornav", "vectornav-binary", "{ fields = 'imu:pres,mag;gps:fix,poslla,velned' }", "bin"),
    ("vectornav_ins", "vectornav-binary", "{ fields = 'common:yawpitchroll,quaternion,position,velocity,insstatus;"
     "gps:numsats,posu,velu,dop;attitude:ypru;ins:posu,velu' }", "bin"),
    ("xsens", "xsens-mtdata2", "{ items = 'magnetic_field,baro_pressure,gnss_pvt_data' }", "bin"),
    ("xsens_ins", "xsens-mtdata2", "{ items = 'quaternion,euler_angles,lat_lon,altitude_ellipsoid,velocity_xyz', "
     "precision = 'float64', frame = 'NED' }", "bin"),
)


def cli(*args):
    done = subprocess.run([sys.executable, "-m", "imu_emulator.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=ROOT, timeout=scaled(600))
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout + done.stderr


def scene_text(out: Path) -> str:
    """examples/companions.toml, 3 s long with its GNSS outage moved inside (1.0 to 1.5 s), streaming to files."""
    text = (ROOT / "examples" / "companions.toml").read_text()
    text = re.sub(r"duration_s = [0-9.]+", "duration_s = 3.0", text)
    text = re.sub(r"outages_s = .*", "outages_s = [[1.0, 1.5]]", text)
    assert "duration_s = 3.0" in text and "outages_s = [[1.0, 1.5]]" in text
    for name, fmt, options, suffix in STREAMS:
        text += (f'\n[[stream]]\nimu = "imu0"\nformat = "{fmt}"\nto = "file:{out / name}.{suffix}"\n'
                 f"options = {options}\n")
    return text


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("head")
    scene = out / "scene.toml"
    scene.write_text(scene_text(out))
    cli("generate", scene, "-o", out / "reference.npz", "--quiet")
    cli("stream", scene, "--speed", "0", "--quiet")
    with np.load(out / "reference.npz") as z:
        ref = {k: z[k] for k in z.files}
    ref = {k: (v[0] if v.ndim >= 2 and k not in ("conventions", "units") else v) for k, v in ref.items()}
    assert len(ref["t"]) == 600 and np.isclose(np.diff(ref["t"]), 1 / RATE).all()
    return out, ref


def test_the_reference_file_states_each_companion_array_s_units(run):
    """The NPZ's "units" line of each array names that array's own units (the GNSS keys are 3, 3, 1, 1 wide)."""
    _, ref = run
    lines = {line.split(":")[0]: line for line in ref["units"]}
    assert lines["mag"].startswith("mag: gauss (")
    assert lines["pressure_pa"].startswith("pressure_pa: Pa (") and "degC" in lines["baro_temperature_c"]
    assert lines["gnss_llh"].startswith("gnss_llh: deg, m (GNSS antenna latitude")
    assert lines["gnss_velocity_ned"].startswith("gnss_velocity_ned: m/s (GNSS velocity north")
    assert lines["gnss_fix"].startswith("gnss_fix:  (fix type") and lines["gnss_new"].startswith("gnss_new:  (1 ")
    assert lines["differential_pressure_pa"].startswith("differential_pressure_pa: Pa (pitot")
    assert lines["gnss_satellites"].startswith("gnss_satellites:  (satellites used")
    assert lines["gnss_horizontal_accuracy_m"].startswith("gnss_horizontal_accuracy_m: m (1-sigma horizontal")
    assert lines["ins_quat"].startswith("ins_quat:  (estimated attitude quaternion")
    assert lines["ins_euler"].startswith("ins_euler: rad (estimated roll")
    assert lines["ins_llh"].startswith("ins_llh: deg, m (estimated latitude")
    assert lines["ins_attitude_sigma_rad"].startswith("ins_attitude_sigma_rad: rad (stated 1-sigma roll")
    assert lines["ins_mode"].startswith("ins_mode:  (filter mode")


def new_solutions(ref) -> np.ndarray:
    new = np.flatnonzero(ref["gnss_new"] != 0)
    # 5 Hz receiver over 3 s, every solution reported (those in the outage without a fix)
    assert len(new) == 15 and (ref["gnss_fix"][new] == 0).sum() >= 2 and (ref["gnss_fix"][new] == 3).sum() >= 10
    return new


def f32(values):
    return np.asarray(values, dtype=np.float32).astype(np.float64)


def mavlink(path: Path):
    data = path.read_bytes()
    messages = mavlink2.MAVLink(None).parse_buffer(data) or []
    assert messages and all(m.get_type() != "BAD_DATA" for m in messages)
    return messages


def test_mavlink_hil_sensor_mag_and_baro(run):
    out, ref = run
    sensors = mavlink(out / "hil_sensor.bin")
    assert len(sensors) == 600 and {m.get_type() for m in sensors} == {"HIL_SENSOR"}
    assert [m.time_usec for m in sensors] == [round(t * 1e6) for t in ref["t"]]
    # gauss in FRD (the scene is NED: its sensor axes are the part's FRD), float32
    mag = np.array([(m.xmag, m.ymag, m.zmag) for m in sensors])
    assert np.array_equal(mag, f32(ref["mag"]))
    assert np.array_equal([m.abs_pressure for m in sensors], f32(ref["pressure_pa"] / 100))         # hPa
    assert np.array_equal([m.temperature for m in sensors], f32(ref["baro_temperature_c"]))
    assert np.array_equal([m.diff_pressure for m in sensors], f32(ref["differential_pressure_pa"] / 100))    # hPa
    # fields_updated: the magnetometer's bits (6-8) exactly at its new readings (100 Hz), the barometer's (9, 11,
    # 12) at its own (50 Hz), from the scene's rates with no stream option: where the reference column takes a new
    # value (noise makes every reading differ), which is where its mag_new / baro_new columns say so
    updated = np.array([m.fields_updated for m in sensors])
    new_mag = np.r_[True, (np.diff(ref["mag"], axis=0) != 0).any(axis=1)]
    new_baro = np.r_[True, np.diff(ref["pressure_pa"]) != 0]
    assert new_mag.sum() == 300 and new_baro.sum() == 150
    assert np.array_equal(ref["mag_new"] != 0, new_mag) and np.array_equal(ref["baro_new"] != 0, new_baro)
    assert np.array_equal(updated & 0x1C0 == 0x1C0, new_mag) and not (updated & 0x1C0 & ~(0x1C0 * new_mag)).any()
    assert np.array_equal(updated & 0x1A00 == 0x1A00, new_baro)


def test_mavlink_hil_gps_on_each_new_solution(run):
    out, ref = run
    new = new_solutions(ref)
    fixes = mavlink(out / "hil_gps.bin")
    assert len(fixes) == len(new)
    for k, m in zip(new, fixes):
        lat, lon, h = ref["gnss_llh"][k]
        vn, ve, vd = ref["gnss_velocity_ned"][k]
        # the fix's time of validity: the sample it arrived at less the receiver's latency_s (50 ms)
        assert m.time_usec == START_NS // 1000 + round(ref["t"][k] * 1e6) - LATENCY_US     # UTC, time of validity
        assert (m.lat, m.lon, m.alt) == (round(lat * 1e7), round(lon * 1e7), round(h * 1e3))     # 1e-7 deg, mm
        assert (m.vn, m.ve, m.vd) == (round(vn * 100), round(ve * 100), round(vd * 100))       # cm/s
        assert m.vel == round(math.hypot(vn, ve) * 100)
        assert m.fix_type == (3 if ref["gnss_fix"][k] == 3 else 1)      # GPS_FIX_TYPE 3D_FIX, else NO_FIX
        # cm, the 1-sigma accuracies as PX4 reads them (mavlink_nav's docstring); satellites used
        assert (m.eph, m.epv) == (round(ref["gnss_horizontal_accuracy_m"][k] * 100),
                                  round(ref["gnss_vertical_accuracy_m"][k] * 100))
        assert m.satellites_visible == ref["gnss_satellites"][k]
    # the columns carry the receiver's figures: with a fix the scene's, without one none
    fixed = ref["gnss_fix"][new] == 3
    assert (ref["gnss_satellites"][new][fixed] == 12).all() and (ref["gnss_satellites"][new][~fixed] == 0).all()


def test_mavlink_scaled_pressure_at_the_barometer_rate(run):
    out, ref = run
    readings = mavlink(out / "scaled_pressure.bin")
    k = np.arange(0, 600, 4)                                  # 50 Hz of 200 Hz
    assert len(readings) == len(k)
    assert [m.time_boot_ms for m in readings] == [round(ref["t"][i] * 1e3) for i in k]
    assert np.array_equal([m.press_abs for m in readings], f32(ref["pressure_pa"][k] / 100))
    assert [m.temperature for m in readings] == [round(c * 100) for c in ref["baro_temperature_c"][k]]   # cdegC


def candump_transfers(path: Path):
    """(time s, pydronecan Transfer) of a candump log, multi-frame transfers reassembled and CRC-checked by
    pydronecan; the tail byte's end-of-transfer bit (0x40) closes one."""
    out, pending = [], {}
    for line in path.read_text().splitlines():
        stamp, _, frame = line.split()[:3]
        can_id, data = frame.split("#")
        data = bytes.fromhex(data)
        pending.setdefault(can_id, []).append(Frame(int(can_id, 16), bytearray(data)))
        if data[-1] & 0x40:
            transfer = Transfer()
            transfer.from_frames(pending.pop(can_id))
            out.append((float(stamp.strip("()")), transfer))
    assert not pending
    return out


def test_dronecan_node_compass_baro_and_fix2(run):
    out, ref = run
    by_kind = {}
    for stamp, transfer in candump_transfers(out / "dronecan.log"):
        assert transfer.source_node_id == 42
        by_kind.setdefault(transfer.payload._type.full_name, []).append((round((stamp - START_NS / 1e9) * RATE),
                                                                         transfer.payload))
    eq = "uavcan.equipment."
    assert set(by_kind) == {eq + "ahrs.MagneticFieldStrength2", eq + "air_data.StaticPressure",
                            eq + "air_data.StaticTemperature", eq + "gnss.Fix2"}
    compass = by_kind[eq + "ahrs.MagneticFieldStrength2"]
    assert [k for k, _ in compass] == list(range(0, 600, 2))
    for k, msg in compass:      # float16 gauss, FRD
        want = np.asarray(ref["mag"][k], dtype=np.float16).astype(float)
        assert list(msg.magnetic_field_ga) == list(want)
    pressure = by_kind[eq + "air_data.StaticPressure"]
    assert [k for k, _ in pressure] == list(range(0, 600, 4))
    for k, msg in pressure:
        assert msg.static_pressure == float(np.float32(ref["pressure_pa"][k]))                  # Pa, float32
    for k, msg in by_kind[eq + "air_data.StaticTemperature"]:
        assert msg.static_temperature == float(np.float16(ref["baro_temperature_c"][k] + 273.15))  # K, float16
    fixes = by_kind[eq + "gnss.Fix2"]
    new = new_solutions(ref)
    assert [k for k, _ in fixes] == list(new)
    for k, msg in fixes:
        lat, lon, h = ref["gnss_llh"][k]
        assert (msg.latitude_deg_1e8, msg.longitude_deg_1e8) == (round(lat * 1e8), round(lon * 1e8))
        assert msg.height_ellipsoid_mm == round(h * 1e3)
        assert list(msg.ned_velocity) == list(f32(ref["gnss_velocity_ned"][k]))
        # STATUS_3D_FIX 3 or STATUS_NO_FIX 0 (uavcan.equipment.gnss.Fix2)
        assert msg.status == (3 if ref["gnss_fix"][k] == 3 else 0)
        assert msg.sats_used == ref["gnss_satellites"][k]
        # float16 PDOP = hypot(HDOP, VDOP); covariance diag h^2, h^2, v^2, s^2 x 3 (dronecan_sensors' docstring)
        assert msg.pdop == float(np.float16(math.hypot(ref["gnss_hdop"][k], ref["gnss_vdop"][k])))
        h, v, s = (ref[key][k] for key in ("gnss_horizontal_accuracy_m", "gnss_vertical_accuracy_m",
                                           "gnss_speed_accuracy_mps"))
        assert list(msg.covariance) == [float(np.float16(x)) for x in (h * h, h * h, v * v, s * s, s * s, s * s)]


def mip_packets(data: bytes, descriptor_set: int):
    """{descriptor: field data} of each MIP packet, framing and Fletcher-16 checked as the DCP manual says."""
    packets, pos = [], 0
    while pos < len(data):
        assert data[pos:pos + 2] == b"\x75\x65" and data[pos + 2] == descriptor_set
        end = pos + 4 + data[pos + 3] + 2
        packet, a, b = data[pos:end], 0, 0
        for byte in packet[:-2]:
            a, b = (a + byte) % 256, (b + (a + byte) % 256) % 256
        assert (a, b) == tuple(packet[-2:])
        fields, k, payload = {}, 0, packet[4:-2]
        while k < len(payload):
            fields[payload[k + 1]] = payload[k + 2:k + payload[k]]
            k += payload[k]
        packets.append(fields)
        pos = end
    return packets


def test_microstrain_sensor_set_mag_and_pressure(run):
    out, ref = run
    packets = mip_packets((out / "mip_sensor.bin").read_bytes(), 0x80)
    assert len(packets) == 600
    mag = np.array([struct.unpack(">3f", p[0x06]) for p in packets])            # scaled mag, gauss, FRD
    assert np.array_equal(mag, f32(ref["mag"]))
    pressure = np.array([struct.unpack(">f", p[0x17])[0] for p in packets])   # scaled ambient pressure, mbar
    assert np.array_equal(pressure, f32(ref["pressure_pa"] / 100))


def test_microstrain_gnss_set_on_each_new_solution(run):
    out, ref = run
    new = new_solutions(ref)
    packets = mip_packets((out / "mip_gnss.bin").read_bytes(), 0x91)
    assert len(packets) == len(new)                                # one per solution, none repeated
    for k, p in zip(new, packets):
        lat, lon, h_ell, h_msl, h_acc, v_acc, valid = struct.unpack(">4d2fH", p[0x03])
        assert (lat, lon, h_ell) == tuple(ref["gnss_llh"][k])
        vel = struct.unpack(">8fH", p[0x05])
        assert list(vel[:3]) == list(f32(ref["gnss_velocity_ned"][k]))
        assert (h_acc, v_acc) == (np.float32(ref["gnss_horizontal_accuracy_m"][k]),
                                  np.float32(ref["gnss_vertical_accuracy_m"][k]))
        fix_type, satellites, _flags, _valid = struct.unpack(">BBHH", p[0x0B])
        # mip_sdk data_gnss.h FixInfo: 0 3D, 3 none
        assert fix_type == (0 if ref["gnss_fix"][k] == 3 else 3)
        assert satellites == ref["gnss_satellites"][k]
        # data_gnss.h DopData: gdop, pdop, hdop, vdop, tdop, ndop, edop, valid flags
        gdop, pdop, hdop, vdop, *_ = struct.unpack(">7fH", p[0x07])
        assert (hdop, vdop) == (np.float32(ref["gnss_hdop"][k]), np.float32(ref["gnss_vdop"][k]))
        assert pdop == np.float32(math.hypot(ref["gnss_hdop"][k], ref["gnss_vdop"][k]))
        assert (valid != 0) == (ref["gnss_fix"][k] == 3)


def canonical(q) -> np.ndarray:
    """q and -q are one attitude: the sign with w >= 0 (the columns' convention), to compare quaternions."""
    q = np.asarray(q, dtype=float)
    return q * (-1.0 if q[0] < 0 else 1.0)


def test_microstrain_filter_set_carries_the_ins_estimate(run):
    """Set 0x82 (mip_sdk data_filter.h): position LLH f64, velocity NED, quaternion (w, x, y, z, vehicle -> NED),
    Euler roll, pitch, yaw (rad), their 1-sigma uncertainties (f32), each with a u16 valid flag; filter status
    (GQ7 states: 1 init, 4 full nav) from ins_mode."""
    out, ref = run
    packets = mip_packets((out / "mip_filter.bin").read_bytes(), 0x82)
    assert len(packets) == 600
    for k, p in enumerate(packets):
        mode = int(ref["ins_mode"][k])
        *llh, valid = struct.unpack(">3dH", p[0x01])
        assert tuple(llh) == tuple(ref["ins_llh"][k]) and valid == (mode == 2)
        assert list(struct.unpack(">3fH", p[0x02])[:3]) == list(f32(ref["ins_velocity_ned"][k]))
        quat = canonical(struct.unpack(">4fH", p[0x03])[:4])
        np.testing.assert_allclose(quat, ref["ins_quat"][k], rtol=0, atol=6e-8)       # f32: half an ulp of 1
        euler = struct.unpack(">3fH", p[0x05])[:3]
        np.testing.assert_allclose(euler, ref["ins_euler"][k], rtol=1.2e-7, atol=1e-12)
        for descriptor, key in ((0x08, "ins_position_sigma_m"), (0x09, "ins_velocity_sigma_mps"),
                                (0x0A, "ins_attitude_sigma_rad")):
            assert list(struct.unpack(">3fH", p[descriptor])[:3]) == list(f32(ref[key][k])), key
        state, _dynamics, _flags = struct.unpack(">3H", p[0x10])
        assert state == {1: 1, 2: 4}[mode]


def test_vectornav_ins_attitude_and_gnss_quality(run):
    """VectorNav ICD binary output: common YawPitchRoll (deg, f32), Quaternion (x, y, z, w), Position (f64 deg, deg,
    m), Velocity (f32 NED), InsStatus (bits 0-1 mode, bit 2 GNSS fix); GPS NumSats, PosU (N, E, D m), VelU, Dop (g,
    p, t, v, h, n, e); attitude YprU (deg, yaw, pitch, roll); INS PosU, VelU (root sum of squares of the sigmas)."""
    out, ref = run
    payloads = vectornav_packets((out / "vectornav_ins.bin").read_bytes(), {0: 0x10D8, 3: 0x0608 | 0x2000,
                                                                            4: 0x0100, 5: 0x0600})
    assert len(payloads) == 600
    for k, payload in enumerate(payloads):
        values = struct.unpack("<3f4f3d3fH" "B3ff7f" "3f" "2f", payload)
        ypr, xyzw, lla, vel, status = values[0:3], values[3:7], values[7:10], values[10:13], values[13]
        sats, gnss_pos_u, gnss_vel_u, dop = values[14], values[15:18], values[18], values[19:26]
        ypr_u, pos_u, vel_u = values[26:29], values[29], values[30]
        roll, pitch, yaw = ref["ins_euler"][k]
        np.testing.assert_allclose(ypr, np.degrees([yaw, pitch, roll]), rtol=1.2e-7, atol=1e-9)
        np.testing.assert_allclose(canonical(np.roll(xyzw, 1)), ref["ins_quat"][k], rtol=0, atol=6e-8)
        assert lla == tuple(ref["ins_llh"][k]) and list(vel) == list(f32(ref["ins_velocity_ned"][k]))
        fix = ref["gnss_fix"][k] == 3
        assert status == int(ref["ins_mode"][k]) | (4 if fix else 0)
        assert sats == ref["gnss_satellites"][k]
        h, v = ref["gnss_horizontal_accuracy_m"][k], ref["gnss_vertical_accuracy_m"][k]
        assert list(gnss_pos_u) == list(f32([h, h, v])) and gnss_vel_u == np.float32(ref["gnss_speed_accuracy_mps"][k])
        assert (dop[3], dop[4]) == (np.float32(ref["gnss_vdop"][k]), np.float32(ref["gnss_hdop"][k]))
        sigma = ref["ins_attitude_sigma_rad"][k]
        assert list(ypr_u) == list(f32(np.degrees(sigma[::-1])))
        assert pos_u == np.float32(np.linalg.norm(ref["ins_position_sigma_m"][k]))
        assert vel_u == np.float32(np.linalg.norm(ref["ins_velocity_sigma_mps"][k]))


def test_ins_columns_are_the_truth_turned_by_the_stated_errors(run):
    """The INS columns against an independent path: the quaternion and angles agree with each other (scipy), the
    estimate stays within a few of its stated sigmas of the GNSS-free truth (the attitude the kernel wrote, turned
    into NED), and the stated sigmas are examples/companions.toml's."""
    from scipy.spatial.transform import Rotation
    _, ref = run
    q = ref["ins_quat"]
    assert (q[:, 0] >= 0).all() and np.allclose(np.linalg.norm(q, axis=1), 1.0, rtol=0, atol=1e-15)
    angles = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_euler("ZYX")[:, ::-1]
    np.testing.assert_allclose(angles, ref["ins_euler"], rtol=0, atol=1e-12)
    # the sensor's true attitude (NED scene: the kernel's quat is sensor -> NED already, its axes FRD)
    truth = Rotation.from_quat(ref["quat"][:, [1, 2, 3, 0]])
    error = (Rotation.from_quat(q[:, [1, 2, 3, 0]]) * truth.inv()).as_rotvec()
    sigma = ref["ins_attitude_sigma_rad"]
    assert (np.abs(error) < 5 * sigma).all()             # 5 sigma of a Gauss-Markov error: P(out) < 1e-6 a value
    assert np.allclose(sigma, np.radians([0.5, 0.5, 2.0]))


def vectornav_packets(data: bytes, groups: dict):
    """Payloads of VectorNav binary packets with the given {group bit: field word}, CRC-16/XMODEM checked (ICD:
    the CRC over everything after the sync byte, CRC included, is 0)."""
    header = bytes([0xFA, sum(1 << g for g in groups)]) + b"".join(struct.pack("<H", groups[g]) for g in sorted(groups))
    out, pos = [], 0
    while pos < len(data):
        assert data[pos:pos + len(header)] == header
        end = data.find(header, pos + 1) if data.find(header, pos + 1) > 0 else len(data)
        crc = 0
        for byte in data[pos + 1:end]:
            crc ^= byte << 8
            for _ in range(8):
                crc = ((crc << 1) ^ 0x1021 if crc & 0x8000 else crc << 1) & 0xFFFF
        assert crc == 0
        out.append(data[pos + len(header):end - 2])
        pos = end
    return out


def test_vectornav_imu_and_gps_groups(run):
    out, ref = run
    # IMU group (2): Pres bit 5, Mag bit 8; GPS group (3): Fix bit 4, PosLla bit 5, VelNed bit 7
    payloads = vectornav_packets((out / "vectornav.bin").read_bytes(), {2: 0x0120, 3: 0x00B0})
    assert len(payloads) == 600
    for k, payload in enumerate(payloads):
        pres, mx, my, mz, fix, lat, lon, h, vn, ve, vd = struct.unpack("<4fB3d3f", payload)
        assert pres == np.float32(ref["pressure_pa"][k] / 1000)                          # kPa
        assert [mx, my, mz] == list(f32(ref["mag"][k]))                               # gauss, FRD
        assert fix == int(ref["gnss_fix"][k])                     # the receiver's solution, held between fixes
        assert (lat, lon, h) == tuple(ref["gnss_llh"][k])
        assert [vn, ve, vd] == list(f32(ref["gnss_velocity_ned"][k]))


def test_xsens_mag_baro_and_gnss_pvt(run):
    out, ref = run
    data = (out / "xsens.bin").read_bytes()
    frames, pos = [], 0
    while pos < len(data):
        end = pos + 4 + data[pos + 3] + 1
        frames.append(ap_parse_mtdata2(data[pos:end]))
        pos = end
    assert len(frames) == 600
    flu = np.array([1.0, -1.0, -1.0])            # Xsens' sensor frame is x forward, y left, z up
    for k, frame in enumerate(frames):
        # arbitrary units of 0.49 gauss: ArduPilot multiplies by 490 mG per a.u. and gets the field back
        assert list(frame["magneticField"]) == list(f32(ref["mag"][k] * flu / 0.49))
        assert np.allclose(np.array(frame["magneticField"]) * 0.490, ref["mag"][k] * flu, rtol=1e-6, atol=0)
        assert frame["barometricPressure"] == round(ref["pressure_pa"][k])                  # u32 Pa
        pvt = frame["gnssPvtData"]
        lat, lon, h = ref["gnss_llh"][k]
        assert (pvt["lat"], pvt["lon"], pvt["height"]) == (round(lat * 1e7), round(lon * 1e7), round(h * 1e3))
        vel = ref["gnss_velocity_ned"][k]
        assert (pvt["velN"], pvt["velE"], pvt["velD"]) == tuple(round(v * 1e3) for v in vel)       # mm/s, NED
        assert pvt["fixType"] == int(ref["gnss_fix"][k])
        assert pvt["numSv"] == ref["gnss_satellites"][k]
        assert (pvt["hAcc"], pvt["vAcc"], pvt["sAcc"]) == tuple(
            round(ref[key][k] * 1e3) for key in ("gnss_horizontal_accuracy_m", "gnss_vertical_accuracy_m",
                                                 "gnss_speed_accuracy_mps"))                      # mm, mm/s
        assert (pvt["hDop"], pvt["vDop"]) == (round(ref["gnss_hdop"][k] * 100), round(ref["gnss_vdop"][k] * 100))


def test_xsens_orientation_position_velocity_are_the_ins_estimate(run):
    """MT Low-Level Communication Protocol MTData2: items of XDI (u16, low bits 0x3 precision: 3 = float64, 0xC
    coordinate frame: 0x4 NED), size (u8), big-endian data. The MTi's sensor frame is forward-left-up: its
    Quaternion (w, x, y, z) and EulerAngles (deg) are that frame w.r.t. NED, the estimate's attitude of the part's
    FRD axes turned by the half turn about x; LatLon (deg), AltitudeEllipsoid (m), VelocityXYZ (NED, m/s)."""
    from scipy.spatial.transform import Rotation
    out, ref = run
    data = (out / "xsens_ins.bin").read_bytes()
    frames, pos = [], 0
    while pos < len(data):
        assert data[pos:pos + 3] == b"\xfa\xff\x36" and sum(data[pos + 1:pos + 5 + data[pos + 3]]) & 0xFF == 0
        payload, items, k = data[pos + 4:pos + 4 + data[pos + 3]], {}, 0
        while k < len(payload):
            xdi, size = struct.unpack_from(">HB", payload, k)
            assert xdi & 0x3 == 0x3                                              # float64
            items[xdi & 0xFFF0] = (xdi & 0xC, struct.unpack_from(f">{size // 8}d", payload, k + 3))
            k += 3 + size
        frames.append(items)
        pos += 5 + data[pos + 3]
    assert len(frames) == 600
    flu = Rotation.from_rotvec([np.pi, 0.0, 0.0])                 # FLU -> FRD
    for k, items in enumerate(frames):
        estimate = Rotation.from_quat(ref["ins_quat"][k][[1, 2, 3, 0]]) * flu
        frame, (w, x, y, z) = items[0x2010]
        assert frame == 0x4
        np.testing.assert_allclose(canonical((w, x, y, z)), canonical(estimate.as_quat()[[3, 0, 1, 2]]), atol=1e-15)
        frame, euler = items[0x2030]
        assert frame == 0x4
        np.testing.assert_allclose(euler, np.degrees(estimate.as_euler("ZYX")[::-1]), rtol=0, atol=1e-11)
        assert items[0x5040][1] + items[0x5020][1] == tuple(ref["ins_llh"][k])
        frame, velocity = items[0xD010]
        assert frame == 0x4 and velocity == tuple(ref["ins_velocity_ned"][k])


# --- ENU and NED: one motion, two habits, the same messages ---------------------------------------------------

# The companions on test_axes_at_the_wire's moving scene: vectors of the scene (hard iron, the antenna's lever arm)
# written in each scene's body axes (FLU for ENU, FRD for NED), the rest equal.
COMPANIONS = """
[imu.magnetometer]
rate_hz = 100
noise_density = "140 ugauss/sqrt(Hz)"
turn_on_bias = "2 mgauss"
hard_iron = {hard_iron}
[imu.barometer]
noise = "1.2 Pa"
bias = "0.5 hPa"
[imu.gnss]
rate_hz = 5
latency_s = "50 ms"
lever_arm_m = {antenna}
position_noise = [0.3, 0.3, 0.6]
velocity_noise = 0.05
[imu.ins]
attitude_error = ["0.5 deg", "0.5 deg", "2 deg"]
position_error = [0.5, 0.5, 1.0]
velocity_error = 0.05
"""
BODY_VECTORS = {"ENU": ('["20 uT", "5 uT", "-3 uT"]', "[0.3, 0.1, 0.2]"),
                "NED": ('["20 uT", "-5 uT", "3 uT"]', "[0.3, -0.1, -0.2]")}
FRD_WIRES = (("hil_sensor", "mavlink-hil-sensor", "{}", "bin"),
             ("hil_gps", "mavlink-hil-gps", "{}", "bin"),
             ("dronecan", "dronecan-gnss-compass-baro", "{}", "log"),
             ("vectornav", "vectornav-binary", "{ fields = 'imu:pres,mag;gps:fix,poslla,velned' }", "bin"),
             ("mip_gnss", "microstrain-mip", "{ descriptor_set = 0x81, fields = 'position_llh,velocity_ned' }", "bin"))


@pytest.fixture(scope="module")
def both_frames(tmp_path_factory):
    from tests.firmware_protocols.test_axes_at_the_wire import SCENES
    out = {}
    for frame, text in SCENES.items():
        where = tmp_path_factory.mktemp(frame)
        hard_iron, antenna = BODY_VECTORS[frame]
        text = text.replace("[scene]\n", "[scene]\nseed = 3\n"
                            "origin = { lat_deg = 47.397742, lon_deg = 8.545594, height_m = 488.0 }\n")
        text = text.replace("\n[effects]", COMPANIONS.format(hard_iron=hard_iron, antenna=antenna) + "\n[effects]")
        for name, fmt, options, suffix in FRD_WIRES:
            text += (f'\n[[stream]]\nimu = "imu0"\nformat = "{fmt}"\nto = "file:{where / name}.{suffix}"\n'
                     f"options = {options}\n")
        (where / "scene.toml").write_text(text)
        cli("generate", where / "scene.toml", "-o", where / "bag.mcap", "--quiet")
        cli("generate", where / "scene.toml", "-o", where / "run.npz", "--quiet")
        cli("stream", where / "scene.toml", "--speed", "0", "--quiet")
        out[frame] = where
    return out


def ros_messages(path: Path) -> dict:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    topics = {}
    with open(path, "rb") as f:
        for _, channel, message, ros in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            topics.setdefault(channel.topic, []).append((message.log_time, ros))
    return topics


def fields(msg, prefix="") -> dict:
    """Every leaf field of a decoded ROS message, by its dotted path."""
    if hasattr(msg, "__slots__"):
        out = {}
        for name in msg.__slots__:
            out.update(fields(getattr(msg, name), f"{prefix}{name}."))
        return out
    if isinstance(msg, (list, tuple)) and msg and hasattr(msg[0], "__slots__"):
        out = {}
        for i, item in enumerate(msg):
            out.update(fields(item, f"{prefix}{i}."))
        return out
    return {prefix.rstrip("."): msg}


def test_enu_and_ned_scenes_give_the_same_ros2_messages(both_frames):
    """REP 103 / 105: both bags carry FLU bodies in ENU; every topic, stamp and field equal. The two kernels'
    attitudes differ in the last bits of a double (test_axes_at_the_wire), so the orientation and the magnetic field
    turned by it agree to a few ulp; everything else exactly."""
    enu, ned = ros_messages(both_frames["ENU"] / "bag.mcap"), ros_messages(both_frames["NED"] / "bag.mcap")
    assert set(enu) == set(ned) >= {"/imu/imu0", "/imu/imu0/mag", "/imu/imu0/pressure", "/imu/imu0/fix"}
    assert len(enu["/imu/imu0"]) == 400 and len(enu["/imu/imu0/fix"]) == 10
    for topic in enu:
        assert len(enu[topic]) == len(ned[topic]), topic
        for (t_enu, a), (t_ned, b) in zip(enu[topic], ned[topic]):
            assert t_enu == t_ned
            fa, fb = fields(a), fields(b)
            assert fa.keys() == fb.keys()
            for key, value in fa.items():
                if key.startswith("orientation.") or key.startswith("magnetic_field."):
                    assert value == pytest.approx(fb[key], rel=0, abs=1e-15 if "orientation" in key else 1e-19), \
                        (topic, key)
                elif isinstance(value, float) or isinstance(value, np.ndarray):
                    assert np.array_equal(value, fb[key]), (topic, key)
                else:
                    assert value == fb[key], (topic, key)


def test_enu_and_ned_scenes_give_the_same_ins_and_gnss_columns(both_frames):
    """The INS estimate's columns are the part's forward-right-down axes w.r.t. local NED whatever the scene's frame
    (as the wires send it), the receiver's figures are frame-free: one motion written as an ENU and as a NED scene
    gives the same columns (the kernels' attitudes differ in the last bits of a double: test_axes_at_the_wire)."""
    with np.load(both_frames["ENU"] / "run.npz") as enu, np.load(both_frames["NED"] / "run.npz") as ned:
        for key in ("ins_quat", "ins_euler"):
            np.testing.assert_allclose(enu[key], ned[key], rtol=0, atol=1e-12, err_msg=key)
        # the truth's position and velocity, turned into NED from each frame, agree to rounding
        for key in ("ins_llh", "ins_velocity_ned", "differential_pressure_pa"):
            np.testing.assert_allclose(enu[key], ned[key], rtol=1e-12, atol=1e-12, err_msg=key)
        for key in ("ins_attitude_sigma_rad", "ins_mode", "gnss_satellites", "gnss_hdop", "gnss_horizontal_accuracy_m"):
            assert np.array_equal(enu[key], ned[key]), key


@pytest.mark.parametrize("name", [name for name, *_ in FRD_WIRES])
def test_enu_and_ned_scenes_give_the_same_companion_bytes_on_frd_wires(both_frames, name):
    suffix = dict((n, s) for n, _, _, s in FRD_WIRES)[name]
    enu = (both_frames["ENU"] / f"{name}.{suffix}").read_bytes()
    ned = (both_frames["NED"] / f"{name}.{suffix}").read_bytes()
    assert len(enu) > 400 and enu == ned          # ten fixes at least, or 400 samples


@pytest.mark.parametrize("preset, descriptor_set, period", [("ardupilot", 0x91, 100), ("ardupilot-gx5", 0x81, 50)])
def test_microstrain_device_sends_each_solution_once_at_no_more_than_its_rate(run, preset, descriptor_set, period):
    """The device's GNSS set follows the receiver (gnss_new) under the preset's rate (GQ7 2 Hz: every 100th sample of
    200 Hz; GX5-45 4 Hz: every 50th): a solution is never sent twice, packets are at least a period apart and
    follow within one solution interval (40 samples of the 5 Hz receiver) of the period's end, each carrying the
    newest solution then."""
    from firmware_protocols import Samples, create_device
    _, ref = run
    samples = Samples(START_NS + np.rint(ref["t"] * 1e9).astype(np.int64), ref["accel"], ref["gyro"], mag=ref["mag"],
                      start_ns=START_NS,
                      pressure_pa=ref["pressure_pa"], gnss_llh=ref["gnss_llh"],
                      gnss_velocity_ned=ref["gnss_velocity_ned"], gnss_fix=ref["gnss_fix"], gnss_new=ref["gnss_new"])
    device = create_device("microstrain-mip", RATE, preset=preset)
    sent = []
    for k in range(len(samples)):
        data = device.output(samples, k)
        pos = 0
        while pos < len(data):
            end = pos + 4 + data[pos + 3] + 2
            if data[pos + 2] == descriptor_set:
                (packet,) = mip_packets(data[pos:end], descriptor_set)
                sent.append((k, struct.unpack(">3d", packet[0x03][:24])))
            pos = end
    new = new_solutions(ref)
    ticks = [k for k, _ in sent]
    assert ticks[0] == new[0]                                   # the first solution at once
    assert all(b - a >= period for a, b in zip(ticks, ticks[1:]))
    assert all(b - a <= period + 40 for a, b in zip(ticks, ticks[1:]))
    # the solution each packet carries (the newest at its sample; in the outage the receiver holds its position,
    # so solutions are told apart by their arrival, not their values): never the same twice
    carried = np.searchsorted(new, ticks, side="right") - 1
    assert carried.min() >= 0 and len(set(carried.tolist())) == len(carried)
    for k, llh in sent:
        assert llh == tuple(ref["gnss_llh"][k])               # the newest solution at that sample


def test_mavlink_device_carries_the_head_on_one_link(run):
    """The MAVLink device with also= (what a pty or UDP stream runs): HIL_SENSOR every sample, HIL_GPS at each new
    solution and SCALED_PRESSURE at the barometer's rate on one sequence, the same fields as the encoders'."""
    from firmware_protocols import Samples, create_device
    out, ref = run
    samples = Samples(START_NS + np.rint(ref["t"] * 1e9).astype(np.int64), ref["accel"], ref["gyro"], mag=ref["mag"],
                      start_ns=START_NS,
                      pressure_pa=ref["pressure_pa"], temperature_c=ref["baro_temperature_c"],
                      differential_pressure_pa=ref["differential_pressure_pa"],
                      gnss_llh=ref["gnss_llh"], gnss_velocity_ned=ref["gnss_velocity_ned"], gnss_fix=ref["gnss_fix"],
                      gnss_new=ref["gnss_new"], gnss_age_s=np.full(600, LATENCY_US / 1e6),   # at each new solution
                      mag_new=ref["mag_new"], baro_new=ref["baro_new"],
                      **{key: ref[key] for key in ("gnss_satellites", "gnss_hdop", "gnss_vdop",
                                                   "gnss_horizontal_accuracy_m", "gnss_vertical_accuracy_m",
                                                   "gnss_speed_accuracy_mps")})
    device = create_device("mavlink-hil-sensor", RATE, also="mavlink-hil-gps,mavlink-scaled-pressure")
    messages = mavlink2.MAVLink(None).parse_buffer(b"".join(device.output(samples, k) for k in range(600)))
    kinds = [m.get_type() for m in messages]
    assert kinds.count("HIL_SENSOR") == 600 and kinds.count("SCALED_PRESSURE") == 150
    assert kinds.count("HIL_GPS") == len(new_solutions(ref)) and kinds.count("HEARTBEAT") == 3
    seqs = [m.get_seq() for m in messages]
    assert all((b - a) % 256 == 1 for a, b in zip(seqs, seqs[1:]))
    streamed = {kind: [m.to_dict() for m in mavlink(out / f"{name}.bin")]
                for kind, name in (("HIL_SENSOR", "hil_sensor"), ("HIL_GPS", "hil_gps"),
                                   ("SCALED_PRESSURE", "scaled_pressure"))}
    for kind, want in streamed.items():
        got = [m.to_dict() for m in messages if m.get_type() == kind]
        assert len(got) == len(want), kind
        for k, (a, b) in enumerate(zip(got, want)):
            # every field from the NPZ's columns, the differential pressure and the receiver's figures included
            assert a == b, (kind, k, {key: (a[key], b[key]) for key in a if a[key] != b[key]})
