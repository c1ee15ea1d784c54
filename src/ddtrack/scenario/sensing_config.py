"""The scenario's ``[sensing]`` section: latency, encoders, odometry (its heading from the wheels or a gyro) and an
absolute fix between the robot and its controller (model.md §1.9)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from ..model import Sensing
from ..model.sensed import SensingParameters
from ..robots import RobotPreset
from ._base import FieldError, NonNegative, _Section

# --- [sensing] -------------------------------------------------------------------------------


class SensingConfig(SensingParameters, _Section):
    """Latency, wheel encoders and odometry between the robot and its controller (model.md §1.9); all off by
    default. Metrics stay against the true pose."""

    heading: Literal["encoders", "gyro"] | None = Field(
        None,
        description=(
            "Where odometry takes each period's turn: 'encoders' (R (dphi_R - dphi_L) / 2L) or 'gyro' (the IMU's "
            "integrated yaw rate, as a TurtleBot3 does with use_imu); the distance always comes from the encoders. "
            "Default: the [robot] preset's odometry (gyro on the TurtleBot3s), else encoders. Needs odometry = true."
        ),
    )
    gyro_noise_density: NonNegative | None = Field(
        None,
        le=1.0,
        description=(
            "The gyro's white rate noise [rad/s/sqrt(Hz)] (its datasheet's rate noise spectral density): a turn over "
            "T_c is off by density sqrt(T_c) standard deviations. Default: the [robot] preset's gyro."
        ),
    )
    gyro_bias: float | None = Field(
        None,
        ge=-1.0,
        le=1.0,
        description="The gyro's constant rate bias [rad/s], the heading drifting by bias t. Default: the preset's.",
    )

    @model_validator(mode="after")
    def _encoders_feed_odometry(self) -> SensingConfig:
        for field, what in (
            ("encoder_counts", "encoders feed"),
            ("fix_period", "an absolute fix corrects"),
            ("heading", "the heading source feeds"),
        ):
            if getattr(self, field) and not self.odometry:
                raise FieldError(
                    field,
                    f"{what} odometry, and odometry is off: {field} would change nothing",
                    f"set sensing.odometry = true, or leave {field} out",
                )
        return self

    def gyro(self, robot: RobotPreset | None) -> tuple[float, float] | None:
        """(noise density [rad/s/sqrt(Hz)], bias [rad/s]) of the gyro odometry turns with, given the ``[robot]
        preset`` ``robot`` (or None); None where the heading comes from the encoders."""
        chip = None if robot is None else robot.gyro
        heading = self.heading or ("gyro" if chip is not None else "encoders")
        if not self.odometry or heading == "encoders":
            return None
        density = (
            self.gyro_noise_density if self.gyro_noise_density is not None else getattr(chip, "noise_density", None)
        )
        bias = self.gyro_bias if self.gyro_bias is not None else getattr(chip, "bias", None)
        if density is None or bias is None:
            missing = "gyro_noise_density" if density is None else "gyro_bias"
            raise FieldError(
                f"sensing.{missing}",
                "a gyro heading needs its noise density and bias, and [robot] names no preset with a gyro",
                "give sensing.gyro_noise_density (the datasheet's rate noise spectral density in rad/s/sqrt(Hz)) "
                "and sensing.gyro_bias [rad/s], 0 for an ideal gyro; or set sensing.heading = 'encoders'",
            )
        return float(density), float(bias)

    def build(self, control_period: float, robot: RobotPreset | None = None) -> Sensing | None:
        """The runtime chain at ``control_period`` [s] for the ``[robot] preset`` ``robot`` (whose gyro odometry
        may turn with), or None when everything is off (the plant as it is)."""
        if not (self.actuation_delay or self.measurement_delay or self.odometry):
            return None
        gyro = self.gyro(robot)
        return Sensing(
            self.actuation_delay,
            self.measurement_delay,
            self.encoder_counts,
            self.odometry,
            control_period,
            self.fix_period,
            self.fix_gain,
            self.fix_position_std,
            self.fix_heading_std,
            gyro is not None,
            *(gyro or (0.0, 0.0)),
        )
