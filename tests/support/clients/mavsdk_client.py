"""MAVSDK (its own C++ core, via the `mavsdk` wheel) as a ground station on a UDP port: run as a separate
process by tests/firmware_protocols/devices/test_device_mavlink.py. Prints one JSON line: discovery, connection, IMU telemetry
counted over two windows, before and after `set_rate_imu`."""
import asyncio
import json
import sys
import time


async def main(port: int, new_rate: float, window_s: float) -> dict:
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
    out = {}
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        print("listening", flush=True)
        end = time.monotonic() + 20
        systems = []
        while not systems and time.monotonic() < end:
            systems = await mavsdk.get_systems()
            await asyncio.sleep(0.1)
        if not systems:
            return {"discovered": False}
        system = systems[0]
        out["discovered"] = True
        out["sysid"] = await system.get_system_id()
        while not await system.is_connected() and time.monotonic() < end:
            await asyncio.sleep(0.1)
        out["connected"] = await system.is_connected()
        telemetry = TelemetryAsync(system)

        async def count(seconds):
            samples = []
            stream = telemetry.subscribe_imu()
            stop = time.monotonic() + seconds
            try:
                while time.monotonic() < stop:
                    try:
                        imu = await asyncio.wait_for(stream.__anext__(), timeout=max(0.01, stop - time.monotonic()))
                    except asyncio.TimeoutError:
                        break
                    a, w = imu.acceleration_frd, imu.angular_velocity_frd
                    samples.append([imu.timestamp_us, a.forward_m_s2, a.right_m_s2, a.down_m_s2,
                                    w.forward_rad_s, w.right_rad_s, w.down_rad_s])
            finally:
                await stream.aclose()
            return samples

        out["before"] = await count(window_s)
        try:
            await telemetry.set_rate_imu(new_rate)
            out["set_rate"] = "ok"
        except Exception as exc:      # the result MAVSDK reports is what the test checks
            out["set_rate"] = f"{type(exc).__name__}: {exc}"
        await asyncio.sleep(0.3)
        out["after"] = await count(window_s)
    return out


if __name__ == "__main__":
    result = asyncio.run(main(int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])))
    print(json.dumps(result), flush=True)
