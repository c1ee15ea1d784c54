"""Identifying a robot from a log (docs/identification.md): the velocity-lag model of a base that takes cmd_vel,
the body model of one driven by wheel torques, or the motor model of one driven by voltages, from a bag or a
table; and the excitation plans that make a log identify them."""

from .body import body_model, identify_body, plant_keys
from .excitation import Plan, excitation_plan
from .fit import SpeedFit, SpeedLog, SpeedModel, identify
from .lag import LAG, identify_lag, lag_time_constants, simulate_speeds
from .logs import read_motor_log, read_speed_log
from .motor import ArmatureFit, MotorFit, MotorLog, drive_constants, identify_motor, motor_model, plant_fragment
from .synthetic import body_log, lag_log, motor_log, reversing_steps, timed_lag_log, torque_plan

__all__ = [
    "LAG",
    "ArmatureFit",
    "MotorFit",
    "MotorLog",
    "Plan",
    "SpeedFit",
    "SpeedLog",
    "SpeedModel",
    "body_log",
    "body_model",
    "drive_constants",
    "excitation_plan",
    "identify",
    "identify_body",
    "identify_lag",
    "identify_motor",
    "lag_log",
    "lag_time_constants",
    "motor_log",
    "motor_model",
    "plant_fragment",
    "plant_keys",
    "read_motor_log",
    "read_speed_log",
    "reversing_steps",
    "simulate_speeds",
    "timed_lag_log",
    "torque_plan",
]
