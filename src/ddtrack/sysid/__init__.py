"""Identifying a robot from a log (docs/identification.md): the velocity-lag model of a base that takes cmd_vel, or
the body model of one driven by wheel torques, from a bag or a table; and the excitation plans that make a log
identify them."""

from .body import body_model, identify_body, plant_keys
from .excitation import Plan, excitation_plan
from .fit import SpeedFit, SpeedLog, SpeedModel, identify
from .lag import LAG, identify_lag, lag_time_constants, simulate_speeds
from .logs import read_speed_log
from .synthetic import body_log, lag_log, torque_plan

__all__ = [
    "LAG",
    "Plan",
    "SpeedFit",
    "SpeedLog",
    "SpeedModel",
    "body_log",
    "body_model",
    "excitation_plan",
    "identify",
    "identify_body",
    "identify_lag",
    "lag_log",
    "lag_time_constants",
    "plant_keys",
    "read_speed_log",
    "simulate_speeds",
    "torque_plan",
]
