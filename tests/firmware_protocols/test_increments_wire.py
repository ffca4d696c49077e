"""Increments on the wire: `stream` compiles them for the formats whose fields carry them, and the fields
decode (pydronecan; the vendors' layouts unpacked here with struct) to the analytic integrals.

Motion with closed-form integrals (ENU, level): yaw = Ω t + A sin(w t), z = c t³, so the body rate is
(0, 0, Ω + A w cos w t) and the specific force (0, 0, g + 6 c t):
    Δθ_z = Ω T + A (sin w t_k − sin w t_k−1),   Δv_z = g T + 3 c (t_k² − t_k−1²),   x and y components 0.
Those are the ENU scene's forward-left-up body axes, which Xsens' sensor frame shares; the forward-right-down
wires (DroneCAN, VectorNav, MIP) carry them with z negated (issue 24: the part sits upright in any scene).
"""
from __future__ import annotations

import math
import struct

import can
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_emulator.cli import main

RATE, N = 200, 40
OMEGA, A, W, C, G0 = 0.4, 0.3, 2 * math.pi * 1.5, 0.05, 9.80665
F32 = 2.0 ** -23      # float32 relative rounding, twice over at most

SCENE = f"""
[scene]
rate_hz = {RATE}
duration_s = 1.0

[trajectory]
x = "0"
y = "0"
z = "{C}*t**3"

[attitude]
mode = "euler"
roll = "0"
pitch = "0"
yaw = "{OMEGA}*t + {A}*sin({W!r}*t)"

[[imu]]
name = "imu0"

[effects]
gravity = true
"""


def analytic(axes: str = "FRD"):
    """The closed-form increments in the wire's body axes: "FLU" (the scene's) or "FRD" (z negated)."""
    t = np.arange(N + 1, dtype=float) / RATE - 1.0 / RATE      # t_-1 .. t_N-1
    dtheta = np.zeros((N, 3))
    dvel = np.zeros((N, 3))
    dtheta[:, 2] = OMEGA / RATE + A * np.diff(np.sin(W * t))
    dvel[:, 2] = G0 / RATE + 3 * C * np.diff(t ** 2)
    if axes == "FRD":
        dtheta[:, 2], dvel[:, 2] = -dtheta[:, 2], -dvel[:, 2]
    return dtheta, dvel


def stream(tmp_path, fmt, target_suffix, *options):
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    target = tmp_path / f"out{target_suffix}"
    args = ["stream", str(scene), "--format", fmt, "--to", f"file:{target}", "--speed", "0", "--count", str(N),
            "--quiet", "--realtime", "off"]
    for option in options:
        args += ["--option", option]
    assert main(args) == 0
    return target


def assert_f32_close(actual, expected, scale):
    np.testing.assert_allclose(actual, expected, rtol=0, atol=2 * F32 * scale)


def test_dronecan_rawimu_integrals_are_the_increments(tmp_path):
    import dronecan
    from dronecan.transport import Frame, Transfer
    log = stream(tmp_path, "dronecan-rawimu", ".log")
    frames = [m for m in can.LogReader(str(log))]
    transfers, current = [], []
    for message in frames:                           # tail byte: end of transfer bit 0x40
        current.append(Frame(message.arbitration_id, bytearray(message.data)))
        if message.data[-1] & 0x40:
            transfer = Transfer()
            transfer.from_frames(current)
            transfers.append(transfer.payload)
            current = []
    assert len(transfers) == N
    assert all(isinstance(p, type(dronecan.uavcan.equipment.ahrs.RawIMU())) for p in transfers)
    dtheta, dvel = analytic()
    got_th = np.array([list(p.rate_gyro_integral) for p in transfers])
    got_dv = np.array([list(p.accelerometer_integral) for p in transfers])
    assert_f32_close(got_th, dtheta, np.abs(dtheta).max())
    assert_f32_close(got_dv, dvel, np.abs(dvel).max())
    # the interval is the sample period from the first sample on (not 0, "no integral")
    np.testing.assert_allclose([p.integration_interval for p in transfers], 1.0 / RATE, rtol=F32)
    # the tolerance would see a rate x interval stand-in: the rate at t_k times T misses the yaw's curvature
    t_k = np.arange(N) / RATE
    rate_times_t = (OMEGA + A * W * np.cos(W * t_k)) / RATE
    assert np.abs(rate_times_t - analytic("FLU")[0][:, 2]).max() > 1000 * 2 * F32 * np.abs(dtheta).max()


