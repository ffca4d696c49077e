"""Companion sensors in a ROS 2 bag: MagneticField (tesla, REP 103 axes), FluidPressure (Pa) and the GNSS
receiver's NavSatFix (one per new solution, covariance from its 1-sigma accuracies), written only when the run has
their columns. The columns come from a synthetic block and layout here (the names the companion effects use:
mag_x mag_y mag_z [gauss, sensor frame], pressure_pa, gnss_lat_deg gnss_lon_deg gnss_h_m, gnss_fix (0 none, 2 2D,
3 3D), gnss_new, gnss_horizontal_accuracy_m, gnss_vertical_accuracy_m); the bag is decoded by rosbags."""
from dataclasses import dataclass

import numpy as np
import pytest

from imu_emulator.output.base import Contents
from imu_emulator.output.columns import Column, Group, Layout
from imu_emulator.output.formats.mcap import McapWriter
from imu_emulator.runtime.samples import SampleBlock
from tests.output.test_output_mcap import DEFAULT_EPOCH_NS, read_bag

KEYS = ("mag", "pressure_pa", "gnss_llh", "gnss_fix", "gnss_new", "gnss_horizontal_accuracy_m",
        "gnss_vertical_accuracy_m")
NAMES = ("mag_x", "mag_y", "mag_z", "pressure_pa", "gnss_lat_deg", "gnss_lon_deg", "gnss_h_m", "gnss_fix",
         "gnss_new", "gnss_horizontal_accuracy_m", "gnss_vertical_accuracy_m")


FLAGS = ("mag_new", "baro_new")     # the companions' new-reading columns: without them, a reading every sample


def _layout(per_imu: bool, flags: bool = False):
    keys, names = (KEYS + FLAGS, NAMES + FLAGS) if flags else (KEYS, NAMES)
    group = Group("companions", per_imu, False, keys, tuple(Column(name, "", name) for name in names))

    @dataclass(frozen=True)
    class WithCompanions(Layout):
        def groups(self):
            return super().groups() + [group]
    return WithCompanions()


def _block(k0, n, n_imu, per_imu, rng):
    shape = (n_imu, n) if per_imu else (n,)
    block = SampleBlock(k0=k0, t_s=(k0 + np.arange(n)) / 100.0, accel=rng.normal(size=(n_imu, n, 3)),
                        gyro=rng.normal(size=(n_imu, n, 3)), quat=None)
    block.mag = rng.normal(size=shape + (3,)) * 0.5
    block.pressure_pa = 101325.0 + rng.normal(size=shape) * 10
    block.gnss_llh = np.stack([45 + rng.normal(size=shape), 7 + rng.normal(size=shape), 300 + rng.normal(size=shape)],
                              axis=-1)
    block.gnss_fix = rng.choice([0.0, 2.0, 3.0], size=shape)
    block.gnss_new = (rng.random(size=shape) < 0.2).astype(float)
    block.gnss_horizontal_accuracy_m = rng.uniform(0.5, 3, size=shape)
    block.gnss_vertical_accuracy_m = rng.uniform(1, 5, size=shape)
    block.mag_new = (rng.random(size=shape) < 0.5).astype(float)
    block.baro_new = (rng.random(size=shape) < 0.25).astype(float)
    return block


@pytest.mark.parametrize("flags", [False, True], ids=["every-sample", "new-readings"])
@pytest.mark.parametrize("per_imu", [True, False])
def test_companion_topics_from_their_columns(tmp_path, per_imu, flags):
    rng = np.random.default_rng(7)
    names = ["a", "b"]
    blocks = [_block(0, 50, 2, per_imu, rng), _block(50, 30, 2, per_imu, rng)]
    path = tmp_path / "c.mcap"
    with McapWriter(path, Contents(names, _layout(per_imu, flags), frame="NED")) as writer:
        for block in blocks:
            writer.write(block)
    topics = read_bag(path)
    sources = names if per_imu else [None]
    prefix = {"a": "/imu/a", "b": "/imu/b", None: ""}
    for m, name in enumerate(sources):
        def column(key):
            return np.concatenate([getattr(b, key)[m] if per_imu else getattr(b, key) for b in blocks])
        ns = DEFAULT_EPOCH_NS + np.arange(80) * 10_000_000
        frame = name or "base_link"
        # with the flag columns, a message per new reading only (a driver publishes at the sensor's rate)
        at_mag = np.flatnonzero(column("mag_new")) if flags else np.arange(80)
        at_baro = np.flatnonzero(column("baro_new")) if flags else np.arange(80)
        assert not flags or (20 < len(at_mag) < 60 and 5 < len(at_baro) < 40)
        mag = topics[f"{prefix[name]}/mag"]
        assert [t for t, _ in mag] == list(ns[at_mag]) and {d.header.frame_id for _, d in mag} == {frame}
        # gauss -> tesla (1 G = 1e-4 T); NED scene: sensor FRD -> FLU negates y and z
        want = column("mag")[at_mag] * 1e-4 * np.array([1.0, -1.0, -1.0])
        np.testing.assert_array_equal([[d.magnetic_field.x, d.magnetic_field.y, d.magnetic_field.z]
                                       for _, d in mag], want)
        assert not any(d.magnetic_field_covariance.any() for _, d in mag)
        pressure = topics[f"{prefix[name]}/pressure"]
        assert [t for t, _ in pressure] == list(ns[at_baro])
        np.testing.assert_array_equal([d.fluid_pressure for _, d in pressure], column("pressure_pa")[at_baro])
        assert {d.variance for _, d in pressure} == {0.0}
        fixes = topics[f"{prefix[name]}/fix" if per_imu else "/gnss/fix"]
        new = np.flatnonzero(column("gnss_new"))
        assert 5 < len(new) < 40
        assert [t for t, _ in fixes] == list(ns[new])
        np.testing.assert_array_equal([[d.latitude, d.longitude, d.altitude] for _, d in fixes],
                                      column("gnss_llh")[new])
        # sensor_msgs/NavSatStatus: STATUS_NO_FIX = -1, STATUS_FIX = 0; SERVICE_GPS = 1
        assert [d.status.status for _, d in fixes] == [-1 if f == 0 else 0 for f in column("gnss_fix")[new]]
        assert {d.status.service for _, d in fixes} == {1}
        assert {d.position_covariance_type for _, d in fixes} == {2}      # COVARIANCE_TYPE_DIAGONAL_KNOWN
        h, v = column("gnss_horizontal_accuracy_m")[new], column("gnss_vertical_accuracy_m")[new]
        np.testing.assert_array_equal([d.position_covariance for _, d in fixes],
                                      [np.diag([hh * hh, hh * hh, vv * vv]).ravel() for hh, vv in zip(h, v)])


def test_no_companion_columns_no_companion_topics(tmp_path):
    rng = np.random.default_rng(8)
    block = SampleBlock(k0=0, t_s=np.arange(5) / 10.0, accel=rng.normal(size=(1, 5, 3)),
                        gyro=rng.normal(size=(1, 5, 3)), quat=None)
    path = tmp_path / "plain.mcap"
    with McapWriter(path, Contents(["a"], Layout(), frame="ENU")) as writer:
        writer.write(block)
    topics = read_bag(path)
    assert set(topics) == {"/imu/a", "/tf_static"}
    # no attitude in the blocks: orientation_covariance[0] = -1, "no orientation estimate"
    assert {d.orientation_covariance[0] for _, d in topics["/imu/a"]} == {-1.0}
