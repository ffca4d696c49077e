"""The DroneCAN GNSS/compass/baro node: air_data.StaticPressure / StaticTemperature and gnss.Fix2 byte for byte as
pydronecan (the `dronecan` package) encodes the same values, decoded back equal to the Samples, and read the way
ArduPilot's drivers read them.

ArduPilot, transcribed (ArduPilot/ardupilot):
- libraries/AP_Baro/AP_Baro_DroneCAN.cpp (commit 19351d4b5aeb1b2614201487afd7fafc136073c0): handle_pressure()
  creates the backend for a node (get_dronecan_backend(..., create_new=true)) and accumulates static_pressure in
  Pa; handle_temperature() looks the node up with create_new=false (a temperature before any pressure is
  dropped) and stores KELVIN_TO_C(static_temperature).
- libraries/AP_Compass/AP_Compass_DroneCAN.cpp (commit ee0da68ca14c90d923bbb28406c65b736c3932e2):
  handle_magnetic_field_2() looks the compass up by (node, sensor_id); handle_mag_msg(): raw_field =
  magnetic_field_ga * 1000 (mGauss).
- libraries/AP_GPS/AP_GPS_DroneCAN.cpp (commit 00bc48841c2292adefdc6b536344d3da0eb9018c) handle_fix2_msg():
  status 2 -> 2D, 3 -> 3D (else NO_FIX, nothing used); loc.lat = latitude_deg_1e8 / 10, lng likewise (integer
  division), alt_amsl_cm = height_msl_mm / 10; velocity = ned_velocity; with covariance.len == 6:
  horizontal_accuracy = sqrt(cov[0]), vertical_accuracy = sqrt(cov[2]), speed_accuracy = sqrt((cov[3] + cov[4] +
  cov[5]) / 3); num_sats = sats_used; without an Auxiliary message hdop = vdop = pdop * 100; with
  gnss_time_standard UTC, gnss_timestamp (us since 1970) gives GPS week and ms of week.
"""
import math

import dronecan
import numpy as np
import pytest
from dronecan.transport import Frame, Transfer

from firmware_protocols import registry
from firmware_protocols.base import EncodeError, Samples, frame_bytes
from firmware_protocols.wire_formats.dronecan_sensors import (Fix2Encoder, GnssCompassBaroEncoder,
                                                              StaticPressureEncoder, StaticTemperatureEncoder)

EQ = dronecan.uavcan.equipment
T0 = 1_700_000_000 * 10**9
UNIX_TO_GPS_MS = 315_964_800_000 - 18_000      # GPS epoch in Unix ms, less the 18 leap seconds (ArduPilot's offset)


def transfers(frames):
    """Frame rows -> [(sample, pydronecan Transfer)] in order, each reassembled and CRC-checked by pydronecan."""
    out, pending = [], {}
    for f in frames:
        can_id = int(f["can_id"])
        pending.setdefault(can_id, []).append(Frame(can_id, bytearray(frame_bytes(f)), canfd=bool(f["fd"])))
        if frame_bytes(f)[-1] & 0x40:
            t = Transfer()
            t.from_frames(pending.pop(can_id))
            out.append((int(f["sample"]), t))
    assert not pending
    return out


def oracle(payload, node_id=42, transfer_id=0, priority=31, fd=False):
    t = Transfer(payload=payload, source_node_id=node_id, transfer_id=transfer_id, transfer_priority=priority,
                 canfd=fd)
    return [(t.message_id, bytes(f.bytes)) for f in t.to_frames()]


def ours(frames):
    return [(int(f["can_id"]), frame_bytes(f)) for f in frames]