def _vectornav_packets(data: bytes, payload_size: int):
    """FA, groups, one mask per group, payload, CRC: the layout is fixed, so packets follow each other."""
    size = 1 + 1 + 2 * bin(data[1]).count("1") + payload_size + 2
    return [data[i:i + size] for i in range(0, len(data), size)]


def test_vectornav_delta_theta_and_delta_vel(tmp_path):
    # IMU group bits 6 (DeltaTheta: f32 dtime s, 3 x f32 deg) and 7 (DeltaVel: 3 x f32 m/s), little-endian
    out = stream(tmp_path, "vectornav-binary", ".bin", "fields=imu:deltatheta,deltavel")
    packets = _vectornav_packets(out.read_bytes(), 16 + 12)
    assert len(packets) == N
    assert packets[0][1] == 0x04 and struct.unpack_from("<H", packets[0], 2)[0] == (1 << 6) | (1 << 7)
    values = np.array([struct.unpack_from("<7f", p, 4) for p in packets])
    dtheta, dvel = analytic()
    np.testing.assert_allclose(values[:, 0], 1.0 / RATE, rtol=F32)
    assert_f32_close(np.radians(values[:, 1:4]), dtheta, np.abs(dtheta).max())
    assert_f32_close(values[:, 4:7], dvel, np.abs(dvel).max())


def test_xsens_delta_q_and_delta_v(tmp_path):
    out = stream(tmp_path, "xsens-mtdata2", ".bin", "items=delta_q,delta_v")
    data = out.read_bytes()
    dq, dv = [], []
    i = 0
    while i < len(data):                        # FA FF 36 len payload checksum; items XDI(2, BE) size(1) data
        length = data[i + 3]
        payload = data[i + 4:i + 4 + length]
        j = 0
        while j < length:
            xdi, size = struct.unpack_from(">HB", payload, j)
            values = struct.unpack_from(f">{size // 4}f", payload, j + 3)
            {0x8030: dq, 0x4010: dv}[xdi & 0xFFF0].append(values)
            j += 3 + size
        i += 4 + length + 1
    dtheta, dvel = analytic("FLU")          # the MTi's sensor frame: forward-left-up
    # DeltaQ: the rotation by the increment, scalar first (scipy: scalar last)
    expected_q = Rotation.from_rotvec(dtheta).as_quat()[:, [3, 0, 1, 2]]
    assert_f32_close(np.array(dq), expected_q, 1.0)
    assert_f32_close(np.array(dv), dvel, np.abs(dvel).max())


def test_mip_delta_theta_and_delta_velocity(tmp_path):
    out = stream(tmp_path, "microstrain-mip", ".bin", "fields=delta_theta,delta_velocity")
    data = out.read_bytes()
    th, dv = [], []
    i = 0
    while i < len(data):          # 75 65 set len fields checksum(2); field: len descriptor data (big-endian)
        length = data[i + 3]
        j = i + 4
        while j < i + 4 + length:
            field_len, descriptor = data[j], data[j + 1]
            values = struct.unpack_from(">3f", data, j + 2)
            {0x07: th, 0x08: dv}[descriptor].append(values)
            j += field_len
        i += 4 + length + 2
    dtheta, dvel = analytic()
    assert_f32_close(np.array(th), dtheta, np.abs(dtheta).max())
    assert_f32_close(np.array(dv) * G0, dvel, np.abs(dvel).max())     # 0x08 is in g*s


