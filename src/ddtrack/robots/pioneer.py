"""The Adept MobileRobots Pioneer 3-DX: published specifications and Martins et al.'s identified velocity lags."""

from __future__ import annotations

import math

from .datasheets import GRAVITY, RobotPreset

_ADEPT = (
    "Adept MobileRobots Pioneer 3-DX specifications (9 kg; 19 cm wheels; 1.2 m/s; 300 deg/s), as reproduced in the "
    "Webots user guide (https://github.com/cyberbotics/webots-doc, "
    "guide/using-the-pioneer-3-at-and-pioneer-3-dx-robots.md)"
)
_MARTINS = (
    "F. N. Martins, W. C. Celeste, R. Carelli, M. Sarcinelli-Filho, T. F. Bastos-Filho, 'An adaptive dynamic "
    "controller for autonomous mobile robot trajectory tracking', Control Engineering Practice 16:1354-1363, 2008; as "
    "distributed with Martins' public code"
)

#: The Pioneer 3-DX's identified theta sets (docs/model.md, the velocity-lag model)
PIONEER_3DX_THETA = {
    "with_laser": (0.2604, 0.2509, -0.0005, 0.9965, 0.0026, 1.0768),
    "without_laser": (0.5338, 0.2168, -0.0134, 0.9560, -0.0843, 1.0590),
}

_PIONEER_MASS = 9.0
_PIONEER_RADIUS = 0.19 / 2.0
_PIONEER_LENGTH, _PIONEER_WIDTH = 0.455, 0.381
PIONEER_3DX = RobotPreset(
    name="pioneer_3dx",
    description="Adept MobileRobots Pioneer 3-DX: 9 kg, velocity-commanded, identified first-order velocity lags",
    params={
        "mass": _PIONEER_MASS,
        "inertia": _PIONEER_MASS * (_PIONEER_LENGTH**2 + _PIONEER_WIDTH**2) / 12.0,
        "com_offset": 0.0,
        "wheel_radius": _PIONEER_RADIUS,
        "half_axle": 0.165,
        "max_torque": 1.0 * _PIONEER_MASS * GRAVITY / 2.0 * _PIONEER_RADIUS,
        "viscous_friction": 0.0,
        "coulomb_friction": 0.0,
    },
    wheel_inertia=0.0,
    caster_position=None,
    max_speed=1.2,
    max_yaw_rate=math.radians(300.0),
    motor=None,
    lag=PIONEER_3DX_THETA["with_laser"],
    input="velocity",
    sources={
        "mass": _ADEPT,
        "wheel_radius": _ADEPT,
        "inertia": _ADEPT + " (455 mm x 381 mm)",
        "max_speed": _ADEPT,
        "max_yaw_rate": _ADEPT,
        "lag": _MARTINS,
        "input": _MARTINS + " (the model takes velocity commands)",
    },
    assumptions={
        "com_height": "not published: none, so the slip plants model no load transfer (set plant.com_height)",
        "odometry_heading": "the wheel encoders, as ARIA's odometry computes it; the optional gyro accessory is not "
        "modelled",
        "inertia": "assumed: a uniform 455 mm x 381 mm plate, m (a^2 + b^2) / 12; no measured value is published",
        "com_offset": "assumed 0 (not published); the identified lag model absorbs the body's dynamics",
        "wheel_radius": "derived: the 19 cm wheel diameter / 2",
        "half_axle": "assumed: 0.165 m, the wheel positions (+-0.165 m) of a public robot definition for the "
        "Webots Pioneer 3-DX; the specifications quoted give no track",
        "max_torque": "assumed: the grip limit on a floor of friction 1, 1 x m g / 2 x R (motor data are not "
        "published); matters only to a torque-level plant",
        "viscous_friction": "assumed 0: the identified lag model holds the drag",
        "coulomb_friction": "assumed 0: the identified lag model holds the drag",
        "wheel_inertia": "assumed 0: unknown, and absorbed by the identified lag model",
        "caster_position": "unknown: the wheels share the weight equally",
        "max_yaw_rate": "derived: 300 deg/s in rad/s",
        "motor": "no motor datasheet is published with the robot",
        "lag": "the set identified with the laser scanner on; the other published set, without it, is "
        "PIONEER_3DX_THETA['without_laser']",
    },
)
