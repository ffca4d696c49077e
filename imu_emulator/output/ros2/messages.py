"""The ROS 2 messages a bag holds, each as its definition (MCAP's "ros2msg" schema text: the type, then every
type it uses after a separator line, as rosbag2 writes it) and its CDR layout for one topic (cdr.Layout: the
frame ids are the topic's constants). Field order and types are those of the ROS 2 Humble message files
(sensor_msgs, nav_msgs, geometry_msgs, tf2_msgs, std_msgs, builtin_interfaces); tests/output/test_output_ros2_cdr.py
checks every layout byte for byte against rosbags' serializer.
"""
from __future__ import annotations

import numpy as np

from imu_emulator.output.ros2.cdr import Layout

_SEP = "=" * 80
_TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
_QUAT = "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
_VEC = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
_POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"


def _definition(main: str, *uses: str) -> str:
    return main + "".join(f"{_SEP}\n{d}" for d in uses)


IMU = "sensor_msgs/msg/Imu"
ODOMETRY = "nav_msgs/msg/Odometry"
NAVSATFIX = "sensor_msgs/msg/NavSatFix"
MAGNETIC_FIELD = "sensor_msgs/msg/MagneticField"
FLUID_PRESSURE = "sensor_msgs/msg/FluidPressure"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

DEFINITIONS = {
    IMU: _definition(
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n"
        "geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n"
        "geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n",
        _HEADER, _TIME, _QUAT, _VEC),
    ODOMETRY: _definition(
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
        "geometry_msgs/TwistWithCovariance twist\n",
        _HEADER, _TIME,
        "MSG: geometry_msgs/PoseWithCovariance\ngeometry_msgs/Pose pose\nfloat64[36] covariance\n",
        "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
        _POINT, _QUAT,
        "MSG: geometry_msgs/TwistWithCovariance\ngeometry_msgs/Twist twist\nfloat64[36] covariance\n",
        "MSG: geometry_msgs/Twist\ngeometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n", _VEC),
    NAVSATFIX: _definition(
        "std_msgs/Header header\nsensor_msgs/NavSatStatus status\nfloat64 latitude\nfloat64 longitude\n"
        "float64 altitude\nfloat64[9] position_covariance\nuint8 position_covariance_type\n",
        _HEADER, _TIME, "MSG: sensor_msgs/NavSatStatus\nint8 status\nuint16 service\n"),
    MAGNETIC_FIELD: _definition(
        "std_msgs/Header header\ngeometry_msgs/Vector3 magnetic_field\nfloat64[9] magnetic_field_covariance\n",
        _HEADER, _TIME, _VEC),
    FLUID_PRESSURE: _definition(
        "std_msgs/Header header\nfloat64 fluid_pressure\nfloat64 variance\n", _HEADER, _TIME),
    TF_MESSAGE: _definition(
        "geometry_msgs/TransformStamped[] transforms\n",
        "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\n"
        "geometry_msgs/Transform transform\n", _HEADER, _TIME,
        "MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
        _VEC, _QUAT),
}

# sensor_msgs/NavSatStatus and NavSatFix constants
STATUS_NO_FIX, STATUS_FIX = -1, 0
SERVICE_GPS = 1
COVARIANCE_TYPE_UNKNOWN, COVARIANCE_TYPE_DIAGONAL_KNOWN, COVARIANCE_TYPE_KNOWN = 0, 2, 3


def _header(layout: Layout, frame_id: str) -> Layout:
    return layout.field("sec", "<i4").field("nanosec", "<u4").string(frame_id)


def imu(frame_id: str, orientation_covariance, gyro_covariance, accel_covariance) -> Layout:
    """sensor_msgs/Imu; the covariances (9 each, row major) are the topic's constants."""
    return (_header(Layout(), frame_id).field("orientation", "<f8", 4)
            .constant("<f8", orientation_covariance).field("angular_velocity", "<f8", 3)
            .constant("<f8", gyro_covariance).field("linear_acceleration", "<f8", 3)
            .constant("<f8", accel_covariance))


def odometry(frame_id: str, child_frame_id: str) -> Layout:
    """nav_msgs/Odometry with covariances unknown (zeros): the truth."""
    return (_header(Layout(), frame_id).string(child_frame_id).field("position", "<f8", 3)
            .field("orientation", "<f8", 4).constant("<f8", np.zeros(36)).field("linear", "<f8", 3)
            .field("angular", "<f8", 3).constant("<f8", np.zeros(36)))


def navsatfix_truth(frame_id: str) -> Layout:
    """sensor_msgs/NavSatFix of the truth: always a fix, covariance known to be zero."""
    return (_header(Layout(), frame_id).constant("i1", STATUS_FIX).constant("<u2", 0)
            .field("position", "<f8", 3).constant("<f8", np.zeros(9)).constant("u1", COVARIANCE_TYPE_KNOWN))


def navsatfix_measured(frame_id: str, covariance_type: int = COVARIANCE_TYPE_DIAGONAL_KNOWN) -> Layout:
    """sensor_msgs/NavSatFix of a GNSS receiver: its status and a diagonal covariance from its accuracy (zeros
    with COVARIANCE_TYPE_UNKNOWN when it states none)."""
    return (_header(Layout(), frame_id).field("status", "i1").constant("<u2", SERVICE_GPS)
            .field("position", "<f8", 3).field("position_covariance", "<f8", 9)
            .constant("u1", covariance_type))


def magnetic_field(frame_id: str) -> Layout:
    """sensor_msgs/MagneticField in tesla; covariance all zeros = unknown, as the message defines it."""
    return _header(Layout(), frame_id).field("magnetic_field", "<f8", 3).constant("<f8", np.zeros(9))


def fluid_pressure(frame_id: str) -> Layout:
    """sensor_msgs/FluidPressure in pascal; variance 0 = unknown."""
    return _header(Layout(), frame_id).field("fluid_pressure", "<f8").constant("<f8", 0.0)


def tf_message(parent: str, children: list[str]) -> Layout:
    """tf2_msgs/TFMessage holding one transform per child, all from `parent`; fields "sec{i}", "nanosec{i}",
    "translation{i}", "rotation{i}" (x, y, z, w)."""
    layout = Layout().constant("<u4", len(children))
    for i, child in enumerate(children):
        (layout.field(f"sec{i}", "<i4").field(f"nanosec{i}", "<u4").string(parent).string(child)
         .field(f"translation{i}", "<f8", 3).field(f"rotation{i}", "<f8", 4))
    return layout
