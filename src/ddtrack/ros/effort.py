"""Wheel torques to a ros2_control effort controller, for ``ddtrack drive --effort-topic`` (docs/ros.md).

No standard ROS 2 topic carries a base's wheel torques, but ros2_control's
``effort_controllers/JointGroupEffortController`` takes one ``std_msgs/msg/Float64MultiArray`` per period on
``/<controller>/commands``, one effort [N m] per joint in the order of its ``joints`` parameter. A torque-output law
(e.g. backstepping over computed torque) can so drive a real or simulated robot; its (tau_r, tau_l) are reordered
here to that joint order and clamped to the scenario's torque limit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ConfigError
from .messages import message

EFFORT_TYPE = "std_msgs/msg/Float64MultiArray"
#: the joint order of the controller's ``joints`` parameter, TurtleBot-style names by default
DEFAULT_JOINTS = ("wheel_left_joint", "wheel_right_joint")


def wheel_sides(joints: tuple[str, ...]) -> tuple[int, int]:
    """The indices of the (right, left) wheels in ``joints``, read from the names (one holding ``right``, the other
    ``left``): the controller takes efforts in its own joint order, and a swapped pair would turn the robot the
    wrong way, so a name that says neither side is refused rather than guessed."""
    names = [joint.lower() for joint in joints]
    right = [i for i, name in enumerate(names) if "right" in name and "left" not in name]
    left = [i for i, name in enumerate(names) if "left" in name and "right" not in name]
    if len(joints) != 2 or len(right) != 1 or len(left) != 1:
        raise ConfigError(
            "--joints",
            f"'{','.join(joints)}' is not two joints, one named right and one left: give the controller's joints "
            "parameter in its order, e.g. wheel_left_joint,wheel_right_joint",
        )
    return right[0], left[0]


def torque_limit(scenario: Any) -> float:
    """[N m] per wheel: the smaller of the nominal robot's and the plant's ``max_torque`` (what the controller
    believes, and what the robot the scenario describes takes)."""
    return min(float(scenario.robot.max_torque), float(scenario.plant_params().max_torque))


def effort_message(tau_r: float, tau_l: float, sides: tuple[int, int]) -> Any:
    """The ``Float64MultiArray`` of (tau_r, tau_l) [N m] in the controller's joint order (``sides`` from
    :func:`wheel_sides`); its layout left empty, as ``JointGroupEffortController`` reads ``data`` only."""
    data = [0.0, 0.0]
    data[sides[0]], data[sides[1]] = float(tau_r), float(tau_l)
    layout = message("std_msgs/msg/MultiArrayLayout", dim=[], data_offset=0)
    return message(EFFORT_TYPE, layout=layout, data=np.asarray(data, dtype=np.float64))
