"""The robot: parameters, kinematics, Lagrangian dynamics, motors, plants, disturbances and noise (model.md §1)."""

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
from .motor_plants import (
    TorqueDrivenPlant,
    VelocityDrivenPlant,
    motor_from_datasheet,
    torque_driven_model,
    velocity_driven_model,
)
from .motors import (
    DCMotor,
    VelocityDriver,
    current_envelope,
    current_rate,
    torque_driver,
    torque_envelope,
    torque_feedforward,
    voltage_driver,
)
from .params import RobotParams
from .plants import DynamicPlant, KinematicPlant, ODEPlant, Plant
from .sensed import SensedPlant, Sensing
from .slip import SlipPlant, slip_plant, slip_plant_model
from .slip_velocity import SlipVelocityPlant, slip_velocity_model

__all__ = [
    "PIONEER_3DX_ALTERNATIVE",
    "PIONEER_3DX_WITH_LASER",
    "DCMotor",
    "DynamicPlant",
    "KinematicPlant",
    "LagPlant",
    "MeasurementNoise",
    "ODEPlant",
    "Plant",
    "RobotParams",
    "SensedPlant",
    "Sensing",
    "SlipPlant",
    "SlipVelocityPlant",
    "TorqueDrivenPlant",
    "VelocityDrivenPlant",
    "VelocityDriver",
    "WheelDisturbance",
    "body_acceleration",
    "body_velocity",
    "constraint_matrix",
    "coriolis_vector",
    "current_envelope",
    "current_rate",
    "energy",
    "input_matrix",
    "lag_plant_model",
    "mass_matrix",
    "motor_from_datasheet",
    "pose_rate",
    "reduced_coriolis",
    "reduced_input",
    "reduced_input_inverse",
    "reduced_mass",
    "slip_plant",
    "slip_plant_model",
    "slip_velocity_model",
    "torque_driven_model",
    "torque_driver",
    "torque_envelope",
    "torque_feedforward",
    "velocity_basis",
    "velocity_driven_model",
    "voltage_driver",
    "wheel_friction",
    "wheel_speeds",
]
