"""The plants built from what a scenario's ``[robot] preset`` knows beyond the robot's parameters: the motors of
its datasheet (``motor_torque``, ``motor_velocity`` with ``[plant] velocity_pi``'s gains) and its identified
velocity-lag model (``lag``)."""

from __future__ import annotations

import dataclasses
from typing import Any

from ..errors import ConfigError
from ..model import (
    DCMotor,
    LagPlant,
    RobotParams,
    TorqueDrivenPlant,
    VelocityDrivenPlant,
    VelocityDriver,
    lag_plant_model,
)
from ..model.motor_plants import motor_from_datasheet, torque_driven_model, velocity_driven_model


def scenario_motor(scenario: Any) -> DCMotor:
    """The motor of the scenario (:func:`motor_or_none`); a ConfigError naming ``plant.model`` if it has none."""
    from ..robots import PRESETS

    motor = motor_or_none(scenario)
    if motor is None:
        with_motor = sorted(name for name, robot in PRESETS.items() if robot.motor is not None)
        name = scenario.robot.preset
        raise ConfigError(
            "plant.model",
            f"'{scenario.plant.model}' needs the robot's motor, and "
            + (f"preset '{name}' has none" if name is not None else "[robot] names no preset"),
            "give [plant.motor] (resistance, torque_constant, back_emf, supply_voltage), or set robot.preset to a "
            "robot with motors: " + ", ".join(with_motor),
        )
    return motor


def motor_or_none(scenario: Any) -> DCMotor | None:
    """The ``[robot] preset``'s datasheet motor with ``[plant.motor]``'s constants over it; None where neither
    gives one. Without a preset motor, ``[plant.motor]`` must give the four constants no default can stand for."""
    robot = scenario.robot.preset_robot()
    preset = None if robot is None or robot.motor is None else motor_from_datasheet(robot.motor)
    given = (
        {} if scenario.plant.motor is None else scenario.plant.motor.model_dump(exclude_none=True, exclude={"drive"})
    )
    if preset is not None:
        return dataclasses.replace(preset, **given)
    if not given:
        return None
    missing = [key for key in ("resistance", "torque_constant", "back_emf", "supply_voltage") if key not in given]
    if missing:
        raise ConfigError(
            "plant.motor",
            f"gives no {', '.join(missing)}, and [robot] names no preset with a motor to take them from",
            "give them in [plant.motor] (e.g. from `ddtrack identify --model motor`), or set robot.preset",
        )
    given.setdefault("efficiency", 1.0)
    given.setdefault("current_limit", given["supply_voltage"] / given["resistance"])  # the stall current
    return DCMotor(**given)


def motor_drive(scenario: Any) -> str:
    """How the board drives the motor for a torque command: ``plant.motor.drive``, else "pwm" where the preset's servo
    lists its modes and has no current mode, else "current"."""
    given = None if scenario.plant.motor is None else scenario.plant.motor.drive
    if given is not None:
        return str(given)
    robot = scenario.robot.preset_robot()
    modes = () if robot is None or robot.motor is None else robot.motor.drive_modes
    return "pwm" if modes and "current" not in modes else "current"


def pwm_model(scenario: Any) -> DCMotor | None:
    """The board's model of its motor when it drives by PWM (:func:`motor_drive`), else None: the preset's datasheet
    motor (what the board's firmware knows; ``[plant.motor]`` describes the true one), or the scenario's motor where
    no preset gives one."""
    if motor_drive(scenario) != "pwm":
        return None
    robot = scenario.robot.preset_robot()
    if robot is not None and robot.motor is not None:
        return motor_from_datasheet(robot.motor)
    return scenario_motor(scenario)


def motor_torque_plant(params: RobotParams, scenario: Any) -> TorqueDrivenPlant:
    """The drawn robot with its preset's motors under current control, or PWM where the servo offers only that
    (:func:`motor_drive`; model.md §1.7)."""
    return torque_driven_model(scenario_motor(scenario), pwm_model(scenario))(params)


def motor_velocity_plant(params: RobotParams, scenario: Any) -> VelocityDrivenPlant:
    """The drawn robot with its preset's motors under a PI wheel-speed loop (model.md §1.7)."""
    kp, ki = scenario.plant.velocity_pi
    return velocity_driven_model(VelocityDriver(scenario_motor(scenario), kp, ki))(params)


def lag_plant(params: RobotParams, scenario: Any) -> LagPlant:
    """The identified velocity-lag model (model.md §1.8): ``plant.lag``, else the ``[robot] preset``'s, limited to the
    preset's top speed and yaw rate (none without a preset); the robot's own parameters do not enter it."""
    from ..robots import PRESETS

    name = scenario.robot.preset
    robot = PRESETS.get(name) if name is not None else None
    theta = scenario.plant.lag if scenario.plant.lag is not None else (robot.lag if robot is not None else None)
    if theta is None:
        identified = sorted(key for key, value in PRESETS.items() if value.lag is not None)
        raise ConfigError(
            "plant.model",
            "'lag' needs the robot's identified velocity-lag model, and "
            + (f"preset '{name}' has none" if name is not None else "[robot] names no preset"),
            "give plant.lag (theta_1..theta_6, e.g. from `ddtrack identify`), or set robot.preset to an identified "
            "robot: " + ", ".join(identified),
        )
    top = (robot.max_speed, robot.max_yaw_rate) if robot is not None else (None, None)
    return lag_plant_model(theta, *(limit if limit is not None else float("inf") for limit in top))(params)


def check_drive(scenario: Any) -> list[dict]:
    """Warn where a torque-level law drives a preset whose servos offer no current (torque) mode, saying how the run
    simulates it: through PWM (``plant.motor.drive = "pwm"``, the default for such a servo, on a motor plant), as if
    the servo controlled current, or as ideal torque sources (the ``dynamic`` and motorless plants)."""
    from .registry import controller_output
    from .sections import MOTOR_MODELS

    robot = scenario.robot.preset_robot()
    modes = () if robot is None or robot.motor is None else robot.motor.drive_modes
    if not modes or "current" in modes or controller_output(scenario.controller) != "torque":
        return []
    offered = ", ".join(mode.replace("_", " ") for mode in modes)
    if scenario.plant.model not in MOTOR_MODELS:
        how = f"plant '{scenario.plant.model}' applies its torques as ideal sources"
    elif motor_drive(scenario) == "pwm":
        how = (
            "this run drives them by PWM, the torque turned into a voltage through the datasheet motor's model at "
            'the measured wheel speed (plant.motor.drive = "pwm"), as the robot\'s firmware would have to'
        )
    else:
        how = 'this run simulates them as if they controlled current (plant.motor.drive = "current")'
    message = (
        f"the {robot.name}'s {robot.motor.name} servos offer {offered} modes, no current (torque) mode, and this "
        f"controller commands wheel torques: {how}; a velocity-level law over cmd_vel runs on the robot as it is"
    )
    return [{"code": "drive_not_offered", "message": message}]