def head(n=100, rate_hz=100.0, gnss_every=20, seed=4):
    rng = np.random.default_rng(seed)
    t = T0 + (np.arange(n) * 1e9 / rate_hz).astype(np.int64)
    fix_at = np.repeat(np.arange(0, n, gnss_every), gnss_every)[:n]
    llh = np.column_stack([rng.uniform(-80, 80, n), rng.uniform(-180, 180, n), rng.uniform(-100, 4000, n)])
    return Samples(t, np.zeros((n, 3)), np.zeros((n, 3)), mag=rng.normal(0, 0.4, (n, 3)),
                   pressure_pa=rng.normal(90000, 2000, n), temperature_c=rng.normal(10, 15, n),
                   gnss_llh=llh[fix_at], gnss_velocity_ned=rng.normal(0, 10, (n, 3))[fix_at],
                   gnss_fix=np.full(n, 3.0), gnss_satellites=np.full(n, 21.0), gnss_hdop=np.full(n, 0.8),
                   gnss_vdop=np.full(n, 1.1), gnss_horizontal_accuracy_m=np.full(n, 0.9),
                   gnss_vertical_accuracy_m=np.full(n, 1.6), gnss_speed_accuracy_mps=np.full(n, 0.12),
                   gnss_new=(np.arange(n) % gnss_every == 0).astype(float),
                   gnss_age_s=0.05 + (np.arange(n) - fix_at) / rate_hz)


# --- byte for byte against pydronecan -----------------------------------------------------------

@pytest.mark.parametrize("fd", [False, True])
def test_static_pressure_and_temperature_byte_for_byte(fd):
    block = head(n=3)
    pressure = StaticPressureEncoder(pressure_variance_pa2=4.0, fd=fd, transfer_id=7).encode(block)
    temperature = StaticTemperatureEncoder(temperature_variance_k2=0.25, fd=fd, node_id=9).encode(block)
    for i in range(3):
        assert ours(pressure[pressure["sample"] == i]) == oracle(
            EQ.air_data.StaticPressure(static_pressure=block.pressure_pa[i], static_pressure_variance=4.0),
            transfer_id=7 + i, fd=fd)
        assert ours(temperature[temperature["sample"] == i]) == oracle(
            EQ.air_data.StaticTemperature(static_temperature=block.temperature_c[i] + 273.15,
                                          static_temperature_variance=0.25), node_id=9, transfer_id=i, fd=fd)


def expected_fix2(block, i):
    """The Fix2 the DSDL asks for, built from the Samples by hand (units per 1063.Fix2.uavcan)."""
    usec = (int(block.time_ns[i]) - round(block.gnss_age_s[i] * 1e9)) // 1000
    lat, lon, h = block.gnss_llh[i]
    h2, v2, s2 = (block.gnss_horizontal_accuracy_m[i] ** 2, block.gnss_vertical_accuracy_m[i] ** 2,
                  block.gnss_speed_accuracy_mps[i] ** 2)
    fix = EQ.gnss.Fix2(gnss_time_standard=2, num_leap_seconds=18,
                       longitude_deg_1e8=round(lon * 1e8), latitude_deg_1e8=round(lat * 1e8),
                       height_ellipsoid_mm=round(h * 1000), height_msl_mm=round(h * 1000),
                       ned_velocity=list(block.gnss_velocity_ned[i]), sats_used=21, status=3, mode=0, sub_mode=0,
                       covariance=[h2, h2, v2, s2, s2, s2], pdop=math.hypot(0.8, 1.1))
    fix.timestamp.usec = fix.gnss_timestamp.usec = usec
    return fix


@pytest.mark.parametrize("fd, per_fix", [(False, 10), (True, 1)])     # 62 bytes + CRC: 10 classic frames; 1 FD
def test_fix2_byte_for_byte_on_new_solutions_only(fd, per_fix):
    block = head()
    frames = Fix2Encoder(transfer_id=30, fd=fd).encode(block)
    new = np.flatnonzero(block.gnss_new)
    assert sorted(set(frames["sample"].tolist())) == new.tolist()
    for k, i in enumerate(new):
        assert ours(frames[frames["sample"] == i]) == oracle(expected_fix2(block, i), transfer_id=(30 + k) % 32,
                                                             fd=fd)
    assert len(frames) == per_fix * len(new)


# --- what ArduPilot makes of the node -----------------------------------------------------------

