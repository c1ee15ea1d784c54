"""The paper's robot: torque sources at massless wheels, as the paper simulates it."""

from __future__ import annotations

from .datasheets import RobotPreset

_PAPER = "the paper (m = 10 kg, J = 0.56 kg m^2)"
_FIERRO = (
    "R. Fierro, F. L. Lewis, 'Control of a nonholonomic mobile robot: backstepping kinematics into dynamics', 1997"
)
PAPER = RobotPreset(
    name="paper",
    description="The paper's robot: torque sources at massless wheels, perfect grip (docs/model.md, section 1.4)",
    params={
        "mass": 10.0,
        "inertia": 0.56,
        "com_offset": 0.05,
        "wheel_radius": 0.05,
        "half_axle": 0.25,
        "max_torque": 10.0,
        "viscous_friction": 0.0,
        "coulomb_friction": 0.0,
    },
    wheel_inertia=0.0,
    caster_position=None,
    max_speed=None,
    max_yaw_rate=None,
    motor=None,
    lag=None,
    input="torque",
    sources={
        "mass": _PAPER,
        "inertia": _PAPER + ", read as the yaw inertia about the centre of mass",
        "wheel_radius": _FIERRO,
        "max_torque": "the paper's torque saturation, 10 N m per wheel (docs/model.md, section 2.5)",
    },
    assumptions={
        "com_offset": "chosen: rear drive wheels and front casters put the centre of mass ahead of the axle; "
        "a small offset",
        "half_axle": "chosen: a 10 kg robot with I_C = 0.56 has a radius of gyration of 0.24 m, so a track of 0.5 m",
        "viscous_friction": "the controller's model has no friction (the uncertain plant adds some)",
        "coulomb_friction": "the controller's model has no friction (the uncertain plant adds some)",
        "wheel_inertia": "massless wheels, as in the paper",
        "caster_position": "not given: the wheels share the weight equally",
        "max_speed": "none: torque sources without back-EMF have no top speed",
        "max_yaw_rate": "none: torque sources without back-EMF have no top yaw rate",
        "motor": "none: the paper commands wheel torques directly",
        "lag": "none: a torque-level model",
        "com_height": "not given by the paper: none, so the slip plants model no load transfer",
        "odometry_heading": "the paper has no odometry; with [sensing] odometry on it turns with the encoders",
        "input": "the paper's controllers compute wheel torques",
    },
)