def test_formats_without_increment_fields_do_not_compile_them():
    from imu_emulator.live.config import StreamConfig, TargetOptions, needs_increments
    options = TargetOptions()

    def config(fmt, device=False, **kw):
        return StreamConfig("imu0", fmt, "file:/dev/null", kw, options, device)
    assert not needs_increments([config("mavlink-highres")])
    assert not needs_increments([config("vectornav-binary")])       # Accel|AngularRate by default
    assert needs_increments([config("vectornav-binary", fields="imu:deltatheta")])
    assert needs_increments([config("dronecan-rawimu")])
    assert needs_increments([config("xsens-mtdata2", items="delta_v")])
    assert needs_increments([config("xsens-mtdata2", device=True)])   # its driver may ask for them
    assert needs_increments([config("vectornav-vnymr", device=True)])  # ASCII now, binary DeltaTheta later
    assert needs_increments([config("dronecan-rawimu", device=True)])
    assert not needs_increments([config("mavlink-highres", device=True)])


def test_vectornav_refuses_delta_fields_without_increments():
    from firmware_protocols.base import EncodeError, Samples
    from firmware_protocols.wire_formats.vectornav_binary import BinaryEncoder
    with pytest.raises(EncodeError, match=r"imu\.deltatheta.*no delta_theta"):
        BinaryEncoder("imu:deltatheta").encode(Samples.single(0, [0, 0, 9.8], [0, 0, 0]))


def test_a_divided_device_output_carries_the_increments_since_its_last_packet():
    # VectorNav: "the integration ... is reset each time the values are polled or sent out" (DeltaTheta's
    # description). Binary output 1 at divisor 4 of 800 Hz: each packet's increments are the sum of the four
    # sample intervals since the previous packet, and dtime is four periods.
    from functools import reduce

    from firmware_protocols import create_device
    from firmware_protocols.base import Samples
    device = create_device("vectornav-binary", 800.0)
    body = b"VNWRG,75,1,4,04,00C0"          # IMU group: DeltaTheta | DeltaVel
    device.receive(b"$" + body + b"*%02X\r\n" % reduce(lambda a, b: a ^ b, body, 0))
    n, rng = 16, np.random.default_rng(1)
    samples = Samples(np.arange(n) * 1_250_000, np.zeros((n, 3)), np.zeros((n, 3)),
                      delta_theta=rng.normal(size=(n, 3)) * 1e-3, delta_velocity=rng.normal(size=(n, 3)) * 1e-2,
                      delta_time_s=np.full(n, 1 / 800))
    packets = [device.output(samples, i) for i in range(n)]
    sent = [i for i, p in enumerate(packets) if p]
    assert sent == [0, 4, 8, 12]
    for previous, i in zip([-1] + sent[:-1], sent):
        values = struct.unpack_from("<7f", packets[i], 4)
        span = slice(previous + 1, i + 1)
        np.testing.assert_allclose(values[0], (i - previous) / 800, rtol=F32)
        np.testing.assert_allclose(np.radians(values[1:4]), samples.delta_theta[span].sum(axis=0), rtol=4 * F32)
        np.testing.assert_allclose(values[4:7], samples.delta_velocity[span].sum(axis=0), rtol=4 * F32)


# Coning: roll = a sin(w t), pitch = a cos(w t), yaw 0 (R = Rz(yaw) Ry(pitch) Rx(roll), body -> ENU). The body
# rate's direction turns within each interval, so the attitude change is not the rotation by the summed rate.
CONING_RATE, CONING_N, CONING_A, CONING_W = 100, 60, 0.2, 2 * math.pi * 5.0


def _coning_attitude(t, w=CONING_W):
    return Rotation.from_euler("ZYX", np.column_stack([np.zeros_like(t), CONING_A * np.cos(w * t),
                                                       CONING_A * np.sin(w * t)]))


def _coning_rate(t, w=CONING_W):
    """The closed-form body rate of z-y-x Euler angles with yaw 0: ω = (roll', pitch' cos roll, -pitch' sin roll)."""
    roll, droll = CONING_A * np.sin(w * t), CONING_A * w * np.cos(w * t)
    dpitch = -CONING_A * w * np.sin(w * t)
    return np.stack([droll, dpitch * np.cos(roll), -dpitch * np.sin(roll)], axis=-1)


