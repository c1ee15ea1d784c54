"""The whole scenario document, and the registries of the kinds it accepts (what ``ddtrack list`` shows)."""

from __future__ import annotations

import typing
from typing import Annotated, Any

from pydantic import BaseModel, Field, model_validator

from ..model import RobotParams
from ._base import (
    FieldError,
    _Section,
)
from .controller_configs import BacksteppingConfig
from .registry import ControllerConfig, ControllerField, TrajectoryConfig, TrajectoryField
from .sections import (
    NOT_PARAMETERS,
    DisturbanceConfig,
    InitialConfig,
    NoDisturbance,
    NoiseConfig,
    PlantConfig,
    RandomizeConfig,
    RobotConfig,
    SimulationConfig,
)
from .sensing_config import SensingConfig

MAX_DELAY_PERIODS = 1000  #: the longest [sensing] delay in control periods (its queue is part of the plant's state)
LOST_PATH_FRACTION = 0.25  #: of the reference's width: a run that stays this far off has lost the path

# --- the scenario --------------------------------------------------------------------------------


class Scenario(_Section):
    """A whole scenario file (docs/guide.md).

    Every key, its unit, default and bounds: ``docs/reference.md`` (``ddtrack schema``).

    Attributes
    ----------
    name : str
        Name of the scenario; the default run folder is ``runs/NAME``.
    description : str
        Free text.
    simulation, robot, plant, randomize, disturbance, noise, sensing, trajectory, initial, controller
        The file's sections: the run's timing and seed, the nominal robot the controller believes in, the true
        plant, its random draws, the wheel-torque disturbance, the measurement noise, the latency, encoders and
        odometry, the reference, the initial state and the controller.
    """

    name: str = Field(min_length=1, max_length=200, description="Name of the scenario.")
    description: str = Field("", max_length=10_000, description="Free text.")
    simulation: SimulationConfig = SimulationConfig()
    robot: RobotConfig = RobotConfig()
    plant: PlantConfig = PlantConfig()
    randomize: RandomizeConfig = RandomizeConfig()
    disturbance: DisturbanceConfig = NoDisturbance()
    noise: NoiseConfig = NoiseConfig()
    sensing: SensingConfig = SensingConfig()
    trajectory: Annotated[TrajectoryConfig, TrajectoryField()]
    initial: InitialConfig = InitialConfig()
    controller: Annotated[ControllerConfig, ControllerField()] = BacksteppingConfig(kind="backstepping")

    @model_validator(mode="after")
    def _draws_keep_parameters_physical(self) -> Scenario:
        plant = self.plant_params()
        for field, draw in self.randomize:
            if draw is None or field == "com_offset":
                continue
            value = getattr(plant, field)
            low = value * (1 - draw.reach) if draw.relative is not None else value - draw.reach
            must_be_positive = field in ("mass", "inertia", "wheel_radius", "half_axle")
            if low <= 0.0 if must_be_positive else low < 0.0:
                raise FieldError(
                    f"randomize.{field}", f"can draw a non-physical value ({low:.3g}); use a smaller spread"
                )
        return self

    @model_validator(mode="after")
    def _delays_fit_the_run(self) -> Scenario:
        sensing, sim = self.sensing, self.simulation
        for field, what in (("actuation_delay", "no command"), ("measurement_delay", "no measurement")):
            delay = getattr(sensing, field)
            if delay >= sim.duration:
                raise FieldError(
                    f"sensing.{field}",
                    f"{delay:g} s is not shorter than the run ({sim.duration:g} s): {what} would arrive in time",
                    "shorten the delay or lengthen simulation.duration",
                )
            if delay / sim.control_period > MAX_DELAY_PERIODS:  # the queue is part of the state vector
                raise FieldError(
                    f"sensing.{field}",
                    f"{delay:g} s is {delay / sim.control_period:.3g} control periods, over the limit of "
                    f"{MAX_DELAY_PERIODS}",
                    "shorten the delay or lengthen simulation.control_period",
                )
        for field in ("measurement_delay", "fix_period"):
            value, period = getattr(sensing, field), sim.control_period
            periods = value / period
            if abs(periods - round(periods)) > 1e-9 * max(1.0, periods):
                raise FieldError(
                    f"sensing.{field}",
                    f"{value:g} s is not a whole number of control periods ({period:g} s)",
                    f"use a multiple of simulation.control_period, e.g. {max(1, round(periods)) * period:g}",
                )
        return self

    @model_validator(mode="after")
    def _gyro_is_known(self) -> Scenario:
        self.sensing.gyro(self.robot.preset_robot())  # a gyro heading without its numbers names them
        return self

    def divergence_distance(self) -> float:
        """``simulation.divergence_error``, or the bound that scales with the scenario
        (:func:`ddtrack.feasibility.divergence_bound`) [m]."""
        if self.simulation.divergence_error is not None:
            return self.simulation.divergence_error
        from ..feasibility import divergence_bound

        return divergence_bound(self)

    def lost_path_distance(self) -> float:
        """``simulation.lost_path_error``, or a quarter of the reference's width (the larger side of its bounding
        box) [m]: a run that stays that far off to its end is tracking another path."""
        if self.simulation.lost_path_error is not None:
            return self.simulation.lost_path_error
        from ..feasibility import reference_width

        return LOST_PATH_FRACTION * reference_width(self)

    def top_speeds(self) -> tuple[float | None, float | None, str]:
        """The true robot's top speed [m/s] and yaw rate [rad/s] (None: nothing bounds it) and what sets them: the
        ``[robot] preset``'s rated limits, and its motor's no-load speed at the supply voltage (``[plant.motor]``
        over the preset's datasheet) times R, and over L for the yaw rate, on the true robot's wheels."""
        from .motor_configs import motor_or_none

        robot = self.robot.preset_robot()
        speed = None if robot is None else robot.rated_speed
        yaw_rate = None if robot is None else robot.rated_yaw_rate
        what = "" if robot is None else f"a {robot.name} (robot.preset)"
        if self.robot.top_speed is not None or self.robot.top_yaw_rate is not None:  # declared: the lower counts
            speed = _lower(speed, self.robot.top_speed)
            yaw_rate = _lower(yaw_rate, self.robot.top_yaw_rate)
            what = what or "the robot (robot.top_speed, robot.top_yaw_rate)"
        motor = motor_or_none(self)
        if motor is not None:
            params = self.plant_params()
            top = float(motor.no_load_speed) * params.wheel_radius
            speed = top if speed is None else min(speed, top)
            yaw_rate = top / params.half_axle if yaw_rate is None else min(yaw_rate, top / params.half_axle)
            what = f"{what or 'the robot of [plant.motor]'}, its motors at {float(motor.supply_voltage):g} V"
        return speed, yaw_rate, what

    def plant_params(self) -> RobotParams:
        """The true plant's nominal values: [plant] over [robot]."""
        true = self.plant.model_dump(
            exclude={
                "floor_friction",
                "model",
                "velocity_pi",
                "slip_speed",
                "caster_position",
                "com_height",
                "lag",
                "motor",
            }
        )  # the floor and model are not parameters
        merged = self.robot.model_dump(exclude=NOT_PARAMETERS) | {k: v for k, v in true.items() if v is not None}
        return RobotParams(**merged)


def _lower(a: float | None, b: float | None) -> float | None:
    """The lower of two limits, None standing for none."""
    return b if a is None else a if b is None else min(a, b)


# --- registries (what `ddtrack list` shows) -------------------------------------------------------


def _registry(union: Any) -> dict[str, type[BaseModel]]:
    members = typing.get_args(typing.get_args(union)[0]) if typing.get_origin(union) is Annotated else (union,)
    return {typing.get_args(m.model_fields["kind"].annotation)[0]: m for m in members}


DISTURBANCES = _registry(DisturbanceConfig)


def summary(model: type[BaseModel]) -> str:
    """First line of a config model's docstring."""
    return (model.__doc__ or "").strip().splitlines()[0]
