"""The scenario's plain sections: ``[simulation]``, ``[robot]``, ``[plant]``, ``[randomize]``, ``[disturbance]``,
``[noise]`` and ``[initial]`` (``[sensing]`` has a module of its own, :mod:`.sensing_config`).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, model_validator

from ..errors import ConfigError, did_you_mean
from ..layout import BODY
from ..model import MeasurementNoise, RobotParams, WheelDisturbance
from ..model.disturbance import SinusoidTorque
from ..model.params import RobotParameters
from ..parameters import Timing
from ._base import (
    MAX_CONTROL_PERIODS,
    MAX_SEED,
    Coordinate,
    FieldError,
    NonNegative,
    Pair,
    Positive,
    _Section,
)

# --- [simulation] -------------------------------------------------------------------------------


class SimulationConfig(Timing, _Section):  # control_period and substeps: Timing's declarations
    """Timing of the run, its seed, and what its statistics cover."""

    duration: Positive = Field(40.0, description="Length of the run [s].")
    metric_window: Pair | None = Field(
        None, description="[start, end] of the error statistics [s]; default the whole run."
    )
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Seed of every random draw of the run.")
    settling_threshold: Positive = Field(0.1, description="e_tr below which the run counts as settled [m].")
    divergence_error: Positive | None = Field(
        None,
        description=(
            "Tracking error at which a run is declared diverged [m]; default 3 (initial error + the reference's extent "
            "+ 2 L), which scales with the scenario (91.5 m for the paper's line, 3.8 m for a Burger's 0.5 m circle)."
        ),
    )

    lost_path_error: Positive | None = Field(
        None,
        description=(
            "Tracking error [m] beyond which a run that stays there for the last fifth of its metric window, without "
            "coming back, has lost the path (metrics lost_path, lost_path_time; benchmarks count it apart from the "
            "runs that track); default a quarter of the reference's width, the larger side of its bounding box."
        ),
    )

    @model_validator(mode="after")
    def _consistent(self) -> SimulationConfig:
        steps = self.duration / self.control_period
        if steps > MAX_CONTROL_PERIODS:
            raise FieldError(
                "duration",
                f"{self.duration:g} s at {self.control_period:g} s per period is "
                f"{steps:.3g} control periods, over the limit of {MAX_CONTROL_PERIODS:,}; "
                "shorten duration or lengthen control_period",
            )
        if abs(steps - round(steps)) > 1e-6 * steps or round(steps) < 1:
            raise FieldError(
                "duration",
                f"{self.duration:g} s is not a whole number of control periods "
                f"({self.control_period:g} s); choose a duration that is a multiple of it",
            )
        if self.metric_window is not None:
            start, end = self.metric_window
            if not 0.0 <= start < end <= self.duration + 1e-9:
                raise FieldError(
                    "metric_window",
                    f"{list(self.metric_window)} must satisfy 0 <= start < end <= duration ({self.duration:g} s)",
                )
        return self

    @property
    def n_steps(self) -> int:
        return round(self.duration / self.control_period)

    @property
    def window(self) -> Pair:
        return self.metric_window if self.metric_window is not None else (0.0, self.duration)


# --- [robot], [plant], [randomize] --------------------------------------------------------------


#: the keys of [robot] that are not the model's parameters
NOT_PARAMETERS = {"preset", "top_speed", "top_yaw_rate"}


class _PresetSection(_Section):
    """The root of ``[robot]``: ``preset`` stays its first key, before the parameters it fills."""

    preset: str | None = Field(
        None,
        description=(
            "A real robot by name (`ddtrack list robots`, docs/robots.md): every key of this section the robot has "
            "takes its published value; a key given here as well wins."
        ),
    )


class RobotConfig(RobotParameters, _PresetSection):
    """The nominal model: what the controller believes."""

    top_speed: Positive | None = Field(
        None,
        description=(
            "The robot's top speed [m/s] as its maker states it (a preset's and its motors' count too): a reference "
            "beyond it is warned, and so is a run whose wheels' rims go faster (speed_beyond_robot)."
        ),
    )
    top_yaw_rate: Positive | None = Field(None, description="The robot's top yaw rate [rad/s], likewise.")

    @model_validator(mode="before")
    @classmethod
    def _fill_from_preset(cls, data: Any) -> Any:
        """The preset's values under the keys the file gives (so the resolved scenario holds the numbers and reads
        back the same)."""
        if not isinstance(data, dict) or "preset" not in data or not isinstance(data["preset"], str):
            return data  # no preset, or not a string: the field's own check names it
        from ..robots import preset

        try:
            robot = preset(data["preset"])
        except ConfigError as exc:
            raise FieldError("preset", exc.message, exc.suggestion) from None
        values = {**robot.params, "wheel_inertia": robot.wheel_inertia}
        return {**{k: v for k, v in values.items() if k in cls.model_fields}, **data}

    def params(self) -> RobotParams:
        return RobotParams(**self.model_dump(exclude=NOT_PARAMETERS))

    def preset_robot(self) -> Any:
        """The :class:`~ddtrack.robots.RobotPreset` that ``preset`` names, or None."""
        from ..robots import preset

        return None if self.preset is None else preset(self.preset)


class MotorConfig(_Section):
    """The constants of each wheel's geared DC motor, referred to the wheel (model.md §1.7); a key left out keeps
    the [robot] preset's datasheet value."""

    resistance: Positive | None = Field(None, description="Armature resistance R_a [ohm].")
    torque_constant: Positive | None = Field(
        None, description="Torque constant k_t at the wheel, gear ratio included [N m/A]."
    )
    back_emf: Positive | None = Field(None, description="Back-EMF constant k_e at the wheel [V s/rad].")
    efficiency: Annotated[float, Field(gt=0.0, le=1.0)] | None = Field(
        None, description="Gearbox efficiency eta in (0, 1]: the wheel torque is eta k_t i."
    )
    supply_voltage: Positive | None = Field(None, description="The most voltage the driver applies, V_s [V].")
    current_limit: Positive | None = Field(
        None, description="The driver's current limit i_max [A]; default V_s / R_a without a preset."
    )
    drive: Literal["current", "pwm"] | None = Field(
        None,
        description=(
            "How the board turns a torque law's command into motor drive: 'current' (current control, the torque "
            "met inside the torque-speed curve) or 'pwm' (a voltage from the datasheet motor's model at the measured "
            "wheel speed, for servos without a current mode); default 'current' where the preset's servo has a "
            "current mode or no preset, else 'pwm' (the TurtleBot3 Burger's XL430)."
        ),
    )