def test_ardupilot_reads_the_node_as_compass_baro_and_gps_equal_to_the_samples():
    block = head()
    k = np.arange(len(block))
    # a 50 Hz magnetometer and a 20 Hz barometer on the 100 Hz samples: new readings every 2nd and 5th sample
    block.mag_new, block.baro_new = (k % 2 == 0).astype(float), (k % 5 == 0).astype(float)
    frames = GnssCompassBaroEncoder(node_id=55).encode(block)
    baro_nodes, compass, baro, gps = set(), [], [], []
    for sample, t in transfers(frames):
        msg = t.payload
        kind = msg._type.full_name
        if kind == "uavcan.equipment.air_data.StaticPressure":
            baro_nodes.add(t.source_node_id)                    # create_new = true
            baro.append((sample, "pressure", msg.static_pressure))
        elif kind == "uavcan.equipment.air_data.StaticTemperature":
            assert t.source_node_id in baro_nodes                # else ArduPilot would drop it
            baro.append((sample, "temperature", msg.static_temperature - 273.15))
        elif kind == "uavcan.equipment.ahrs.MagneticFieldStrength2":
            compass.append((sample, msg.sensor_id, [v * 1000 for v in msg.magnetic_field_ga]))
        elif kind == "uavcan.equipment.gnss.Fix2":
            assert msg.status in (2, 3) and len(msg.covariance) == 6
            cov = [float(c) for c in msg.covariance]
            gps.append((sample, dict(lat=int(msg.latitude_deg_1e8 / 10), lng=int(msg.longitude_deg_1e8 / 10),
                                     alt_cm=int(msg.height_msl_mm / 10), vel=list(msg.ned_velocity),
                                     h_acc=math.sqrt(cov[0]), v_acc=math.sqrt(cov[2]),
                                     s_acc=math.sqrt(sum(cov[3:6]) / 3), sats=msg.sats_used,
                                     hdop=msg.pdop * 100,
                                     week_ms=(msg.gnss_timestamp.usec // 1000 - UNIX_TO_GPS_MS) % 604_800_000)))
        else:
            raise AssertionError(kind)
    assert {s for s, _, _ in compass} == set(range(0, 100, 2))           # 50 Hz of a 100 Hz stream
    assert len(baro) == 2 * 20 and [k for _, k, _ in baro[:2]] == ["pressure", "temperature"]
    for sample, _, field_mgauss in compass:
        assert np.allclose(field_mgauss, block.mag[sample] * 1000, rtol=2**-10, atol=1e-3)   # float16
    for sample, kind, value in baro:
        if kind == "pressure":
            assert value == pytest.approx(block.pressure_pa[sample], rel=2**-23)
        else:   # float16 kelvin: 0.125 K steps near 300 K
            assert abs(value - block.temperature_c[sample]) <= 0.125
    assert [s for s, _ in gps] == list(range(0, 100, 20))
    for sample, g in gps:
        lat, lon, h = block.gnss_llh[sample]
        assert abs(g["lat"] - lat * 1e7) <= 1 and abs(g["lng"] - lon * 1e7) <= 1
        assert abs(g["alt_cm"] - h * 100) <= 1
        assert np.allclose(g["vel"], block.gnss_velocity_ned[sample], rtol=2**-23)
        assert g["h_acc"] == pytest.approx(0.9, rel=2e-3) and g["v_acc"] == pytest.approx(1.6, rel=2e-3)
        assert g["s_acc"] == pytest.approx(0.12, rel=2e-3) and g["sats"] == 21
        assert g["hdop"] == pytest.approx(100 * math.hypot(0.8, 1.1), rel=1e-3)
        # GPS time of week of the fix's time of validity (2023-11-14 22:13:20 UTC + 18 s is Tuesday 22:13:38)
        validity_ms = (int(block.time_ns[sample]) - round(block.gnss_age_s[sample] * 1e9)) // 10**6
        assert g["week_ms"] == (validity_ms + 18_000 - 315_964_800_000) % 604_800_000


def test_absent_sensors_are_not_sent_and_our_decoder_reads_the_rest():
    block = head(n=10)
    block.pressure_pa = None
    block.gnss_llh = None
    frames = registry.create_encoder("dronecan-gnss-compass-baro").encode(block)
    sent = [t.payload for _, t in transfers(frames)]
    # no pressure: no temperature either; the receiver reports without a position, as "no fix"
    assert {m._type.full_name for m in sent} == {"uavcan.equipment.ahrs.MagneticFieldStrength2",
                                                "uavcan.equipment.gnss.Fix2"}
    assert {m.status for m in sent if m._type.full_name.endswith("Fix2")} == {0}
    full = head(n=40)
    packets = registry.get("dronecan-gnss-compass-baro").decoder().feed_frames(
        registry.create_encoder("dronecan-gnss-compass-baro").encode(full))
    fixes = [p.fields for p in packets if p.kind == "uavcan.equipment.gnss.Fix2"]
    assert len(fixes) == 2 and fixes[1]["llh"][0] == pytest.approx(full.gnss_llh[20, 0], abs=1e-8)
    temps = [p.fields["temperature_c"] for p in packets if p.kind.endswith("StaticTemperature")]
    assert np.allclose(temps, full.temperature_c, atol=0.125)


def test_fix2_without_a_fix_and_out_of_range_values():
    block = head(n=1)
    block.gnss_fix[:] = 0
    block.gnss_satellites[:] = 99                      # uint6: saturates at 63, counted
    block.gnss_velocity_ned[0, 1] = -1e39              # beyond float32: the largest float32, counted, never inf
    block.gnss_llh[0, 2] = 1e6                         # int27 mm: +-67 km
    encoder = Fix2Encoder()
    ((_, t),) = transfers(encoder.encode(block))
    assert t.payload.status == 0 and t.payload.sats_used == 63
    assert t.payload.ned_velocity[1] == -float(np.finfo(np.float32).max)
    assert t.payload.height_ellipsoid_mm == 2**26 - 1
    assert encoder.saturated.counts == {"sats_used": 1, "ned_velocity": 1, "height_ellipsoid_mm": 1}


@pytest.mark.parametrize("name, flag", [("dronecan-mag2", "mag_new"), ("dronecan-static-pressure", "baro_new"),
                                        ("dronecan-static-temperature", "baro_new")])
def test_standalone_compass_and_baro_messages_only_on_new_readings(name, flag):
    """Streamed alone, a compass or baro message goes out at its sensor's new readings (a 25 Hz sensor on 100 Hz
    samples: every 4th), one transfer each with consecutive transfer ids, carrying that sample's value."""
    block = head()
    setattr(block, flag, (np.arange(len(block)) % 4 == 0).astype(float))
    frames = registry.create_encoder(name).encode(block)
    got = transfers(frames)
    assert [k for k, _ in got] == list(range(0, 100, 4))
    assert [t.transfer_id for _, t in got] == [k % 32 for k in range(25)]
    for k, t in got:
        msg = t.payload
        if flag == "mag_new":
            assert list(msg.magnetic_field_ga) == list(np.asarray(block.mag[k], np.float16).astype(float))
        elif name.endswith("pressure"):
            assert msg.static_pressure == float(np.float32(block.pressure_pa[k]))
        else:
            assert msg.static_temperature == float(np.float16(block.temperature_c[k] + 273.15))


@pytest.mark.parametrize("make, needle", [
    (lambda: StaticPressureEncoder(pressure_variance_pa2=-1.0), "pressure_variance_pa2: a number 0..65504"),
    (lambda: GnssCompassBaroEncoder(baro_rate_hz=5.0), r"baro_rate_hz: retired; .*\[imu.barometer\] rate_hz"),
    (lambda: GnssCompassBaroEncoder(mag_rate_hz=5.0), r"mag_rate_hz: retired; .*\[imu.magnetometer\] rate_hz"),
    (lambda: GnssCompassBaroEncoder(node_id=0), "node_id must be 1..127"),
])
def test_bad_options_are_one_line_errors(make, needle):
    with pytest.raises(ValueError, match=needle):
        make()


def test_non_finite_fix_is_named():
    block = head(n=45)
    block.gnss_velocity_ned[40, 2] = np.nan          # sample 40 carries a new solution
    with pytest.raises(EncodeError, match="'gnss_velocity_ned' at sample 40, component 2"):
        Fix2Encoder().encode(block)


def test_node_device_announces_itself_and_publishes_at_each_sensor_rate():
    device = registry.get("dronecan-gnss-compass-baro").device(100.0, node_id=60)
    block = head()
    block.baro_new = (np.arange(len(block)) % 10 == 0).astype(float)      # a 10 Hz barometer
    frames = np.concatenate([device.output(block, i) for i in range(100)])
    kinds = [t.payload._type.full_name for _, t in transfers(frames)]
    assert kinds.count("uavcan.protocol.NodeStatus") == 1
    assert kinds.count("uavcan.equipment.air_data.StaticPressure") == 10
    assert kinds.count("uavcan.equipment.gnss.Fix2") == 5
    assert kinds.count("uavcan.equipment.ahrs.MagneticFieldStrength2") == 100
