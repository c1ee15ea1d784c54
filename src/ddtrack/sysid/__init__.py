"""Identifying a robot from a log (docs/identification.md): the velocity-lag model of a base that takes cmd_vel,
from a bag or a table, and the excitation plans that make a log identify it."""

from .excitation import Plan, excitation_plan
from .lag import NAMES, UNITS, LagFit, SpeedLog, identify_lag, simulate_speeds
from .logs import read_speed_log
from .synthetic import lag_log

__all__ = [
    "NAMES",
    "UNITS",
    "LagFit",
    "Plan",
    "SpeedLog",
    "excitation_plan",
    "identify_lag",
    "lag_log",
    "read_speed_log",
    "simulate_speeds",
]
