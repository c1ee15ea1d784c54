"""Wheel commands to ros2_control's joint-group controllers, for ``ddtrack drive --effort-topic`` and
``--wheel-velocity-topic`` (docs/ros.md).

No standard ROS 2 topic carries a base's wheel torques or wheel speeds, but ros2_control's
``effort_controllers/JointGroupEffortController`` and ``velocity_controllers/JointGroupVelocityController`` take one
``std_msgs/msg/Float64MultiArray`` per period on ``/<controller>/commands``, one value per joint in the order of
their ``joints`` parameter: efforts [N m], or joint speeds [rad/s]. A torque-output law (backstepping over computed
torque) so drives a base through its effort controller, and a velocity-output law a base that has no
``diff_drive_controller``, its (v, omega) turned into wheel speeds as that controller would (paper eq. 3, W nu).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ConfigError
from ..model import RobotParams
from .messages import message

ARRAY_TYPE = "std_msgs/msg/Float64MultiArray"
#: the joint order of the controller's ``joints`` parameter, TurtleBot-style names by default
DEFAULT_JOINTS = ("wheel_left_joint", "wheel_right_joint")


def wheel_sides(joints: tuple[str, ...]) -> tuple[int, int]:
    """The indices of the (right, left) wheels in ``joints``, read from the names (one holding ``right``, the other
    ``left``): the controller takes values in its own joint order, and a swapped pair would turn the robot the
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


def wheel_speed_limit(scenario: Any, nominal: RobotParams) -> float | None:
    """[rad/s] per wheel, None where nothing bounds it: the motors' no-load speed where the scenario has motors,
    else the robot's top speed over the believed wheel radius."""
    from ..scenario.motor_configs import motor_or_none

    motor = motor_or_none(scenario)
    if motor is not None:
        return float(motor.no_load_speed)
    top_speed = scenario.top_speeds()[0]
    return None if top_speed is None else float(top_speed) / float(nominal.wheel_radius)


def within_wheel_limit(v: float, omega: float, nominal: RobotParams, limit: float | None) -> tuple[float, float]:
    """(v, omega) scaled down together, so that neither wheel turns faster than ``limit`` [rad/s] on the believed
    wheels: the path's curvature omega / v is kept, as a base's own limiter would rather than clip one wheel."""
    right, left = wheel_speeds(v, omega, nominal)
    fastest = max(abs(right), abs(left))
    if limit is None or fastest <= limit:
        return v, omega
    return v * limit / fastest, omega * limit / fastest


def wheel_speeds(v: float, omega: float, nominal: RobotParams) -> tuple[float, float]:
    """(phi_dot_R, phi_dot_L) [rad/s] = W nu = ((v + L omega) / R, (v - L omega) / R) on the believed wheels
    (paper eq. 3), what a ``diff_drive_controller`` of that geometry would send its wheels."""
    radius, half = float(nominal.wheel_radius), float(nominal.half_axle)
    return (v + half * omega) / radius, (v - half * omega) / radius


def wheel_array(right: float, left: float, sides: tuple[int, int]) -> Any:
    """The ``Float64MultiArray`` of a (right, left) pair in the controller's joint order (``sides`` from
    :func:`wheel_sides`); its layout left empty, as the joint-group controllers read ``data`` only."""
    data = [0.0, 0.0]
    data[sides[0]], data[sides[1]] = float(right), float(left)
    layout = message("std_msgs/msg/MultiArrayLayout", dim=[], data_offset=0)
    return message(ARRAY_TYPE, layout=layout, data=np.asarray(data, dtype=np.float64))
