"""ROS 2 messages as ddtrack writes and reads them: stamps, headers and planar poses (docs/ros.md).

Everything here is plain data: the message classes come from ``rosbags``' type store of ROS 2 Jazzy, whose
definitions of the standard messages used here (``std_msgs``, ``geometry_msgs``, ``nav_msgs``, ``sensor_msgs``,
``tf2_msgs``) are those of Humble, Iron and Kilted too, so a bag written with them carries the same type hashes.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import numpy as np

#: the frames of an exported run: the world the run started in, and the robot's body at the axle midpoint
WORLD_FRAME = "odom"
BODY_FRAME = "base_link"
#: joint names of the drive wheels, as TurtleBot3's URDF names them
WHEEL_JOINTS = ("wheel_right_joint", "wheel_left_joint")

NANOSECONDS = 1_000_000_000


@cache
def typestore() -> Any:
    """The ROS 2 Jazzy type store (built once: it parses every message definition)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def message(msgtype: str, *args: Any, **kwargs: Any) -> Any:
    """An instance of the ROS message ``msgtype`` (e.g. ``"nav_msgs/msg/Path"``)."""
    return typestore().types[msgtype](*args, **kwargs)


def stamp(nanoseconds: int) -> Any:
    """``builtin_interfaces/msg/Time`` of ``nanoseconds`` since the epoch."""
    seconds, rest = divmod(int(nanoseconds), NANOSECONDS)
    return message("builtin_interfaces/msg/Time", sec=seconds, nanosec=rest)


def header(nanoseconds: int, frame: str) -> Any:
    """``std_msgs/msg/Header`` stamped at ``nanoseconds`` in ``frame``."""
    return message("std_msgs/msg/Header", stamp=stamp(nanoseconds), frame_id=frame)


def stamp_nanoseconds(header_: Any) -> int:
    """The stamp of a message's header, in nanoseconds since the epoch."""
    return int(header_.stamp.sec) * NANOSECONDS + int(header_.stamp.nanosec)


def planar_pose(x: float, y: float, yaw: float) -> Any:
    """``geometry_msgs/msg/Pose`` at (x, y, 0) [m] turned by ``yaw`` [rad] about z."""
    point = message("geometry_msgs/msg/Point", x=float(x), y=float(y), z=0.0)
    return message("geometry_msgs/msg/Pose", position=point, orientation=yaw_quaternion(yaw))


def yaw_quaternion(yaw: float) -> Any:
    """The unit quaternion of a rotation by ``yaw`` [rad] about z."""
    half = 0.5 * float(yaw)
    return message("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=math.sin(half), w=math.cos(half))


def quaternion_yaw(q: Any) -> float:
    """The yaw [rad] in (-pi, pi] of a quaternion (its rotation about z; roll and pitch are ignored)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def twist(v: float, omega: float) -> Any:
    """``geometry_msgs/msg/Twist`` of a planar body: forward speed ``v`` [m/s], yaw rate ``omega`` [rad/s]."""
    return message(
        "geometry_msgs/msg/Twist",
        linear=message("geometry_msgs/msg/Vector3", x=float(v), y=0.0, z=0.0),
        angular=message("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=float(omega)),
    )


def no_covariance() -> np.ndarray:
    """A 6 x 6 covariance of zeros, row-major (a simulated state is known exactly)."""
    return np.zeros(36)
