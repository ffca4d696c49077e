"""Axes at the boundary (issue 24): an IMU without mounting reads like the real part sitting upright and facing
forward whatever the scene's frame, and each wire carries the axes its manual declares.

Oracles: pymavlink decodes HIL_SENSOR (common.xml: "The IMU readings in SI units in NED body frame", so a level
part at rest reads zacc = -g); VectorNav's yaw/pitch/roll are "the body frame with respect to the local North
East Down (NED) frame" (VN-100 User Manual UM001 §4.4.3), 0/0/0 for a level unit facing north; the Xsens MTi User
Manual MT0605P.E §4.2.3 tabulates yaw for a unit pointing north: 90 deg in ENU, 0 in NWU and NED, its sensor frame
x forward, y left, z up (acceleration z = +g at rest). scipy's Rotation checks the re-expression itself.
The same motion written as an ENU and as a NED scene gives identical bytes on every wire."""
import dataclasses

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2
from scipy.spatial.transform import Rotation

import firmware_protocols
from firmware_protocols import Samples, attitude
from firmware_protocols.axes import BODY_AXES, declarations, reexpress, to_body_axes
from tests.support.paths import DATA

G = 9.80665

STATIC = """
[scene]
rate_hz = 50
duration_s = 0.2
frame = "{frame}"

[trajectory]
shape = "static"
position_m = [0.0, 0.0, 0.0]

[attitude]
mode = "euler"
yaw = "{yaw}"

[[imu]]
name = "upright"

[[imu]]
name = "rolled"
mounting_rpy_deg = [90.0, 0.0, 0.0]

[effects]
gravity = true
mounting = true
"""

# One motion, rotating about every axis and moving along every axis, in both frames: positions (x_ned, y_ned,
# z_ned) = (y_enu, x_enu, -z_enu); body FRD = FLU with y and z negated, so a lever arm (a, b, c) in FLU is
# (a, -b, -c) in FRD; angles: roll is the same rotation in both habits, pitch changes sign (about left vs right)
# and yaw is measured from east anticlockwise vs from north clockwise (yaw_ned = pi/2 - yaw_enu).
MOVING = """
[scene]
rate_hz = 200
duration_s = 2.0
frame = "{frame}"

[trajectory]
x = "{x}"
y = "{y}"
z = "{z}"

[attitude]
mode = "euler"
roll = "0.4*sin(2*pi*0.7*t)"
pitch = "{pitch}"
yaw = "{yaw}"

[[imu]]
name = "imu0"
lever_arm_m = {arm}

[effects]
gravity = true
lever_arm = true
"""
EAST, NORTH, UP = "3*cos(2*pi*0.3*t)", "2*sin(2*pi*0.4*t) + 0.5*t", "0.7*sin(2*pi*0.9*t)"
ENU_PITCH, ENU_YAW = "0.3*cos(2*pi*0.5*t)", "0.6*t + 0.2*sin(2*pi*1.1*t)"
SCENES = {
    "ENU": MOVING.format(frame="ENU", x=EAST, y=NORTH, z=UP, pitch=ENU_PITCH, yaw=ENU_YAW, arm="[0.1, 0.2, 0.3]"),
    "NED": MOVING.format(frame="NED", x=NORTH, y=EAST, z=f"-({UP})", pitch=f"-({ENU_PITCH})",
                         yaw=f"pi/2 - ({ENU_YAW})", arm="[0.1, -0.2, -0.3]"),
}


def _simulate(tmp_path, text, name, increments=0):
    from imu_emulator.runtime.simulation import Simulation
    from imu_emulator.scene.load import load_scene
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    scene = load_scene(path)
    return scene, Simulation(scene, truth=True, increments=increments).block(0, scene.n_samples)