def _coning_increments(t0, t1, nodes=24):
    """∫ω dt over each interval by Gauss-Legendre on the closed-form body rate of z-y-x Euler angles with yaw
    0: ω = (roll', pitch' cos roll, -pitch' sin roll) (24 nodes: exact to double precision at ωT = 0.31)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    h = (t1 - t0)[:, None]
    t = t0[:, None] + (x[None, :] + 1) / 2 * h
    return np.einsum("nk,nki->ni", w[None, :] * h / 2, _coning_rate(t))


def _coning_delta_q(tmp_path, w=CONING_W, extra=""):
    """Xsens DeltaQ (scalar first) of the coning scene streamed to a file, one row per sample."""
    scene = tmp_path / "coning.toml"
    scene.write_text(f"""
[scene]
rate_hz = {CONING_RATE}
duration_s = 1.0

[trajectory]
x = "0"
y = "0"
z = "0"

[attitude]
mode = "euler"
roll = "{CONING_A}*sin({w!r}*t)"
pitch = "{CONING_A}*cos({w!r}*t)"
yaw = "0"

[[imu]]
name = "imu0"
{extra}""")
    target = tmp_path / "out.bin"
    assert main(["stream", str(scene), "--format", "xsens-mtdata2", "--to", f"file:{target}", "--speed", "0",
                 "--count", str(CONING_N), "--quiet", "--realtime", "off", "--option", "items=delta_q"]) == 0
    data = target.read_bytes()
    size = 4 + 3 + 16 + 1                       # FA FF 36 len, XDI size, 4 x f32, checksum
    dq = np.array([struct.unpack_from(">4f", data, i + 7) for i in range(0, len(data), size)])
    assert len(dq) == CONING_N
    return dq


def test_xsens_delta_q_is_the_exact_attitude_change_with_coning(tmp_path):
    dq = _coning_delta_q(tmp_path)
    t = np.arange(-1, CONING_N) / CONING_RATE   # t_-1 .. t_N-1
    truth = _coning_attitude(t)
    exact = (truth[:-1].inv() * truth[1:]).as_quat()[:, [3, 0, 1, 2]]
    exact *= np.sign(exact[:, :1])
    # The first sample has no attitude before it in the stream: its DeltaQ is the rotation by its increment.
    assert_f32_close(dq[1:], exact[1:], 1.0)
    # ... which is what the exact change is not: the rotation by the increment (∫ω dt, integrated here from
    # the closed-form rate) misses the coning term, over a hundred times the tolerance in this motion.
    by_increment = Rotation.from_rotvec(_coning_increments(t[:-1], t[1:])).as_quat()[:, [3, 0, 1, 2]]
    assert np.abs(by_increment[1:] - exact[1:]).max() > 100 * 2 * F32
    assert_f32_close(dq[:1], by_increment[:1], 1.0)


def test_xsens_delta_q_carries_the_gyro_errors(tmp_path):
    # A constant gyro bias b: the sensed attitude change is the solution of q' = q (ω + b) / 2 over the
    # interval, integrated here by RK4 (400 steps: error far below float32) from the true attitude at t_k-1.
    # DeltaQ applies the bias as the rotation by ε ≈ b T after the exact change; the neglected terms are the
    # commutator ½|bT||Δθ| (6e-7 here, 1 Hz coning) plus the two-sample coning estimate's residual (below
    # 1e-8 at ωT = 0.06), so 2e-6 bounds the difference; leaving the bias out would miss by |bT|/2 = 5e-5.
    b = np.array([0.01, 0.005, -0.01])
    w = 2 * math.pi * 1.0
    dq = _coning_delta_q(tmp_path, w, "[imu.gyro]\nbias = [0.01, 0.005, -0.01]\n[effects]\nbias = true\n")
    t = np.arange(-1, CONING_N) / CONING_RATE
    truth = _coning_attitude(t, w)
    steps, expected = 400, []
    for k in range(1, CONING_N):
        q, h = np.array([1.0, 0, 0, 0]), (t[k + 1] - t[k]) / steps

        def derivative(tau, q):
            wx, wy, wz = _coning_rate(np.array([tau]), w)[0] + b
            return 0.5 * np.array([-q[1] * wx - q[2] * wy - q[3] * wz, q[0] * wx + q[2] * wz - q[3] * wy,
                                   q[0] * wy - q[1] * wz + q[3] * wx, q[0] * wz + q[1] * wy - q[2] * wx])
        for j in range(steps):
            tau = t[k] + j * h
            k1 = derivative(tau, q)
            k2 = derivative(tau + h / 2, q + h / 2 * k1)
            k3 = derivative(tau + h / 2, q + h / 2 * k2)
            k4 = derivative(tau + h, q + h * k3)
            q = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        expected.append(q / np.linalg.norm(q))
    expected = np.array(expected)
    np.testing.assert_allclose(dq[1:], expected, rtol=0, atol=2e-6)
    exact = (truth[1:-1].inv() * truth[2:]).as_quat()[:, [3, 0, 1, 2]]
    assert np.abs(exact * np.sign(exact[:, :1]) - expected).max() > 2e-5


def test_increments_since_the_last_output_multiply_the_attitude_changes_in_order():
    # With an output divider the DeltaQ of a packet spans the sub-intervals since the previous one:
    # q(t_0)^-1 q(t_3) = the product of the three changes, against scipy's composition of the true attitudes.
    from firmware_protocols.base import Samples
    from firmware_protocols.devices.base import SinceLastOutput, single
    t = np.arange(4) / CONING_RATE
    truth = _coning_attitude(t)
    changes = (truth[:-1].inv() * truth[1:]).as_quat()[:, [3, 0, 1, 2]]
    n = len(changes)
    samples = Samples(np.arange(n), np.zeros((n, 3)), np.zeros((n, 3)), delta_theta=np.zeros((n, 3)),
                      delta_velocity=np.zeros((n, 3)), delta_time_s=np.full(n, 0.01), attitude_change=changes)
    since = SinceLastOutput()
    for i in range(n):
        since.add(samples, i)
    got = since.attach(single(samples, n - 1)).attitude_change[0]
    expected = (truth[0].inv() * truth[-1]).as_quat()[[3, 0, 1, 2]]
    np.testing.assert_allclose(got * np.sign(got[0]), expected * np.sign(expected[0]), rtol=0, atol=1e-15)


def _vn_command(device, body: str) -> bytes:
    from functools import reduce
    return b"".join(device.receive(b"$" + body.encode() + b"*%02X\r\n" % reduce(lambda a, b: a ^ b, body.encode(), 0)))


def test_vectornav_register_82_layout_read_write_and_refusals():
    # VectorNav's C library reads register 82 as five fields: u8 IntegrationFrame (BODY 0, NED 1), u8
    # GyroCompensation, u8 AccelCompensation (NONE 0, BIAS 1), u8 Reserved1, u16 Reserved2; factory: all 0.
    from firmware_protocols import create_device
    device = create_device("vectornav-binary", 800.0)
    assert b"$VNRRG,82,0,0,0,0,0*" in _vn_command(device, "VNRRG,82")
    assert b"$VNWRG,82,1,1,0,0,0*" in _vn_command(device, "VNWRG,82,1,1,0,0,0")
    assert b"$VNRRG,82,1,1,0,0,0*" in _vn_command(device, "VNRRG,82")
    assert b"$VNERR,07*" in _vn_command(device, "VNWRG,82,2,0,0,0,0")      # no integration frame 2
    assert b"$VNERR,07*" in _vn_command(device, "VNWRG,82,0,0,0,0,65536")  # Reserved2 is 16 bits
    assert b"$VNERR,05*" in _vn_command(device, "VNWRG,82,1,0,0")
    assert b"$VNRRG,82,1,1,0,0,0*" in _vn_command(device, "VNRRG,82")      # refused writes changed nothing


@pytest.mark.parametrize("divisor", [1, 3])
def test_vectornav_ned_integration_frame_against_the_closed_form(divisor):
    # Constant yaw rate Ω about down with a constant body specific force f = (fx, 0, fz): the body -> NED
    # attitude is Rz(Ω t), so over (t_a, t_b] ∫C f dt = (fx (sin Ωt_b − sin Ωt_a)/Ω, −fx (cos Ωt_b − cos Ωt_a)/Ω,
    # fz (t_b − t_a)) and ∫C ω dt = (0, 0, Ω (t_b − t_a)). With a divisor the packet spans the samples since
    # the previous one, summed in NED. Register 82 = 1 (NED) selects it; 0 (body) gives f T back.
    from firmware_protocols import create_device
    from firmware_protocols.base import Samples
    rate, omega, fx, fz, n = 800.0, 1.7, 2.5, -9.8, 12
    t = np.arange(n) / rate + 0.3
    quat = np.column_stack([np.cos(omega * t / 2), np.zeros(n), np.zeros(n), np.sin(omega * t / 2)])
    samples = Samples((t * 1e9).astype(np.int64), np.tile([fx, 0, fz], (n, 1)), np.tile([0, 0, omega], (n, 1)),
                      quat=quat, delta_theta=np.tile([0, 0, omega / rate], (n, 1)),
                      delta_velocity=np.tile([fx / rate, 0, fz / rate], (n, 1)), delta_time_s=np.full(n, 1 / rate))
    for frame in (1, 0):
        device = create_device("vectornav-binary", rate)
        _vn_command(device, f"VNWRG,75,1,{divisor},04,00C0")      # IMU group: DeltaTheta | DeltaVel
        _vn_command(device, f"VNWRG,82,{frame},0,0,0,0")
        packets = [device.output(samples, i) for i in range(n)]
        sent = [i for i, p in enumerate(packets) if p]
        assert sent == list(range(0, n, divisor))
        for previous, i in zip([-1] + sent[:-1], sent):
            values = np.array(struct.unpack_from("<7f", packets[i], 4))
            t_a, t_b = t[previous + 1] - 1 / rate, t[i]
            if frame == 1:
                dvel = [fx * (np.sin(omega * t_b) - np.sin(omega * t_a)) / omega,
                        -fx * (np.cos(omega * t_b) - np.cos(omega * t_a)) / omega, fz * (t_b - t_a)]
            else:
                dvel = [fx * (t_b - t_a), 0.0, fz * (t_b - t_a)]
            assert_f32_close(np.radians(values[1:4]), [0, 0, omega * (t_b - t_a)], omega * (t_b - t_a))
            assert_f32_close(values[4:7], dvel, 4 * abs(fz) * (t_b - t_a))


def test_xsens_alignment_rotation_turns_the_attitude_change_into_the_object_frame():
    # RotSensor q_OS: vectors x_O = R_OS x_S, so a rotation R_S seen in O is R_OS R_S R_OS^-1 (scipy composes).
    from firmware_protocols.base import Samples
    from firmware_protocols.devices.xsens import aligned
    sensor = Rotation.from_rotvec([0.3, -1.1, 0.7])
    change = Rotation.from_rotvec([0.01, 0.02, -0.015])
    one = Samples(np.array([0]), np.zeros((1, 3)), np.zeros((1, 3)), delta_theta=change.as_rotvec()[None, :],
                  delta_velocity=np.zeros((1, 3)), attitude_change=change.as_quat()[None, [3, 0, 1, 2]])
    out = aligned(one, sensor.as_quat()[[3, 0, 1, 2]], (1.0, 0.0, 0.0, 0.0), "NED")
    expected = (sensor * change * sensor.inv()).as_quat()[[3, 0, 1, 2]]
    np.testing.assert_allclose(out.attitude_change[0], expected * np.sign(expected[0]), rtol=0, atol=1e-15)
    np.testing.assert_allclose(out.delta_theta[0], sensor.apply(change.as_rotvec()), rtol=0, atol=1e-15)
