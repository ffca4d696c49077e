"""What every test shares: the hypothesis profile, one kernel cache for the session, a private empty cache for
the tests about caching, and time limits scaled to the machine (tests/support/timing.py)."""
import os
from pathlib import Path

import pytest
from hypothesis import settings

# Reproducible property tests in CI: fixed seed, no example database.
settings.register_profile("ci", derandomize=True, database=None, deadline=None, print_blob=True)
# Longer searches on demand (HYPOTHESIS_PROFILE=fuzz, with FUZZ_EXAMPLES=N for tests/scene/test_scene_fuzz.py):
# random seeds, failures printed with a blob to reproduce them.
settings.register_profile("fuzz", database=None, deadline=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def session_cache_root() -> Path:
    """The kernel cache every test (and every process a test starts) shares, unless it asks for a private one:
    kernels are keyed on structure only, so a parameter sweep compiles once, and a second run of the suite finds
    them all. Kept apart from the user's own cache (~/.cache/imu-emulator), which the tests never fill.
    IMU_EMULATOR_TEST_CACHE moves it (CI can keep it between runs)."""
    chosen = os.environ.get("IMU_EMULATOR_TEST_CACHE")
    return Path(chosen) if chosen else Path.home() / ".cache" / "imu-emulator-tests"


def pytest_configure(config):
    # Set here, once, in the controller and in every xdist worker alike (the value does not depend on which):
    # the package reads IMU_EMULATOR_CACHE at each use, and subprocesses inherit it.
    os.environ["IMU_EMULATOR_CACHE"] = str(session_cache_root())


@pytest.fixture(scope="session")
def kernel_cache() -> Path:
    """The session's kernel cache root (IMU_EMULATOR_CACHE), for a test that hands it to a process explicitly."""
    return Path(os.environ["IMU_EMULATOR_CACHE"])


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch) -> Path:
    """A private, empty kernel cache for this test (for tests of compiling and caching themselves), with this
    process's loaded kernels forgotten; returns its kernels directory (not created yet)."""
    from imu_emulator.runtime import kernels as kernel_module
    monkeypatch.setenv("IMU_EMULATOR_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(kernel_module, "_loaded", {})
    return tmp_path / "cache" / "kernels"


def pytest_collection_modifyitems(config, items):
    # Tests that pace, sleep, compare CPU times or start a live stream share one xdist group, so --dist loadgroup
    # runs them one after another in one worker. A streaming emulator's sender spins at SCHED_FIFO ("auto"): two
    # at once on two cores starve every normal thread, their own SIGINT handling included (seen: an emulator not
    # stopping within 10 s of SIGINT). The other worker runs the ordinary tests beside them, and the processes
    # that stream nothing (generate, align, a wheel's install, the docs build): one group of everything that
    # starts a process kept one worker busy for most of the run.
    for item in items:
        if any(item.get_closest_marker(name) for name in ("realtime", "uml", "streams")):
            item.add_marker(pytest.mark.xdist_group("realtime"))
