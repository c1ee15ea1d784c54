"""Where ``ddtrack drive`` gets the robot's pose: the odometry topic, or one transform of ``/tf`` (docs/ros.md).

A robot that broadcasts its pose only as a transform (``odom`` -> ``base_footprint`` on ``/tf``) has no twist to
read, so :class:`TfOdometry` differences consecutive poses over their stamps and hands drive a
``nav_msgs/msg/Odometry`` like the one such a robot would publish; the rest of drive (the lockstep on stamps, the
staleness timeout, the controller's BODY vector) then works on either source alike.
"""

from __future__ import annotations

import math
from typing import Any

from .dds import QosProfile
from .export import _odometry
from .messages import NANOSECONDS, planar_pose, quaternion_yaw, stamp_nanoseconds

TF_TOPIC = "/tf"
TF_TYPE = "tf2_msgs/msg/TFMessage"
#: best effort (so it matches a reliable broadcaster too) and keep last 100, as tf2's listener keeps: a busy /tf
#: (every joint of a robot_state_publisher) must not push the one transform drive reads out of the history
TF_QOS = QosProfile(reliable=False, transient_local=False, depth=100)


def _frame(name: str) -> str:
    """A frame id without a leading '/': tf2 refuses one, but older broadcasters still send ``/odom``."""
    return name[1:] if name.startswith("/") else name


class TfOdometry:
    """The odometry of one direct transform ``parent`` -> ``child`` on ``/tf`` (no chained lookup).

    The pose (x, y, yaw) is the transform's; the twist is differenced from the previous transform: v is the
    displacement projected on the mean heading over the stamp difference (the chord of a constant-twist arc lies
    along it, so a unicycle's v comes out within sinc(omega dt / 2)), omega the wrapped yaw difference over it;
    both zero for the first. A transform stamped no later than the previous one is dropped (it adds no time).

    Parameters
    ----------
    parent, child : str
        The frames, e.g. ``odom`` and ``base_footprint`` (a TurtleBot3's).
    """

    def __init__(self, parent: str, child: str) -> None:
        self.parent, self.child = _frame(parent), _frame(child)
        self._last: tuple[int, float, float, float] | None = None  #: stamp [ns], x, y, yaw of the previous pose

    def odometry(self, tf_message: Any) -> list[Any]:
        """The ``nav_msgs/msg/Odometry`` of each matching transform of a ``tf2_msgs/msg/TFMessage``, oldest first
        (an empty list when it carries none)."""
        found = []
        for transform in tf_message.transforms:
            if (_frame(transform.header.frame_id), _frame(transform.child_frame_id)) != (self.parent, self.child):
                continue
            nanoseconds = stamp_nanoseconds(transform.header)
            translation = transform.transform.translation
            x, y, yaw = float(translation.x), float(translation.y), quaternion_yaw(transform.transform.rotation)
            v = omega = 0.0
            if self._last is not None:
                before, x0, y0, yaw0 = self._last
                if nanoseconds <= before:
                    continue
                dt = (nanoseconds - before) / NANOSECONDS
                turn = math.remainder(yaw - yaw0, 2.0 * math.pi)
                heading = yaw0 + 0.5 * turn
                v = ((x - x0) * math.cos(heading) + (y - y0) * math.sin(heading)) / dt
                omega = turn / dt
            self._last = (nanoseconds, x, y, yaw)
            found.append(_odometry(nanoseconds, planar_pose(x, y, yaw), v, omega, self.parent, self.child))
        return found