#: the plant models that drive their wheels through motors (and so read plant.motor)
MOTOR_MODELS = ("motor_torque", "motor_velocity", "slip", "slip_velocity")


class PlantConfig(_Section):
    """The true robot; every key left out takes the [robot] value."""

    model: str = Field(
        "dynamic",
        description=(
            "The plant that simulates the true robot, by name (`ddtrack list plants`): 'dynamic' is the "
            "Lagrangian robot driven by wheel torques; 'slip' the same robot on a floor of finite grip "
            "(plant.floor_friction, plant.slip_speed, plant.caster_position); 'slip_velocity' that floor under the "
            "preset's motors and the plant.velocity_pi loop, for (v, omega) commands."
        ),
    )
    mass: Positive | None = Field(None, description="True total mass m [kg].")
    inertia: Positive | None = Field(None, description="True yaw inertia about the centre of mass I_C [kg m^2].")
    com_offset: Annotated[float, Field(ge=-1.0, le=1.0)] | None = Field(
        None, description="True signed offset d of the centre of mass ahead of the axle [m]."
    )
    wheel_radius: Annotated[float, Field(gt=0.0, le=2.0)] | None = Field(None, description="True wheel radius R [m].")
    half_axle: Annotated[float, Field(gt=0.0, le=5.0)] | None = Field(
        None, description="True half wheel separation L [m]."
    )
    max_torque: Positive | None = Field(None, description="True torque limit per wheel [N m].")
    viscous_friction: NonNegative | None = Field(None, description="True viscous wheel friction b_w [N m s/rad].")
    coulomb_friction: NonNegative | None = Field(None, description="True Coulomb wheel friction tau_c [N m].")
    friction_smoothing: Positive | None = Field(None, description="tanh smoothing wheel speed eps_f [rad/s].")
    wheel_inertia: Annotated[float, Field(ge=0.0, le=10.0)] | None = Field(
        None, description="True spin inertia J_w of each wheel, wheel plus N^2 J_rotor [kg m^2]."
    )
    lag: tuple[Positive, Positive, float, float, float, float] | None = Field(
        None,
        description=(
            "theta_1..theta_6 [s, s, s m/rad^2, 1, s/m, 1] of model 'lag' (the identified velocity lags, e.g. from "
            "`ddtrack identify`); default the [robot] preset's identified set."
        ),
    )
    motor: MotorConfig | None = Field(
        None,
        description=(
            "The motors of models " + ", ".join(f"'{m}'" for m in MOTOR_MODELS) + " (e.g. from `ddtrack identify "
            "--model motor`): a [plant.motor] table of resistance, torque_constant, back_emf, efficiency, "
            "supply_voltage, current_limit; keys left out keep the [robot] preset's datasheet values."
        ),
    )
    velocity_pi: tuple[NonNegative, NonNegative] = Field(
        (2.0, 50.0),
        description=(
            "[kp [V s/rad], ki [V/rad]] of the wheel-speed PI loop of models 'motor_velocity' and 'slip_velocity'; "
            "an assumed tuning: on a TurtleBot3 Burger driving straight its poles are real, -14 and -176 1/s. Tune it "
            "to your board."
        ),
    )
    floor_friction: Positive = Field(
        0.8,
        le=3.0,
        description=(
            "Friction coefficient of the floor (tyre on floor, 0.3 to 1.0 indoors): a run that needs more grip is "
            "flagged (metrics mu_required_max, time_above_floor_mu; warning friction_exceeds_floor). Models 'slip' "
            "and 'slip_velocity' use it as their friction coefficient mu."
        ),
    )

    slip_speed: Annotated[float, Field(gt=0.0, le=1.0)] = Field(
        1e-2,
        description=(
            "Slip speed eps_s [m/s] of models 'slip' and 'slip_velocity' (the floor's grip is plant.floor_friction): "
            "friction is fully developed once a wheel's contact slides faster than this; smaller is closer to perfect "
            "grip, and stiffer."
        ),
    )
    caster_position: Annotated[float, Field(ge=-5.0, le=5.0)] | None = Field(
        None,
        description=(
            "Body x l_c [m] of the frictionless caster, on the side of the centre of mass, for models 'slip' and "
            "'slip_velocity': the drive wheels carry m g (1 - d / l_c) / 2 each. Default the [robot] preset's, else "
            "none (m g / 2)."
        ),
    )
    com_height: Annotated[float, Field(ge=0.0, le=5.0)] | None = Field(
        None,
        description=(
            "Height h [m] of the centre of mass above the floor, for models 'slip' and 'slip_velocity': accelerating "
            "and turning move weight between the drive wheels and the caster, m h a_x / (2 l_c) onto each drive "
            "wheel and m h a_y / (2 L) from the inner wheel to the outer. Default the [robot] preset's, else 0 "
            "(no load transfer)."
        ),
    )

    @model_validator(mode="after")
    def _registered_model(self) -> PlantConfig:
        from .registry import is_plant, plant_kinds  # the registry imports this module's neighbours

        if not is_plant(self.model):
            raise FieldError("model", f"unknown plant '{self.model}'", did_you_mean(self.model, plant_kinds()))
        if self.motor is not None and self.model not in MOTOR_MODELS:
            raise FieldError(
                "motor",
                f"is read only by models {', '.join(MOTOR_MODELS)}, not '{self.model}'",
                "set plant.model to one of those, or drop [plant.motor]",
            )
        if self.lag is not None and self.model != "lag":
            raise FieldError(
                "lag", f"is read only by model 'lag', not '{self.model}'", 'set model = "lag", or drop lag'
            )
        return self


