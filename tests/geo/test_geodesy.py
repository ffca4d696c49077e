"""Tangent-plane positions to geodetic coordinates, against pymap3d (an independent, well-kept implementation)."""
import numpy as np
import pytest

from imu_emulator.geo.geodesy import DEFAULT_ORIGIN, local_to_geodetic, to_ned

pymap3d = pytest.importorskip("pymap3d")


@pytest.mark.parametrize("frame", ["ENU", "NED"])
def test_local_to_geodetic_matches_pymap3d(frame):
    rng = np.random.default_rng(3)
    local = np.vstack([np.zeros(3), rng.normal(0, 5000, (50, 3)), [[1e5, -2e5, 3e3]]])
    got = local_to_geodetic(local, frame)
    for row, (lat, lon, h) in zip(local, got):
        if frame == "ENU":
            want = pymap3d.enu2geodetic(*row, *DEFAULT_ORIGIN)
        else:
            want = pymap3d.ned2geodetic(*row, *DEFAULT_ORIGIN)
        # 1e-9 deg is 0.1 mm; heights to 0.1 mm
        assert abs(lat - want[0]) < 1e-9 and abs(lon - want[1]) < 1e-9 and abs(h - want[2]) < 1e-4


def test_enu_vectors_become_ned():
    np.testing.assert_array_equal(to_ned(np.array([[1.0, 2.0, 3.0]]), "ENU"), [[2.0, 1.0, -3.0]])
