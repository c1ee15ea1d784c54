"""Presets of real robots: the numbers of a TurtleBot3, a Pioneer 3-DX and the paper's robot, each with its source.

A preset is data, plain Python floats: :attr:`RobotPreset.params` holds the fields of
:class:`ddtrack.model.RobotParams`, and the rest (wheel spin inertia, caster, top speeds, motor datasheet, the
identified velocity-lag model) describes what a richer plant needs. Every number names where it comes from in
:attr:`RobotPreset.sources`, or why it was chosen in :attr:`RobotPreset.assumptions`; numbers derived from others
(the yaw inertia of a URDF's links, a top speed from a motor's no-load speed) are computed here, not typed in.
docs/robots.md shows each preset as a table.
"""

from __future__ import annotations

from collections.abc import Mapping

from ..errors import ConfigError, did_you_mean
from .datasheets import (
    GRAVITY,
    GyroDatasheet,
    InputKind,
    MotorDatasheet,
    RobotPreset,
    UrdfLink,
    composite_body,
    composite_height,
    markdown_table,
    rpm,
)
from .paper import PAPER
from .pioneer import PIONEER_3DX, PIONEER_3DX_THETA
from .turtlebot3 import (
    BAM_ARMATURE_MX64,
    BAM_ARMATURE_XL330,
    BURGER_LINKS,
    OPENCR_MPU9250,
    TURTLEBOT3_BURGER,
    TURTLEBOT3_WAFFLE_PI,
    TURTLEBOT3_WHEEL_SPIN_INERTIA,
    WAFFLE_PI_LINKS,
    XL430_W250,
    XM430_W210,
)

__all__ = [
    "BAM_ARMATURE_MX64",
    "BAM_ARMATURE_XL330",
    "BURGER_LINKS",
    "GRAVITY",
    "OPENCR_MPU9250",
    "PAPER",
    "PIONEER_3DX",
    "PIONEER_3DX_THETA",
    "PRESETS",
    "TURTLEBOT3_BURGER",
    "TURTLEBOT3_WAFFLE_PI",
    "TURTLEBOT3_WHEEL_SPIN_INERTIA",
    "WAFFLE_PI_LINKS",
    "XL430_W250",
    "XM430_W210",
    "GyroDatasheet",
    "InputKind",
    "MotorDatasheet",
    "RobotPreset",
    "UrdfLink",
    "composite_body",
    "composite_height",
    "markdown_table",
    "preset",
    "rpm",
]

#: Every preset by name
PRESETS: Mapping[str, RobotPreset] = {p.name: p for p in (TURTLEBOT3_BURGER, TURTLEBOT3_WAFFLE_PI, PIONEER_3DX, PAPER)}


def preset(name: str) -> RobotPreset:
    """The preset called ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`PRESETS`.

    Returns
    -------
    RobotPreset
        The preset.

    Raises
    ------
    ConfigError
        On ``robot.preset`` for an unknown name, with the closest name as a hint.
    """
    try:
        return PRESETS[name]
    except KeyError:
        raise ConfigError("robot.preset", f"unknown robot preset {name!r}", did_you_mean(name, PRESETS)) from None