class ParameterDraw(_Section):
    """A random plant parameter, drawn per run: value * (1 + r) (``relative``) or value + r (``absolute``),
    r uniform on [-spread, spread] or normal with std = spread truncated at 3 std."""

    distribution: Literal["uniform", "normal"] = Field(
        "uniform", description=("r uniform on [-spread, spread], or normal with std = spread truncated at 3 std.")
    )
    relative: NonNegative | None = Field(None, description="Spread as a fraction of the value: value * (1 + r).")
    absolute: NonNegative | None = Field(None, description="Spread in the parameter's unit: value + r.")

    @model_validator(mode="after")
    def _one_spread(self) -> ParameterDraw:
        if (self.relative is None) == (self.absolute is None):
            raise FieldError(
                "relative", "give exactly one of 'relative' (fraction of the value) or 'absolute' (same unit)"
            )
        return self

    @property
    def reach(self) -> float:
        """Largest possible |r|."""
        spread = self.relative if self.relative is not None else self.absolute
        assert spread is not None  # the validator above requires one of the two
        return spread * (3.0 if self.distribution == "normal" else 1.0)


class RandomizeConfig(_Section):
    """Plant parameters drawn per run from the run's seed, each an inline table; left out: not drawn."""

    mass: ParameterDraw | None = Field(None, description="Draw of the plant's mass [kg].")
    inertia: ParameterDraw | None = Field(None, description="Draw of the plant's yaw inertia I_C [kg m^2].")
    com_offset: ParameterDraw | None = Field(None, description="Draw of the plant's centre-of-mass offset d [m].")
    wheel_radius: ParameterDraw | None = Field(None, description="Draw of the plant's wheel radius R [m].")
    half_axle: ParameterDraw | None = Field(None, description="Draw of the plant's half axle L [m].")
    viscous_friction: ParameterDraw | None = Field(
        None, description=("Draw of the plant's viscous wheel friction b_w [N m s/rad].")
    )
    coulomb_friction: ParameterDraw | None = Field(
        None, description=("Draw of the plant's Coulomb wheel friction tau_c [N m].")
    )


