"""ArduPilot's own Copter SITL with its own physics and sensors (no emulator): when its EKF3 becomes healthy, by
the same definition the reports use (sitl_report.ekf_healthy). The baseline for the JSON backend's time to EKF
healthy: what ArduPilot takes on its own simulated sensors, standing still at the same home.

    .venv/bin/python tools/interop/ardupilot_stock_sitl.py --arducopter ARDUPILOT/build/sitl/bin/arducopter \
        --defaults ARDUPILOT/Tools/autotest/default_params/copter.parm [--seconds 80]

Prints each STATUSTEXT and the first healthy EKF_STATUS_REPORT, in seconds since SITL was started.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import sitl_report  # noqa: E402
from ardupilot_sitl_run import connect  # noqa: E402

#: the home of examples/sitl_flight.toml (its [scene] origin), as the reports' runs use
HOME = "-35.363262,149.165237,584.0,0"


def main(argv=None) -> int:
    from pymavlink import mavutil
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--arducopter", type=Path, required=True)
    p.add_argument("--defaults", type=Path, required=True)
    p.add_argument("--seconds", type=float, default=80.0)
    args = p.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="sitl-stock-"))
    start = time.monotonic()
    sitl = subprocess.Popen([str(args.arducopter), "--wipe", "--speedup", "1", "--model", "quad", "--home", HOME,
                             "--defaults", str(args.defaults)], cwd=work,
                            stdout=open(work / "sitl.log", "w"), stderr=subprocess.STDOUT)
    try:
        link = connect(sitl, work)
        link.mav.command_long_send(link.target_system, link.target_component,
                                   mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, 193, 2e5, 0, 0, 0, 0, 0)
        healthy = None
        while time.monotonic() - start < args.seconds and sitl.poll() is None:
            msg = link.recv_match(type=["STATUSTEXT", "EKF_STATUS_REPORT"], blocking=True, timeout=1)
            now = time.monotonic() - start
            if msg is None:
                continue
            if msg.get_type() == "STATUSTEXT":
                print(f"{now:6.1f} s  {msg.text}", flush=True)
            elif healthy is None and sitl_report.ekf_healthy([msg.flags])[0]:
                healthy = now
                print(f"{now:6.1f} s  EKF healthy (flags {msg.flags:#x})", flush=True)
        print(f"EKF healthy at {healthy:.1f} s after start" if healthy is not None else
              f"EKF not healthy within {args.seconds:g} s")
        return 0
    finally:
        sitl.terminate()
        sitl.wait()


if __name__ == "__main__":
    sys.exit(main())
