"""MicroStrain's own MSCL (pymscl) configuring the emulated device on a serial port: run as a separate
process by tests/firmware_protocols/devices/test_device_microstrain.py. Prints one JSON line: every step's result (or the exception
MSCL raised) and the data packets received afterwards."""
import json
import sys
import time

import mscl


def main(port: str, rate_hz: int, seconds: float) -> dict:
    out = {}
    connection = mscl.Connection.Serial(port, 921600)
    try:
        node = mscl.InertialNode(connection)
        node.timeout(2000)

        def step(name, call):
            try:
                out[name] = call()
            except Exception as exc:          # the result the test checks
                out[name] = f"error: {type(exc).__name__}: {exc}"

        step("ping", lambda: bool(node.ping()))
        step("idle", lambda: node.setToIdle() or "ok")
        step("model_name", lambda: node.modelName())
        step("model_number", lambda: node.modelNumber())
        step("serial", lambda: node.serialNumber())
        step("firmware", lambda: str(node.firmwareVersion()))
        step("base_rate", lambda: node.getDataRateBase(mscl.MipTypes.CLASS_AHRS_IMU))

        def configure():
            channels = mscl.MipChannels()
            for field in (mscl.MipTypes.CH_FIELD_SENSOR_SCALED_ACCEL_VEC, mscl.MipTypes.CH_FIELD_SENSOR_SCALED_GYRO_VEC):
                channels.append(mscl.MipChannel(field, mscl.SampleRate.Hertz(rate_hz)))
            node.setActiveChannelFields(mscl.MipTypes.CLASS_AHRS_IMU, channels)
            return "ok"

        step("set_format", configure)
        step("read_format", lambda: [(c.channelField(), c.sampleRate().samplesPerSecond())
                                     for c in node.getActiveChannelFields(mscl.MipTypes.CLASS_AHRS_IMU)])
        step("enable", lambda: node.enableDataStream(mscl.MipTypes.CLASS_AHRS_IMU) or "ok")
        node.getDataPackets(0)              # what streamed before the configuration
        step("resume", lambda: node.resume() or "ok")
        packets, end = [], time.monotonic() + seconds
        while time.monotonic() < end:
            for p in node.getDataPackets(100):
                points = {d.channelName(): d for d in p.data()}
                accel = [points[f"scaledAccel{a}"].as_float() for a in "XYZ" if f"scaledAccel{a}" in points]
                packets.append({"set": p.descriptorSet(), "channels": sorted(points), "accel": accel})
        out["packets"] = packets
    finally:
        connection.disconnect()
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]))), flush=True)