# --- [disturbance], [noise] ----------------------------------------------------------------------


class NoDisturbance(_Section):
    """No disturbance."""

    kind: Literal["none"] = "none"

    def build(self) -> WheelDisturbance:
        return WheelDisturbance()


class ConstantDisturbance(_Section):
    """Constant wheel torques, opposing the drive when positive."""

    kind: Literal["constant"]
    torque: Pair = Field(description="[right, left] wheel torque [N m].")

    def build(self) -> WheelDisturbance:
        return WheelDisturbance(bias=self.torque)


class SinusoidDisturbance(SinusoidTorque, _Section):  # the keys: SinusoidTorque's declarations
    """bias + amplitude * sin(frequency t + phase), per wheel (model.md §1.4's default)."""

    kind: Literal["sinusoid"]

    def build(self) -> WheelDisturbance:
        return WheelDisturbance(bias=self.bias, amplitude=self.amplitude, frequency=self.frequency, phase=self.phase)


class GaussianDisturbance(_Section):
    """Normal torques drawn from the run's seed and held over each control period."""

    kind: Literal["gaussian"]
    mean: Pair = Field((0.0, 0.0), description="[right, left] mean [N m].")
    std: tuple[NonNegative, NonNegative] = Field(description="[right, left] standard deviation [N m].")

    def build(self) -> WheelDisturbance:
        return WheelDisturbance(bias=self.mean, std=self.std)


DisturbanceConfig = Annotated[
    NoDisturbance | ConstantDisturbance | SinusoidDisturbance | GaussianDisturbance, Field(discriminator="kind")
]


class NoiseConfig(_Section):
    """Gaussian measurement noise on what the controller sees (the true state is recorded)."""

    position_std: NonNegative = Field(0.0, description="On x and y [m].")
    heading_std: NonNegative = Field(0.0, description="On theta [rad].")
    velocity_std: NonNegative = Field(0.0, description="On v [m/s].")
    yaw_rate_std: NonNegative = Field(0.0, description="On omega [rad/s].")

    def build(self) -> MeasurementNoise:
        p = self.position_std
        std = {"x": p, "y": p, "theta": self.heading_std, "v": self.velocity_std, "omega": self.yaw_rate_std}
        return MeasurementNoise(std=tuple(std[name] for name in BODY.names))


# --- [initial] -------------------------------------------------------------------------------


class InitialConfig(_Section):
    """The robot's state at t = 0."""

    pose: tuple[Coordinate, Coordinate, float] | None = Field(
        None, description="[x, y, theta] of the axle midpoint; default the reference pose at t = 0."
    )
    velocity: Pair = Field((0.0, 0.0), description="[v, omega] [m/s, rad/s].")
