"""Real SocketCAN, on a host kernel without it: boot User Mode Linux with the host's root as its root
(hostfs, so this very virtualenv runs inside), load can/can-raw/can-dev/vcan, and run tests/live/socketcan there."""
import sys

import pytest

from tests.support.paths import UML

sys.path.insert(0, str(UML))
import boot as uml  # noqa: E402

pytestmark = [pytest.mark.uml, pytest.mark.subprocess, pytest.mark.slow]


def test_socketcan_suite_inside_user_mode_linux(tmp_path):
    reason = uml.unavailable()
    if reason:
        pytest.skip(reason)
    result = uml.boot(tmp_path / "uml")
    if not result.booted:
        pytest.skip(result.output)
    assert result.exit_code is not None, f"the guest booted but did not finish the tests:\n{result.output}"
    assert result.exit_code == 0, f"socketcan tests inside User Mode Linux failed (exit {result.exit_code}):\n{result.output}"
    assert " passed" in result.output and "skipped" not in result.output, result.output
