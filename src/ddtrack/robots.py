"""Presets of real robots: the numbers of a TurtleBot3, a Pioneer 3-DX and the paper's robot, each with its source.

A preset is data, plain Python floats: :attr:`RobotPreset.params` holds the fields of
:class:`ddtrack.model.RobotParams`, and the rest (wheel spin inertia, caster, top speeds, motor datasheet, the
identified velocity-lag model) describes what a richer plant needs. Every number names where it comes from in
:attr:`RobotPreset.sources`, or why it was chosen in :attr:`RobotPreset.assumptions`; numbers derived from others
(the yaw inertia of a URDF's links, a top speed from a motor's no-load speed) are computed here, not typed in.
docs/robots.md shows each preset as a table.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from .errors import ConfigError, did_you_mean

if TYPE_CHECKING:
    from .model.params import RobotParams

GRAVITY = 9.80665  #: standard gravity [m/s^2], the value ``ddtrack.model.traction`` uses

InputKind = Literal["torque", "voltage", "velocity"]


def rpm(value: float) -> float:
    """Convert revolutions per minute to rad/s."""
    return value * 2.0 * math.pi / 60.0


@dataclass(frozen=True)
class MotorDatasheet:
    """A geared motor as its datasheet gives it, all figures at the output shaft.

    The field names match the arguments of a motor model built from a datasheet (voltage, stall torque and
    current, no-load speed and current).

    Attributes
    ----------
    name : str
        The motor's model name.
    voltage : float
        Voltage the figures below hold at [V].
    stall_torque : float
        Output torque at stall [N m].
    stall_current : float
        Current at stall [A].
    no_load_speed : float
        Output speed with no load [rad/s].
    no_load_current : float
        Current with no load [A] (0 where the datasheet gives none; the preset's assumptions say so).
    gear_ratio : float
        Gear reduction, motor turns per output turn.
    encoder_counts : int
        Encoder counts per output revolution.
    source : str
        Where the figures come from.
    """

    name: str
    voltage: float
    stall_torque: float
    stall_current: float
    no_load_speed: float
    no_load_current: float
    gear_ratio: float
    encoder_counts: int
    source: str


@dataclass(frozen=True)
class UrdfLink:
    """One URDF link as far as yaw matters: name, mass [kg], centre of mass (x, y) [m] in the base frame (axle
    midpoint at the origin, x forward) and yaw inertia about its own centre of mass [kg m^2] (0: a point mass)."""

    name: str
    mass: float
    x: float
    y: float
    yaw_inertia: float = 0.0


def composite_body(links: tuple[UrdfLink, ...]) -> tuple[float, float, float]:
    """Mass, centre-of-mass x and yaw inertia about that centre of mass, of rigidly joined links (parallel axis).

    Parameters
    ----------
    links : tuple of UrdfLink
        The links of the body.

    Returns
    -------
    tuple of float
        ``(mass [kg], x_com [m], yaw inertia about the centre of mass [kg m^2])``. The y of the centre of mass
        is 0 for the symmetric robots here and enters the inertia through each link's offset.
    """
    mass = sum(link.mass for link in links)
    x_com = sum(link.mass * link.x for link in links) / mass
    y_com = sum(link.mass * link.y for link in links) / mass
    inertia = sum(link.yaw_inertia + link.mass * ((link.x - x_com) ** 2 + (link.y - y_com) ** 2) for link in links)
    return mass, x_com, inertia


@dataclass(frozen=True)
class RobotPreset:
    """A named real robot: the model's parameters, what a richer plant needs, and where every number comes from.

    Attributes
    ----------
    name : str
        The preset's name, as ``robot.preset`` takes it.
    description : str
        One line on the robot.
    params : Mapping[str, float]
        Fields of :class:`ddtrack.model.RobotParams`: mass, inertia, com_offset, wheel_radius, half_axle,
        max_torque, viscous_friction, coulomb_friction.
    wheel_inertia : float
        Spin inertia of each wheel with its geared motor, wheel + N^2 J_rotor [kg m^2].
    caster_position : float or None
        Body x of the caster [m], on the same side of the axle as the centre of mass; None where unknown.
    max_speed : float or None
        Top forward speed [m/s]; None where nothing bounds it (torque sources with no back-EMF).
    max_yaw_rate : float or None
        Top yaw rate [rad/s]; None where nothing bounds it.
    motor : MotorDatasheet or None
        The drive motor's datasheet; None where none is published.
    lag : tuple of 6 floats or None
        theta of the identified velocity-lag model (docs/model.md); None where none is identified.
    input : {"torque", "voltage", "velocity"}
        What the robot's driver takes.
    sources : Mapping[str, str]
        Field name -> where its value comes from.
    assumptions : Mapping[str, str]
        Field name -> why its value was chosen or how it was derived.
    rated_limits : tuple of 2 floats or None
        The maker's top speed [m/s] and yaw rate [rad/s] whatever the motors' voltage (the firmware's limits);
        None: ``max_speed`` and ``max_yaw_rate`` are the maker's. A scenario's top speeds are these and the
        motors' no-load speed at its supply voltage (``Scenario.top_speeds``).
    """

    name: str
    description: str
    params: Mapping[str, float]
    wheel_inertia: float
    caster_position: float | None
    max_speed: float | None
    max_yaw_rate: float | None
    motor: MotorDatasheet | None
    lag: tuple[float, float, float, float, float, float] | None
    input: InputKind
    sources: Mapping[str, str]
    assumptions: Mapping[str, str]
    rated_limits: tuple[float, float] | None = None

    @property
    def rated_speed(self) -> float | None:
        """The maker's top speed [m/s] (:attr:`rated_limits`, else :attr:`max_speed`)."""
        return self.max_speed if self.rated_limits is None else self.rated_limits[0]

    @property
    def rated_yaw_rate(self) -> float | None:
        """The maker's top yaw rate [rad/s] (:attr:`rated_limits`, else :attr:`max_yaw_rate`)."""
        return self.max_yaw_rate if self.rated_limits is None else self.rated_limits[1]

    def robot_params(self) -> RobotParams:
        """The preset as :class:`ddtrack.model.RobotParams`: the fields it has; the others keep their defaults."""
        import dataclasses

        from .model.params import RobotParams

        names = {f.name for f in dataclasses.fields(RobotParams)}
        extra = {"wheel_inertia": self.wheel_inertia}
        return RobotParams(**{k: v for k, v in {**self.params, **extra}.items() if k in names})

    def wheel_load(self) -> float:
        """Static normal load on each drive wheel [N]: m g (1 - d / l_c) / 2, or m g / 2 without a caster position."""
        weight = self.params["mass"] * GRAVITY
        if self.caster_position is None:
            return weight / 2.0
        return weight * (1.0 - self.params["com_offset"] / self.caster_position) / 2.0

    def friction_at_torque_limit(self) -> float:
        """Floor friction a wheel needs at full torque from rest, straight ahead (real floors give 0.3-1.0): the
        floor's force F over the wheel's load, where the torque first spins the wheel up, J_w a / R^2 of it, so
        F = (max_torque / R) / (1 + 2 J_w / (m R^2)) with a = 2 F / m."""
        mass, radius = self.params["mass"], self.params["wheel_radius"]
        force = self.params["max_torque"] / radius / (1.0 + 2.0 * self.wheel_inertia / (mass * radius**2))
        return force / self.wheel_load()


def markdown_table(preset: RobotPreset) -> str:
    """The preset as a Markdown table: every number with its source or assumption (docs/robots.md embeds it).

    Parameters
    ----------
    preset : RobotPreset
        The preset.

    Returns
    -------
    str
        The table, one row per field.
    """
    values: dict[str, object] = dict(preset.params)
    values |= {
        "wheel_inertia": preset.wheel_inertia,
        "caster_position": preset.caster_position,
        "max_speed": preset.max_speed,
        "max_yaw_rate": preset.max_yaw_rate,
        "motor": preset.motor.name if preset.motor else None,
        "lag": preset.lag,
        "input": preset.input,
    }
    rows = ["| field | value | source, or why |", "|---|---|---|"]
    for name, value in values.items():
        shown = f"{value:.6g}" if isinstance(value, float) else "none" if value is None else str(value)
        note = preset.sources.get(name, "")
        if name in preset.assumptions:
            note = f"{note}; {preset.assumptions[name]}" if note else preset.assumptions[name]
        rows.append(f"| `{name}` | {shown} | {note} |")
    return "\n".join(rows)


# ---------------------------------------------------------------------------------------------------------------
# Sources

_TURTLEBOT3_PAGE = "ROBOTIS e-Manual, TurtleBot3 specifications (https://emanual.robotis.com/docs/en/platform/turtlebot3/specifications/)"
_DXL = "ROBOTIS e-Manual, TurtleBot3 appendix DYNAMIXEL (https://emanual.robotis.com/docs/en/platform/turtlebot3/appendix_dynamixel/)"
_URDF = "ROBOTIS-GIT/turtlebot3, turtlebot3_description/urdf/{}.urdf (https://github.com/ROBOTIS-GIT/turtlebot3)"
_PARAM = "ROBOTIS-GIT/turtlebot3, turtlebot3_bringup/param/{}.yaml (wheels.separation, wheels.radius)"
_BAM = (
    "Rhoban BAM, identified servo armatures (arXiv:2410.08650): XL330 0.002 kg m^2, MX-64 0.012 kg m^2, output-referred"
)
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

# XL330 and MX-64 armatures identified by Rhoban BAM [kg m^2], output-referred
BAM_ARMATURE_XL330 = 0.002
BAM_ARMATURE_MX64 = 0.012

XL430_W250 = MotorDatasheet(
    "DYNAMIXEL XL430-W250", 11.1, 1.4, 1.3, rpm(57.0), 0.0, 258.5, 4096,
    "ROBOTIS e-Manual, XL430-W250 (https://emanual.robotis.com/docs/en/dxl/x/xl430-w250/), 11.1 V; " + _DXL,
)  # fmt: skip
XM430_W210 = MotorDatasheet(
    "DYNAMIXEL XM430-W210", 11.1, 2.7, 2.1, rpm(70.0), 0.0, 212.6, 4096,
    "ROBOTIS e-Manual, XM430-W210 (https://emanual.robotis.com/docs/en/dxl/x/xm430-w210/), 11.1 V; " + _DXL,
)  # fmt: skip

# The URDF links, as far as yaw matters. A wheel joint is rotated -1.57 rad about x, so the wheel link's y axis is
# the vertical: its yaw inertia is the URDF's iyy. The caster and laser links are point masses: their URDF inertia
# tensors (0.001 kg m^2 each, on 5 g and 114 g) are placeholders, a 5 g caster with that inertia would have a
# radius of gyration of 0.45 m.
BURGER_LINKS = (
    UrdfLink("base_link", 8.2573504e-01, 0.0, 0.0, 2.0064271e-03),
    UrdfLink("wheel_left_link", 2.8498940e-02, 0.0, 0.080, 1.1192413e-05),
    UrdfLink("wheel_right_link", 2.8498940e-02, 0.0, -0.080, 1.1192413e-05),
    UrdfLink("caster_back_link", 0.005, -0.081, 0.0),
    UrdfLink("base_scan", 0.114, -0.032, 0.0),
)
WAFFLE_PI_LINKS = (
    UrdfLink("base_link", 1.3729096e00, 0.0, 0.0, 1.4612727e-02),
    UrdfLink("wheel_left_link", 2.8498940e-02, 0.0, 0.144, 1.1192413e-05),
    UrdfLink("wheel_right_link", 2.8498940e-02, 0.0, -0.144, 1.1192413e-05),
    UrdfLink("caster_back_right_link", 0.005, -0.177, -0.064),
    UrdfLink("caster_back_left_link", 0.005, -0.177, 0.064),
    UrdfLink("base_scan", 0.114, -0.064, 0.0),
)
TURTLEBOT3_WHEEL_SPIN_INERTIA = 2.0712558e-05  # izz of wheel_left_link, the spin axis [kg m^2]

#: The Pioneer 3-DX's identified theta sets (docs/model.md, the velocity-lag model)
PIONEER_3DX_THETA = {
    "with_laser": (0.2604, 0.2509, -0.0005, 0.9965, 0.0026, 1.0768),
    "without_laser": (0.5338, 0.2168, -0.0134, 0.9560, -0.0843, 1.0590),
}


def _turtlebot3(
    name: str,
    description: str,
    urdf: str,
    param_file: str,
    links: tuple[UrdfLink, ...],
    separation: float,
    motor: MotorDatasheet,
    armature: float,
    armature_why: str,
    spec: tuple[float, float, float],
) -> RobotPreset:
    spec_speed, spec_yaw_rate, spec_mass = spec  # ROBOTIS' top speed [m/s], top yaw rate [rad/s], weight [kg]
    mass, x_com, inertia = composite_body(links)
    casters = [link.x for link in links if link.name.startswith("caster")]
    radius, half_axle = 0.033, separation / 2.0
    top_speed = motor.no_load_speed * radius  # both wheels at the no-load speed
    coulomb = 0.02 * motor.stall_torque
    return RobotPreset(
        name=name,
        description=description,
        params={
            "mass": mass,
            "inertia": inertia,
            "com_offset": x_com,
            "wheel_radius": radius,
            "half_axle": half_axle,
            "max_torque": motor.stall_torque,
            "viscous_friction": 0.0,
            "coulomb_friction": coulomb,
        },
        wheel_inertia=TURTLEBOT3_WHEEL_SPIN_INERTIA + armature,
        caster_position=sum(casters) / len(casters),
        max_speed=min(spec_speed, top_speed),
        max_yaw_rate=min(spec_yaw_rate, top_speed / half_axle),
        rated_limits=(spec_speed, spec_yaw_rate),
        motor=motor,
        lag=None,
        input="velocity",
        sources={
            "mass": _URDF.format(urdf),
            "inertia": _URDF.format(urdf),
            "com_offset": _URDF.format(urdf),
            "wheel_radius": _PARAM.format(param_file) + "; " + _URDF.format(urdf) + " (wheel cylinder radius)",
            "half_axle": _PARAM.format(param_file),
            "max_torque": motor.source,
            "wheel_inertia": _URDF.format(urdf) + " (wheel izz); " + _BAM,
            "caster_position": _URDF.format(urdf),
            "max_speed": _TURTLEBOT3_PAGE + f" ({spec_speed} m/s); " + motor.source,
            "max_yaw_rate": _TURTLEBOT3_PAGE + f" ({spec_yaw_rate} rad/s); " + motor.source,
            "motor": motor.source,
            "input": "ROBOTIS-GIT/turtlebot3, turtlebot3_node: the base takes cmd_vel (v, omega) commands and runs "
            "its DYNAMIXELs in velocity mode",
        },
        assumptions={
            "mass": f"derived: sum of the URDF's link masses ({len(links)} links); ROBOTIS gives {spec_mass} kg",
            "inertia": "derived: the links' yaw inertias moved to the composite centre of mass (parallel axis); the "
            "caster and laser are point masses, their URDF inertias (0.001 kg m^2) being placeholders",
            "com_offset": "derived: composite centre of mass of the URDF's links; base_link's inertial origin is at "
            "the axle midpoint, so the offset comes from the laser and caster behind it",
            "half_axle": f"derived: separation {separation} m / 2",
            "max_torque": f"the stall torque at {motor.voltage} V, the 3-cell LiPo battery's voltage",
            "viscous_friction": "assumed 0: a motor model's back-EMF is the speed-dependent drag",
            "coulomb_friction": "assumed: 2 % of the stall torque for gearbox and bearing drag (none is published)",
            "wheel_inertia": f"derived: wheel spin izz + assumed armature {armature:.3g} kg m^2 ({armature_why})",
            "caster_position": "the caster joint's x in the URDF (mean of the casters), behind the axle like the "
            "centre of mass",
            "max_speed": f"derived: the lower of ROBOTIS' limit and no-load speed x R = {top_speed:.4g} m/s",
            "max_yaw_rate": "derived: the lower of ROBOTIS' limit and no-load speed x R / L "
            f"= {top_speed / half_axle:.4g} rad/s",
            "lag": "none identified; the motor datasheet describes the drive",
            "motor": "no-load current not published (the 52/40 mA standby current is the electronics): taken as 0",
        },
    )


TURTLEBOT3_BURGER = _turtlebot3(
    "turtlebot3_burger",
    "ROBOTIS TurtleBot3 Burger: 1 kg, two DYNAMIXEL XL430-W250 wheel servos, rear caster",
    "turtlebot3_burger",
    "burger",
    BURGER_LINKS,
    0.160,
    XL430_W250,
    BAM_ARMATURE_XL330,
    "not published; that of the XL330 identified by BAM, the closest cored X-series servo with a similar "
    "gear ratio (288.4:1 against 258.5:1)",
    (0.22, 2.84, 1.0),
)
TURTLEBOT3_WAFFLE_PI = _turtlebot3(
    "turtlebot3_waffle_pi",
    "ROBOTIS TurtleBot3 Waffle Pi: 1.8 kg, two DYNAMIXEL XM430-W210 wheel servos, two rear casters",
    "turtlebot3_waffle_pi",
    "waffle_pi",
    WAFFLE_PI_LINKS,
    0.287,
    XM430_W210,
    math.sqrt(BAM_ARMATURE_XL330 * BAM_ARMATURE_MX64),
    "not published; the geometric mean of BAM's XL330 and MX-64, which the XM430 lies between in size and torque",
    (0.26, 1.82, 1.8),
)

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
        "input": "the paper's controllers compute wheel torques",
    },
)

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