def _stream_samples(scene, block, imu: int, device: bool = False):
    """What the live path hands every encoder (Stream.samples), for IMU `imu` of the block."""
    from imu_emulator.live.config import StreamConfig
    from imu_emulator.live.stream import Stream
    stream = Stream(StreamConfig("imu0", "mavlink-hil-sensor", "pty"), imu,
                    firmware_protocols.get("mavlink-hil-sensor"), float(scene.rate_hz))
    stream.frame = scene.frame
    if device:       # the device path's Samples (euler too); no device needed to build them
        stream.device = object()
    return stream.samples(block, block.time_ns())


# --- the re-expression itself ------------------------------------------------------------------

def test_reexpress_keeps_every_reference_frame_quantity_and_turns_the_body_side():
    """FRD -> FLU and back: vectors get the axes' signs, and R(q) v (the vector in NED) is unchanged; the attitude
    change over an interval equals the change between the converted attitudes (scipy as the oracle)."""
    rng = np.random.default_rng(24)
    n = 50
    quat = Rotation.random(n, random_state=7).as_quat()[:, [3, 0, 1, 2]]
    before = Rotation.random(n, random_state=8).as_quat()[:, [3, 0, 1, 2]]
    change = attitude.multiply(attitude.conjugate(before), quat)
    vectors = {name: rng.normal(size=(n, 3)) for name in ("accel", "gyro", "mag", "delta_theta", "delta_velocity")}
    frd = Samples(np.arange(n), quat=quat, euler=attitude.to_euler(quat), attitude_change=change,
                  velocity_ned=rng.normal(size=(n, 3)), **vectors)
    flu = to_body_axes(frd, "FLU")
    for name in vectors:
        np.testing.assert_array_equal(getattr(flu, name), getattr(frd, name) * [1.0, -1.0, -1.0])
        in_ned = Rotation.from_quat(frd.quat[:, [1, 2, 3, 0]]).apply(getattr(frd, name))
        np.testing.assert_allclose(Rotation.from_quat(flu.quat[:, [1, 2, 3, 0]]).apply(getattr(flu, name)),
                                   in_ned, atol=1e-12)
    flu_before = Rotation.from_quat(before[:, [1, 2, 3, 0]]) * Rotation.from_rotvec([np.pi, 0.0, 0.0])
    want = flu_before.inv() * Rotation.from_quat(flu.quat[:, [1, 2, 3, 0]])
    assert np.all((want.inv() * Rotation.from_quat(flu.attitude_change[:, [1, 2, 3, 0]])).magnitude() < 1e-12)
    np.testing.assert_allclose(flu.euler, Rotation.from_quat(flu.quat[:, [1, 2, 3, 0]]).as_euler("ZYX")[:, ::-1],
                               atol=1e-12)
    np.testing.assert_array_equal(flu.velocity_ned, frd.velocity_ned)       # NED stays NED
    back = reexpress(flu, "FLU", "FRD")
    for name in vectors:
        np.testing.assert_array_equal(getattr(back, name), getattr(frd, name))
    for name in ("quat", "attitude_change"):      # q and -q are one rotation: compare canonical signs
        np.testing.assert_allclose(getattr(back, name), attitude.canonical(getattr(frd, name)), atol=1e-15)
    assert to_body_axes(frd, "FRD") is frd
    with pytest.raises(ValueError, match="body axes"):
        to_body_axes(frd, "RFU")


def test_every_format_declares_its_axes():
    """The one table: every registered format names body axes this module converts to and a reference frame
    (or none, for formats without attitude), with the source it was read from."""
    table = declarations()
    assert set(table) == set(firmware_protocols.formats())
    for name, (body, reference, source) in table.items():
        assert body in BODY_AXES, name
        assert reference in (None, "NED", "ENU"), name
        assert source, name
    assert table["mavlink-hil-sensor"][:2] == ("FRD", "NED")
    assert table["xsens-mtdata2"][:2] == ("FLU", "ENU")
    assert table["bosch-mm7"][0] == "FLU"


# --- a level part at rest, facing north, in an ENU and a NED scene ------------------------------

