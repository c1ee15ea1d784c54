"""The robot: parameters, kinematics, Lagrangian dynamics, plants, disturbances and noise (model.md §1)."""

from .disturbance import MeasurementNoise, WheelDisturbance
from .dynamics import (
    body_acceleration,
    body_velocity,
    constraint_matrix,
    coriolis_vector,
    energy,
    input_matrix,
    mass_matrix,
    pose_rate,
    reduced_coriolis,
    reduced_input,
    reduced_input_inverse,
    reduced_mass,
    velocity_basis,
    wheel_friction,
    wheel_speeds,
)
from .lag import PIONEER_3DX_ALTERNATIVE, PIONEER_3DX_WITH_LASER, LagPlant, lag_plant_model
from .params import RobotParams
from .plants import DynamicPlant, KinematicPlant, ODEPlant, Plant

__all__ = [
    "PIONEER_3DX_ALTERNATIVE",
    "PIONEER_3DX_WITH_LASER",
    "DynamicPlant",
    "KinematicPlant",
    "LagPlant",
    "MeasurementNoise",
    "ODEPlant",
    "Plant",
    "RobotParams",
    "WheelDisturbance",
    "body_acceleration",
    "body_velocity",
    "constraint_matrix",
    "coriolis_vector",
    "energy",
    "input_matrix",
    "lag_plant_model",
    "mass_matrix",
    "pose_rate",
    "reduced_coriolis",
    "reduced_input",
    "reduced_input_inverse",
    "reduced_mass",
    "velocity_basis",
    "wheel_friction",
    "wheel_speeds",
]
