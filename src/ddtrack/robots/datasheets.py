"""What a robot preset is: a motor's datasheet, a URDF's links, and :class:`RobotPreset` with its sources."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    from ..model.params import RobotParams

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
    drive_modes : tuple of str
        The operating modes the servo offers ("current", "velocity", "position", "extended_position",
        "current_based_position", "pwm"); empty where the datasheet lists none. Without "current" a torque law must
        drive it by PWM (``plant.motor.drive``).
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
    drive_modes: tuple[str, ...] = ()


@dataclass(frozen=True)
class GyroDatasheet:
    """The yaw-rate gyro a robot's stock odometry takes its heading from (ROS's ``use_imu``).

    Attributes
    ----------
    name : str
        The IMU's model name.
    noise_density : float
        White rate noise [rad/s/sqrt(Hz)], the datasheet's rate noise spectral density.
    bias : float
        Constant rate bias left in a run [rad/s] (after whatever calibration the robot does at start).
    source : str
        Where ``noise_density`` comes from.
    bias_why : str
        Where ``bias`` comes from, or why that value.
    """

    name: str
    noise_density: float
    bias: float
    source: str
    bias_why: str


@dataclass(frozen=True)
class UrdfLink:
    """One URDF link as far as yaw and load transfer matter: name, mass [kg], centre of mass (x, y) [m] in the base
    frame (axle midpoint at the origin, x forward), yaw inertia about its own centre of mass [kg m^2] (0: a point
    mass) and the centre of mass's height z above the floor [m]."""

    name: str
    mass: float
    x: float
    y: float
    yaw_inertia: float = 0.0
    z: float = 0.0


def composite_height(links: tuple[UrdfLink, ...]) -> float:
    """Height above the floor [m] of the centre of mass of rigidly joined links: sum m_i z_i / sum m_i."""
    return sum(link.mass * link.z for link in links) / sum(link.mass for link in links)


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
    gyro : GyroDatasheet or None
        The gyro the robot's stock odometry takes its heading from; None: its odometry turns with the wheels.
    com_height : float or None
        Height of the centre of mass above the floor [m], for the slip plants' load transfer; None where unknown
        (no load transfer is modelled).
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
    gyro: GyroDatasheet | None = None
    com_height: float | None = None

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

        from ..model.params import RobotParams

        names = {f.name for f in dataclasses.fields(RobotParams)}
        extra = {"wheel_inertia": self.wheel_inertia}
        return RobotParams(**{k: v for k, v in {**self.params, **extra}.items() if k in names})

    def values(self) -> dict[str, object]:
        """Every number and choice of the preset by name, as :attr:`sources` and :attr:`assumptions` name them."""
        values: dict[str, object] = dict(self.params)
        values |= {
            "wheel_inertia": self.wheel_inertia,
            "caster_position": self.caster_position,
            "max_speed": self.max_speed,
            "max_yaw_rate": self.max_yaw_rate,
            "motor": self.motor.name if self.motor else None,
            "lag": self.lag,
            "input": self.input,
            "odometry_heading": "gyro" if self.gyro else "encoders",
            "com_height": self.com_height,
        }
        if self.gyro is not None:
            values |= {"gyro_noise_density": self.gyro.noise_density, "gyro_bias": self.gyro.bias}
        return values

    def wheel_load(self) -> float:
        """Static normal load on each drive wheel [N]: m g (1 - d / l_c) / 2, or m g / 2 without a caster position."""
        weight = self.params["mass"] * GRAVITY
        if self.caster_position is None:
            return weight / 2.0
        return weight * (1.0 - self.params["com_offset"] / self.caster_position) / 2.0

    def accelerating_load(self, push: float) -> float:
        """Each drive wheel's load [N] while the floor pushes each wheel forward with ``push`` [N] (model.md §1.10):
        the static share plus h F / l_c, the load the centre of mass's height moves (none without a height or a
        caster position)."""
        if self.com_height is None or self.caster_position is None:
            return self.wheel_load()
        return self.wheel_load() + self.com_height * push / self.caster_position

    def friction_at_torque_limit(self) -> float:
        """Floor friction a wheel needs at full torque from rest, straight ahead (real floors give 0.3-1.0): the
        floor's force F over the wheel's load while accelerating (:meth:`accelerating_load`), where the torque first
        spins the wheel up, J_w a / R^2 of it, so F = (max_torque / R) / (1 + 2 J_w / (m R^2)) with a = 2 F / m;
        ``inf`` where the load moved off the drive wheels would lift them (the robot would tip onto its caster)."""
        mass, radius = self.params["mass"], self.params["wheel_radius"]
        force = self.params["max_torque"] / radius / (1.0 + 2.0 * self.wheel_inertia / (mass * radius**2))
        load = self.accelerating_load(force)
        return force / load if load > 0.0 else math.inf


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
    rows = ["| field | value | source, or why |", "|---|---|---|"]
    for name, value in preset.values().items():
        shown = f"{value:.6g}" if isinstance(value, float) else "none" if value is None else str(value)
        note = preset.sources.get(name, "")
        if name in preset.assumptions:
            note = f"{note}; {preset.assumptions[name]}" if note else preset.assumptions[name]
        rows.append(f"| `{name}` | {shown} | {note} |")
    return "\n".join(rows)