@pytest.fixture(scope="module")
def at_rest(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rest")
    return {frame: _simulate(tmp, STATIC.format(frame=frame, yaw="pi/2" if frame == "ENU" else "0"), frame)
            for frame in ("ENU", "NED")}


@pytest.mark.parametrize("frame", ["ENU", "NED"])
def test_hil_sensor_reads_minus_g_on_z_at_rest(at_rest, frame):
    scene, block = at_rest[frame]
    for imu, want in ((0, (0.0, 0.0, -G)), (1, (0.0, -G, 0.0))):
        # imu 1 is rolled 90 deg from upright (right side down): its y axis points down and reads -g
        data = firmware_protocols.create_encoder("mavlink-hil-sensor").encode(_stream_samples(scene, block, imu)).data
        parser = mavlink2.MAVLink(None)
        messages = parser.parse_buffer(data)
        assert len(messages) == len(block.t_s)
        for message in messages:
            assert message.get_type() == "HIL_SENSOR"
            np.testing.assert_allclose((message.xacc, message.yacc, message.zacc), want, atol=1e-5)
            np.testing.assert_allclose((message.xgyro, message.ygyro, message.zgyro), 0.0, atol=1e-9)


@pytest.mark.parametrize("frame", ["ENU", "NED"])
def test_vectornav_yaw_pitch_roll_zero_facing_north(at_rest, frame):
    scene, block = at_rest[frame]
    encoder = firmware_protocols.create_encoder("vectornav-binary", fields="common:yawpitchroll,accel")
    decoder = firmware_protocols.create_decoder("vectornav-binary")
    packets = decoder.feed(encoder.encode(_stream_samples(scene, block, 0, device=True)).data)
    assert len(packets) == len(block.t_s)
    for packet in packets:
        rpy = np.degrees(packet.fields["common.yawpitchroll"])      # decoded back to roll, pitch, yaw in rad
        np.testing.assert_allclose(np.mod(rpy + 180.0, 360.0) - 180.0, 0.0, atol=1e-4)
        np.testing.assert_allclose(packet.fields["common.accel"], (0.0, 0.0, -G), atol=1e-5)


# MT0605P.E §4.2.3: yaw of a unit pointing north is 90 deg (ENU), 0 (NWU), 0 (NED); with the sensor frame
# x forward, y left, z up, NED (z down) makes it upside down: roll 180.
XSENS_RPY = {"ENU": (0.0, 0.0, 90.0), "NWU": (0.0, 0.0, 0.0), "NED": (180.0, 0.0, 0.0)}


@pytest.mark.parametrize("frame", ["ENU", "NED"])
@pytest.mark.parametrize("setting", ["ENU", "NED", "NWU"])
def test_xsens_sensor_frame_and_the_configured_reference(at_rest, frame, setting):
    scene, block = at_rest[frame]
    options = {"items": "quaternion,euler_angles,acceleration,rate_of_turn", "precision": "float64",
               "frame": setting}
    data = firmware_protocols.create_encoder("xsens-mtdata2", **options).encode(
        _stream_samples(scene, block, 0, device=True)).data
    packets = firmware_protocols.create_decoder("xsens-mtdata2").feed(data)
    assert len(packets) == len(block.t_s)
    for packet in packets:
        assert packet.fields["frame"] == setting
        np.testing.assert_allclose(packet.fields["accel"], (0.0, 0.0, G), atol=1e-9)   # z up: +g at rest
        euler = np.degrees(packet.fields["euler"])          # roll, pitch, yaw (the decoder gives rad)
        wrapped = np.mod(euler - XSENS_RPY[setting] + 180.0, 360.0) - 180.0
        np.testing.assert_allclose(wrapped, 0.0, atol=1e-9)


# --- one moving scene, two frames, the same bytes -------------------------------------------------

@pytest.fixture(scope="module")
def moving(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("moving")
    return {frame: _simulate(tmp, text, frame, increments=2) for frame, text in SCENES.items()}


def _wire(name, samples):
    out = firmware_protocols.create_encoder(name).encode(samples)
    return bytes(out.data) if hasattr(out, "data") else out.tobytes()


def test_enu_and_ned_versions_of_one_motion_give_the_same_bytes_on_every_wire(moving):
    (enu_scene, enu), (ned_scene, ned) = moving["ENU"], moving["NED"]
    # the two scenes are one motion: the NED truth is the ENU truth's permutation
    np.testing.assert_allclose(ned.truth["position"], enu.truth["position"][:, [1, 0, 2]] * [1, 1, -1], atol=1e-9)
    frd = {frame: _stream_samples(scene, block, 0, device=True) for frame, (scene, block) in moving.items()}
    # attitude and rates equal the scene's: the NED scene's body is FRD already, untouched
    np.testing.assert_array_equal(frd["NED"].gyro, ned.gyro[0])
    np.testing.assert_array_equal(frd["NED"].accel, ned.accel[0])
    for name in ("accel", "gyro", "delta_theta", "delta_velocity"):
        np.testing.assert_allclose(getattr(frd["ENU"], name), getattr(frd["NED"], name), rtol=0, atol=1e-12,
                                   err_msg=name)
    angle = (Rotation.from_quat(frd["ENU"].quat[:, [1, 2, 3, 0]]).inv()
             * Rotation.from_quat(frd["NED"].quat[:, [1, 2, 3, 0]])).magnitude()
    assert angle.max() < 1e-12
    np.testing.assert_allclose(frd["ENU"].euler, frd["NED"].euler, atol=1e-12)
    assert np.all((Rotation.from_quat(frd["ENU"].attitude_change[:, [1, 2, 3, 0]]).inv()
                   * Rotation.from_quat(frd["NED"].attitude_change[:, [1, 2, 3, 0]])).magnitude() < 1e-12)
    # Every wire carries the same bytes for the sensor data (vectors and increments are equal to the last bit,
    # a rest's zeros included: no -0.0 from a negation); the attitude the two kernels compute differs in the
    # last bits of a double (above), which can tip a float32 rounding, so it is compared decoded, below.
    sensors = {frame: dataclasses.replace(samples, quat=None, euler=None, attitude_change=None)
               for frame, samples in frd.items()}
    different = [name for name in firmware_protocols.formats()
                 if _wire(name, sensors["ENU"]) != _wire(name, sensors["NED"])]
    assert not different, f"ENU and NED scenes differ on {different}"
    fields = "common:quaternion,yawpitchroll,accel,angularrate"
    decoded = {frame: firmware_protocols.create_decoder("vectornav-binary").feed(
        firmware_protocols.create_encoder("vectornav-binary", fields=fields).encode(samples).data)
        for frame, samples in frd.items()}
    assert len(decoded["ENU"]) == len(decoded["NED"]) == len(ned.t_s)
    for a, b in zip(decoded["ENU"], decoded["NED"]):
        assert set(a.fields) == set(b.fields)
        for key in a.fields:           # float32: within a unit in the last place of values up to pi
            np.testing.assert_allclose(a.fields[key], b.fields[key], rtol=0, atol=4e-7, err_msg=key)


def _xbus(mid: int, data: bytes = b"") -> bytes:
    """An Xbus message from the host, built from the spec's rules (preamble FA, bus id FF, byte-sum checksum)."""
    body = bytes([0xFF, mid, len(data)]) + data
    return b"\xfa" + body + bytes([(0x100 - sum(body)) & 0xFF])


@pytest.mark.parametrize("setting, bits", [("ENU", 0x0), ("NED", 0x4), ("NWU", 0x8)])
def test_xsens_device_follows_the_coordinate_system_a_driver_configures(setting, bits):
    """GoToConfig, SetOutputConfiguration with Quaternion and Acceleration (the quaternion's XDI carrying the
    coordinate-system bits), GoToMeasurement; then a level part at rest facing north (FRD Samples: identity
    attitude, f = (0, 0, -g)) goes out as the MTi's sensor frame referenced to what was configured: acceleration
    z = +g in every setting, the euler angles of MT0605P.E's table (XSENS_RPY) computed from the quaternion."""
    import struct
    device = firmware_protocols.create_device("xsens-mtdata2", 100.0)
    device.receive(_xbus(0x30), whole=True)
    config = struct.pack(">HH", 0x2010 | bits, 100) + struct.pack(">HH", 0x4020, 100)
    device.receive(_xbus(0xC0, config), whole=True)
    device.receive(_xbus(0x10), whole=True)
    block = Samples(np.arange(3) * 10_000_000, np.tile([0.0, 0.0, -G], (3, 1)), np.zeros((3, 3)),
                    quat=np.tile([1.0, 0.0, 0.0, 0.0], (3, 1)), euler=np.zeros((3, 3)))
    packets = firmware_protocols.create_decoder("xsens-mtdata2").feed(b"".join(device.output(block, i)
                                                                               for i in range(3)))
    assert len(packets) == 3
    for packet in packets:
        assert packet.fields["frame"] == setting
        np.testing.assert_allclose(packet.fields["accel"], (0.0, 0.0, G), rtol=1e-7)
        w, x, y, z = packet.fields["quat"]
        rpy = Rotation.from_quat([x, y, z, w]).as_euler("ZYX", degrees=True)[::-1]
        np.testing.assert_allclose(np.mod(rpy - XSENS_RPY[setting] + 180.0, 360.0) - 180.0, 0.0, atol=1e-4)


# --- the sensor's errors are drawn in its own axes (issue 24) --------------------------------------

# The moving scene with every random error term of the IMU, one seed: the draws belong to the part's
# forward-right-down axes, so the ENU scene's noise is the NED scene's seen in forward-left-up axes. Per-axis
# magnitudes keep their axis (y is the part's lateral axis in both habits); signed vectors of the scene
# (a constant bias, a mounting, a lever arm) are in the scene's axes, as the lever arm above.
ERRORS = (DATA / "random_errors.toml").read_text()
ERROR_EFFECTS = "noise = true\nbias_instability = true\nrandom_walk = true\nbias = true\nvibration = true\n"


def _with_errors(text: str) -> str:
    """`text` (a scene ending in its [effects] table) with a seed, ERRORS' tables added to its one IMU and
    ERROR_EFFECTS on."""
    scene, _, imu = text.partition("[[imu]]")
    imu, _, effects_table = imu.partition("[effects]")
    return (scene.replace("[scene]\n", "[scene]\nseed = 2024\n") + "[[imu]]" + imu + ERRORS + "\n[effects]"
            + effects_table + ERROR_EFFECTS)


@pytest.fixture(scope="module")
def noisy(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("noisy")
    return {frame: _simulate(tmp, _with_errors(text), frame, increments=2) for frame, text in SCENES.items()}


def test_enu_and_ned_scenes_with_random_errors_give_the_same_bytes_on_every_wire(noisy):
    """Noise, bias instability (flicker poles and a Gauss-Markov bias), random walk, turn-on bias and random
    vibration (linear and angular PSD lines) with one seed: the same forward-right-down samples, to the last bit,
    and the same bytes on every wire (the attitude, turned by the angular vibration, compared as above)."""
    frd = {frame: _stream_samples(scene, block, 0, device=True) for frame, (scene, block) in noisy.items()}
    (_, enu), (_, ned) = noisy["ENU"], noisy["NED"]
    # the errors are there: the realized biases are far from 0 and differ per axis
    assert np.all(np.abs(ned.truth["gyro_bias"][0]).max(axis=0) > 1e-4)
    for name in ("accel", "gyro", "delta_theta", "delta_velocity"):
        np.testing.assert_array_equal(getattr(frd["ENU"], name), getattr(frd["NED"], name), err_msg=name)
    # the realized biases too, the scene's axes being FLU and FRD
    for name in ("gyro_bias", "accel_bias"):
        np.testing.assert_array_equal(enu.truth[name] * [1.0, -1.0, -1.0], ned.truth[name], err_msg=name)
    angle = (Rotation.from_quat(frd["ENU"].quat[:, [1, 2, 3, 0]]).inv()
             * Rotation.from_quat(frd["NED"].quat[:, [1, 2, 3, 0]])).magnitude()
    assert angle.max() < 1e-12
    sensors = {frame: dataclasses.replace(samples, quat=None, euler=None, attitude_change=None)
               for frame, samples in frd.items()}
    different = [name for name in firmware_protocols.formats()
                 if _wire(name, sensors["ENU"]) != _wire(name, sensors["NED"])]
    assert not different, f"ENU and NED scenes differ on {different}"
    # MAVLink HIL_SENSOR through pymavlink: the NED scene's values (FRD already), decoded
    data = firmware_protocols.create_encoder("mavlink-hil-sensor").encode(sensors["ENU"]).data
    messages = mavlink2.MAVLink(None).parse_buffer(data)
    got = np.array([(m.xgyro, m.ygyro, m.zgyro) for m in messages])
    np.testing.assert_allclose(got, ned.gyro[0], rtol=1e-7, atol=1e-9)


NOISE_ONLY = """
[scene]
rate_hz = 400
duration_s = 50.0
frame = "{frame}"
seed = 11

[trajectory]
shape = "static"
position_m = [0.0, 0.0, 0.0]

[[imu]]
name = "imu0"

[imu.gyro]
noise_density = [0.001, 0.002, 0.004]

[imu.accel]
noise_density = [0.003, 0.0005, 0.0015]

[effects]
noise = true
"""


@pytest.fixture(scope="module")
def noise_only(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("noise")
    return {frame: _simulate(tmp, NOISE_ONLY.format(frame=frame), frame) for frame in ("ENU", "NED")}


def test_per_axis_noise_densities_apply_to_the_parts_axes(noise_only):
    """README "Sensor errors": a density given per axis x, y, z is the part's forward, lateral and vertical axis
    in any scene frame, and the draws are the FRD axes' stream: the NED scene's gyro y at rest is
    +N_y sqrt(f_s) times the stream "noise.gyro.y" (counter_rng, keyed by seed, IMU, name), the ENU scene's the
    negative of it. Each axis' sample variance against N^2 f_s within the chi-square interval (n - 1 degrees of
    freedom, two-sided 1e-4), on the wire's FRD axes."""
    from scipy.stats import chi2

    from imu_emulator.numerics.counter_rng import normals, stream_key
    rate = 400.0
    densities = {"gyro": np.array([0.001, 0.002, 0.004]), "accel": np.array([0.003, 0.0005, 0.0015])}
    for frame, (scene, block) in noise_only.items():
        n = scene.n_samples
        frd = _stream_samples(scene, block, 0)
        for triad in ("gyro", "accel"):
            values = getattr(frd, triad)
            for axis, name in enumerate("xyz"):
                draws = normals(np.uint64(stream_key(11, 0, f"noise.{triad}.{name}")), 0, n)
                np.testing.assert_array_equal(values[:, axis], densities[triad][axis] * np.sqrt(rate) * draws)
                sign = -1.0 if frame == "ENU" and axis else 1.0
                np.testing.assert_array_equal(getattr(block, triad)[0][:, axis], sign * values[:, axis])
                var = np.var(values[:, axis], ddof=1)
                want = densities[triad][axis] ** 2 * rate
                lo, hi = chi2.ppf([5e-5, 1 - 5e-5], n - 1) / (n - 1)
                assert lo < var / want < hi, (frame, triad, name, var / want)
