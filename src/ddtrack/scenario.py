"""Scenario files: TOML -> validated pydantic models -> runtime objects, through registries (docs/guide.md).

Every user mistake becomes a :class:`~ddtrack.errors.ConfigError` naming the field (``robot.mass``)
and how to fix it. Unknown keys, NaN and inf are errors; a ``[plant]`` key left out takes the
``[robot]`` value.
"""

from __future__ import annotations

import csv
import errno
import json
import math
import tomllib
import types
import typing
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import jax
import jax.numpy as jnp
from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, model_validator

from .controllers import (
    Backstepping,
    Cascade,
    ComputedTorque,
    Controller,
    Emulator,
    NNAdaptiveBackstepping,
    WheelPD,
    emulator_scales,
    init_mlp,
    one_step_coefficient,
)
from .controllers.baselines import (
    MPPI,
    AdaptiveComputedTorque,
    LTVUnicycleLQR,
    MPPICost,
    RegulatedPurePursuit,
    SlidingModeTorque,
)
from .errors import ConfigError, did_you_mean
from .identification import identification_scale
from .model import DynamicPlant, KinematicPlant, MeasurementNoise, RobotParams, WheelDisturbance
from .sim import NominalPeriod
from .trajectories import Circle, FigureEight, Line, Sinusoid, Trajectory, polyline_path, square

Positive = Annotated[float, Field(gt=0.0)]
NonNegative = Annotated[float, Field(ge=0.0)]
Pair = tuple[float, float]
MAX_COORDINATE = 1e6  # [m]: 1000 km; far larger positions and lengths break the plots (ticks of 1e308 m)
Coordinate = Annotated[float, Field(ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Position = tuple[Coordinate, Coordinate]
Length = Annotated[float, Field(gt=0.0, le=MAX_COORDINATE)]


class FieldError(ValueError):
    """A validator's error about one field of its section (so the message names ``section.field``)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field


MAX_CONTROL_PERIODS = 2_000_000  # about 0.5 GB of recorded series; longer runs belong in chunks
MAX_SEED = 2**63 - 1  # jax.random.PRNGKey takes an int64
MAX_INPUT_BYTES = 64 * 2**20  # a scenario, sweep or waypoints file larger than this is a mistake


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True, strict=False)


# --- [simulation] -------------------------------------------------------------------------------


class SimulationConfig(_Section):
    """Timing of the run, its seed, and what its statistics cover."""

    duration: Positive = Field(40.0, description="Length of the run [s].")
    control_period: Positive = Field(0.01, description="Controller sampling period T_c [s].")
    substeps: int = Field(10, ge=1, le=1000, description="RK4 steps per control period.")
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


class RobotConfig(_Section):
    """The nominal model: what the controller believes."""

    mass: Positive = Field(10.0, description="Total mass m [kg].")
    inertia: Positive = Field(0.56, description="Yaw inertia about the centre of mass I_C [kg m^2].")
    com_offset: float = Field(
        0.05, ge=-1.0, le=1.0, description="Signed offset d of the centre of mass ahead of the axle [m]."
    )
    wheel_radius: Positive = Field(0.05, le=2.0, description="Wheel radius R [m].")
    half_axle: Positive = Field(0.25, le=5.0, description="Half the wheel separation L [m].")
    max_torque: Positive = Field(10.0, description="Torque limit per wheel [N m].")
    viscous_friction: NonNegative = Field(0.0, description="Viscous wheel friction b_w [N m s/rad].")
    coulomb_friction: NonNegative = Field(0.0, description="Coulomb wheel friction tau_c [N m].")
    friction_smoothing: Positive = Field(0.01, description="tanh smoothing wheel speed eps_f [rad/s].")

    def params(self) -> RobotParams:
        return RobotParams(**self.model_dump())


class PlantConfig(_Section):
    """The true robot; every key left out takes the [robot] value."""

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
    floor_friction: Positive = Field(
        0.8,
        le=3.0,
        description=(
            "Friction coefficient of the floor (tyre on floor, 0.3 to 1.0 indoors): a run that needs more grip is "
            "flagged (metrics mu_required_max, time_above_floor_mu; warning friction_exceeds_floor)."
        ),
    )


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


class SinusoidDisturbance(_Section):
    """bias + amplitude * sin(frequency t + phase), per wheel (model.md §1.4's default)."""

    kind: Literal["sinusoid"]
    bias: Pair = Field((0.0, 0.0), description="[right, left] constant part [N m].")
    amplitude: Pair = Field(description="[right, left] amplitude [N m].")
    frequency: NonNegative = Field(description="Angular frequency [rad/s].")
    phase: Pair = Field((0.0, 0.0), description="[right, left] phase [rad].")

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
        p, h = self.position_std, self.heading_std
        return MeasurementNoise(std=(p, p, h, self.velocity_std, self.yaw_rate_std))


# --- [trajectory] --------------------------------------------------------------------------------


class LineTrajectory(_Section):
    """Straight line at constant speed (the paper's y = x is heading = pi/4)."""

    kind: Literal["line"]
    speed: Positive = Field(0.5, description="v_r [m/s].")
    start: Position = Field((0.0, 0.0), description="Position at t = 0 [m].")
    heading: float = Field(0.0, description="Direction [rad].")

    def build(self) -> Trajectory:
        return Line(start=self.start, heading=self.heading, speed=self.speed)


class SquareTrajectory(_Section):
    """The paper's square, counter-clockwise from ``corner`` with heading 0 (model.md §4.3)."""

    kind: Literal["square"]
    corner: Position = Field((10.0, 0.0), description="Starting corner C0 [m].")
    side: Length = Field(10.0, description="Side S [m].")
    speed: Positive = Field(0.5, description="v_r [m/s].")
    corner_radius: NonNegative = Field(0.0, description="Fillet radius at C1..C3 [m]; 0 = sharp corners.")

    @model_validator(mode="after")
    def _fits(self) -> SquareTrajectory:
        if 2.0 * self.corner_radius > self.side:
            raise FieldError(
                "corner_radius",
                f"{self.corner_radius:g} m does not fit on a side of {self.side:g} m; use at most side / 2",
            )
        try:
            self.build()
        except ValueError as exc:  # a side too small for distinct corners (5e-324 m)
            raise FieldError("side", f"{self.side:g} m is too small for distinct corners ({exc})") from None
        return self

    def build(self) -> Trajectory:
        return square(corner=self.corner, side=self.side, speed=self.speed, corner_radius=self.corner_radius)


class CircleTrajectory(_Section):
    """Circle at constant speed."""

    kind: Literal["circle"]
    center: Position = Field((0.0, 0.0), description="Centre [m].")
    radius: Length = Field(2.0, description="Radius [m].")
    speed: Positive = Field(0.5, description="v_r [m/s].")
    start_angle: float = Field(-math.pi / 2, description="Polar angle of the start point about the centre [rad].")
    clockwise: bool = Field(False, description="Direction of travel.")

    def build(self) -> Trajectory:
        return Circle(
            center=self.center,
            radius=self.radius,
            speed=self.speed,
            start_angle=self.start_angle,
            clockwise=self.clockwise,
        )


class FigureEightTrajectory(_Section):
    """Lemniscate of Gerono (speed between 0.66*size*w and 1.41*size*w, w = 2 pi / period: it never stops)."""

    kind: Literal["figure_eight"]
    center: Position = Field((0.0, 0.0), description="Crossing point [m].")
    size: Length = Field(3.0, description="Half-width [m].")
    period: Positive = Field(60.0, description="Time for both lobes [s].")

    def build(self) -> Trajectory:
        return FigureEight(center=self.center, size=self.size, period=self.period)


class SinusoidTrajectory(_Section):
    """A sine wave about a straight axis run at constant speed."""

    kind: Literal["sinusoid"]
    start: Position = Field((0.0, 0.0), description="Position at t = 0 [m].")
    heading: float = Field(0.0, description="Direction of the axis [rad].")
    speed: Positive = Field(0.5, description="Speed along the axis [m/s].")
    amplitude: Annotated[float, Field(ge=0.0, le=MAX_COORDINATE)] = Field(1.0, description="Lateral amplitude [m].")
    wavelength: Length = Field(10.0, description="Wavelength along the axis [m].")

    def build(self) -> Trajectory:
        return Sinusoid(
            start=self.start,
            heading=self.heading,
            speed=self.speed,
            amplitude=self.amplitude,
            wavelength=self.wavelength,
        )


class WaypointsTrajectory(_Section):
    """A polyline through waypoints at constant speed with rounded corners.

    ``file`` is a CSV of x,y rows (an optional header line), relative to the scenario file and inside its
    folder tree (an absolute path, or a ``..`` or symlink leading out, is an error); the resolved scenario
    holds the points inline instead.
    """

    kind: Literal["waypoints"]
    file: str | None = Field(None, description="CSV file of x,y rows, relative to the scenario file.")
    points: list[Position] | None = Field(None, description="Inline [[x, y], ...] instead of a file [m].")
    speed: Positive = Field(0.5, description="v_r [m/s].")
    corner_radius: NonNegative = Field(0.0, description="Fillet radius at interior waypoints [m].")
    loop: bool = Field(False, description="Repeat the path; otherwise the reference stops at the end.")

    @model_validator(mode="before")
    @classmethod
    def _read_file(cls, data: Any, info: ValidationInfo) -> Any:
        if isinstance(data, dict) and data.get("file") is not None and data.get("points") is None:
            if not isinstance(data["file"], str):
                return data  # the type error is reported by the field
            base = Path((info.context or {}).get("base_dir", "."))
            try:
                data = {**data, "points": read_waypoints(_contained(base, data["file"])), "file": None}
            except ValueError as exc:
                raise FieldError("file", str(exc)) from None
        if isinstance(data, dict) and isinstance(data.get("points"), list):  # TOML arrays -> [x, y] tuples
            data = {**data, "points": [tuple(p) if isinstance(p, list) else p for p in data["points"]]}
        return data

    @model_validator(mode="after")
    def _valid_path(self) -> WaypointsTrajectory:
        if self.points is None:
            raise FieldError("points", "give 'file' (a CSV of x,y rows) or 'points' ([[x, y], ...])")
        if self.file is not None:
            raise FieldError("file", "give only one of 'file' and 'points'")
        try:
            self.build()
        except ValueError as exc:  # names the bad point or leg
            raise FieldError("points", str(exc)) from None
        return self

    def build(self) -> Trajectory:
        assert self.points is not None, "a waypoint file is read into points when the scenario loads"
        return polyline_path(self.points, speed=self.speed, corner_radius=self.corner_radius, loop=self.loop)


TrajectoryConfig = Annotated[
    LineTrajectory
    | SquareTrajectory
    | CircleTrajectory
    | FigureEightTrajectory
    | SinusoidTrajectory
    | WaypointsTrajectory,
    Field(discriminator="kind"),
]


def _contained(base: Path, name: str) -> Path:
    """``base / name``, refused (ValueError) unless it stays inside ``base``'s folder tree once ``..`` and symlinks
    are resolved: a scenario, perhaps from someone else, can make ddtrack read only files beside it or below it."""
    if Path(name).is_absolute():
        raise ValueError(
            f"'{name}' is an absolute path; a waypoints file is read relative to the scenario file, "
            "inside its folder: copy the CSV beside the scenario and give its file name"
        )
    path = base / name
    if not path.resolve().is_relative_to(base.resolve()):
        raise ValueError(
            f"'{name}' leads outside the scenario's folder ('..' or a symlink); copy the CSV beside "
            "the scenario and give its file name"
        )
    return path


def read_waypoints(path: Path) -> list[Pair]:
    """Read x,y rows from a CSV file: ``#`` comment lines and blank lines anywhere, then one optional header line
    before the first point (``x,y``)."""
    try:
        text = read_input(path).decode("utf-8")
    except FileNotFoundError:
        raise ValueError(f"waypoints file '{path}' does not exist") from None
    except UnicodeDecodeError:
        raise ValueError(f"waypoints file '{path}' is not UTF-8 text; give a CSV of x,y rows") from None
    except OSError as exc:
        raise ValueError(f"waypoints file '{path}' cannot be read ({exc.strerror})") from None
    points, header_seen = [], False
    for number, row in enumerate(csv.reader(text.splitlines()), start=1):
        if not row or all(not cell.strip() for cell in row) or row[0].lstrip().startswith("#"):
            continue  # a blank line or a comment
        try:
            if len(row) != 2:
                raise ValueError
            points.append((float(row[0]), float(row[1])))
        except ValueError:
            if not points and not header_seen:
                header_seen = True
                continue  # a header line
            raise ValueError(
                f"waypoints file '{path}' line {number}: expected two numbers 'x,y', got {','.join(row)[:40]!r}"
            ) from None
    return points


# --- [initial], [controller] ---------------------------------------------------------------------


class InitialConfig(_Section):
    """The robot's state at t = 0."""

    pose: tuple[Coordinate, Coordinate, float] | None = Field(
        None, description="[x, y, theta] of the axle midpoint; default the reference pose at t = 0."
    )
    velocity: Pair = Field((0.0, 0.0), description="[v, omega] [m/s, rad/s].")


class _InnerLoopConfig(_Section):
    """The keys of a controller that outputs (v_c, omega_c) over the shared inner loop (docs/architecture.md).

    The inner loop is computed torque (eq. 11) or wheel-space PD (model.md §2.6), so every velocity-level
    controller meets the same dynamics layer.
    """

    kind: str  # each controller narrows it to its Literal; declared here so that it stays the first key
    inner: Literal["computed_torque", "pd"] = Field("computed_torque", description="Inner (dynamic) loop.")
    kc: tuple[Positive, Positive] = Field((10.0, 10.0), description="K_c of eq. 11 (computed torque) [1/s].")
    kp: Positive = Field(0.125, description="Wheel PD proportional gain [N m s/rad].")
    kd: NonNegative = Field(0.0, description="Wheel PD derivative gain [N m s^2/rad].")

    def build_inner(self, nominal: RobotParams, control_period: float) -> ComputedTorque | WheelPD:
        """The inner loop on the ``nominal`` model, sampled every ``control_period`` [s]."""
        if self.inner == "computed_torque":
            return ComputedTorque(nominal, kc=self.kc)
        return WheelPD(nominal, kp=self.kp, kd=self.kd, control_period=control_period)

    def inner_bandwidth(self, nominal: RobotParams) -> tuple[float, float]:
        """(k_v, k_omega) [1/s] of the inner loop on the nominal model (model.md §2.5, 2.6)."""
        if self.inner == "computed_torque":
            return self.kc
        r2 = nominal.wheel_radius**2
        return (2 * self.kp / (nominal.mass * r2), 2 * self.kp * nominal.half_axle**2 / (nominal.inertia_axle * r2))


class _KanayamaConfig(_InnerLoopConfig):
    """The keys of Kanayama's law (paper eq. 12), shared by backstepping and its NN-adaptive form."""

    gains: tuple[Positive, Positive, Positive] = Field((1.0, 55.0, 15.0), description="[Kx, Ky, Ktheta].")
    max_velocity: Positive = Field(2.0, description="Clamp on |v_c| [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Clamp on |omega_c| [rad/s].")
    strict: bool = Field(False, description="Add the strict-backstepping cross term (computed torque only).")

    @model_validator(mode="after")
    def _strict_needs_computed_torque(self) -> _KanayamaConfig:
        if self.strict and self.inner != "computed_torque":
            raise FieldError("strict", 'strict = true needs inner = "computed_torque" (the cross term enters eq. 11)')
        return self


class BacksteppingConfig(_KanayamaConfig):
    """Kanayama backstepping over a computed-torque or PD inner loop (paper eqs. 7, 11, 12, 21)."""

    kind: Literal["backstepping"]

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade:
        """The controller; ``key`` seeds whatever it draws at construction (nothing, for backstepping)."""
        kx, ky, ktheta = self.gains
        outer = Backstepping(
            kx=kx,
            ky=ky,
            ktheta=ktheta,
            max_velocity=self.max_velocity,
            max_yaw_rate=self.max_yaw_rate,
            strict=self.strict,
        )
        return Cascade(outer, self.build_inner(nominal, control_period))


PositiveTriple = tuple[Positive, Positive, Positive]


class NNAdaptiveConfig(_KanayamaConfig):
    """The paper's NN-adaptive backstepping: gains tuned online through an emulator network (model.md §3)."""

    kind: Literal["nn_adaptive_backstepping"] = "nn_adaptive_backstepping"
    rates: tuple[NonNegative, NonNegative, NonNegative] = Field(
        (200.0, 200.0, 200.0),
        description=("Lambda: gain adaptation rates [1/s] with the normalised Jacobian; 0 gives backstepping."),
    )
    gain_momentum: Annotated[float, Field(ge=0.0, lt=1.0)] = Field(0.0, description="beta_K, momentum of the gains.")
    max_step: PositiveTriple = Field((0.05, 5.0, 0.5), description="Largest gain change per control period.")
    gain_min: PositiveTriple = Field((0.1, 1.0, 0.1), description="Lower gain bounds (Kx, Ky, Ktheta).")
    gain_max: PositiveTriple = Field((10.0, 600.0, 60.0), description="Upper gain bounds (Kx, Ky, Ktheta).")
    gate_error: Positive = Field(0.5, description="Gains adapt only while e_tr is below this [m].")
    leakage: NonNegative = Field(0.0, description="sigma: pull of the gains back to their initial values [1/s].")
    gamma: tuple[NonNegative, NonNegative, NonNegative] = Field(
        (1.0, 50.0, 1.0), description=("Gamma of the cost eq. 22, weights of (e_x, e_y, e_theta).")
    )
    jacobian: Literal["network", "analytic", "quasi_static", "model", "model_sensitivity"] = Field(
        "network",
        description=(
            "Plant Jacobian of the gain law: the emulator's (eq. 34), analytic per-sample, "
            "quasi-static, the nominal model's by autodiff, or that in the multi-step sensitivity."
        ),
    )
    error_jacobian: Literal["exact", "paper"] = Field(
        "exact", description=("d e_p / d q: exact (model.md §3.3) or the paper's approximation -T_e.")
    )
    emulator: Literal["E1", "E0"] = Field(
        "E1", description=("E1: input (v_c, omega_c, v, omega); E0: the paper's (v_c, omega_c).")
    )
    hidden_units: int = Field(20, ge=1, le=1000, description="Hidden tanh units N_h.")
    learning_rate: Positive = Field(0.2, description="Emulator backpropagation rate eta.")
    momentum: Annotated[float, Field(ge=0.0, lt=1.0)] = Field(0.3, description="Emulator momentum beta.")
    gradient_clip: Positive = Field(5.0, description="Emulator gradient-norm clip.")
    online_learning: bool = Field(True, description="Train the emulator on every new sample.")
    learn_saturated: bool = Field(
        False,
        description=("Also train the emulator online on transitions during which a clamp or the torque limit acted."),
    )
    structured_jacobian: bool = Field(False, description="Keep only the two direct, positive Jacobian entries.")
    identification: bool = Field(True, description="Pre-train the emulator on an identification run.")
    identification_duration: Positive = Field(60.0, le=3600.0, description="Length of the identification run [s].")
    epochs: int = Field(100, ge=1, le=10_000, description="N_c: pre-training epochs over the identification data.")
    identification_speed: tuple[Positive, Positive] | None = Field(
        None,
        description=(
            "Peak (speed [m/s], yaw rate [rad/s]) of the identification reference; default "
            "(min(0.9, 0.8 max_velocity), min(0.7, 0.8 max_yaw_rate)), inside the clamps."
        ),
    )
    dither: tuple[NonNegative, NonNegative] | None = Field(
        None,
        description=(
            "Command dither (sigma_v [m/s], sigma_omega [rad/s]) of the identification run; default "
            "(0.05, 0.1) scaled like the identification reference."
        ),
    )
    freeze_time: NonNegative | None = Field(
        None, description=("No gain change before this time [s]; default 0 with identification, 2 without.")
    )

    @model_validator(mode="after")
    def _gains_inside_bounds(self) -> NNAdaptiveConfig:
        for name, low, gain, high in zip(("Kx", "Ky", "Ktheta"), self.gain_min, self.gains, self.gain_max, strict=True):
            if not low <= gain <= high:
                raise FieldError("gains", f"{name} = {gain:g} lies outside [gain_min, gain_max] = [{low:g}, {high:g}]")
        if self.identification_speed is not None:  # identification data taken against a clamp teaches nothing
            (v, w), (v_max, w_max) = self.identification_speed, (self.max_velocity, self.max_yaw_rate)
            if v > v_max or w > w_max:
                raise FieldError(
                    "identification_speed",
                    f"[{v:g}, {w:g}] exceeds the clamps max_velocity = "
                    f"{v_max:g} m/s, max_yaw_rate = {w_max:g} rad/s; keep each below about 80 % "
                    "of its clamp",
                )
        return self

    def identification_scale(self) -> tuple[float, float]:
        """(k_v, k_omega) of the identification reference, dither and emulator scales; (1, 1) for the paper's robot."""
        return identification_scale(self.max_velocity, self.max_yaw_rate, self.identification_speed)

    def identification_dither(self) -> tuple[float, float]:
        """The dither's (sigma_v, sigma_omega): given, or the paper's (0.05, 0.1) scaled like the reference."""
        k_v, k_w = self.identification_scale()
        return self.dither if self.dither is not None else (0.05 * k_v, 0.1 * k_w)

    def _nominal_period(self, nominal: RobotParams, control_period: float) -> NominalPeriod | None:
        """One period of the nominal model under the inner loop, RK4 steps of at most 1 ms (the "model" Jacobians)."""
        if not self.jacobian.startswith("model"):
            return None
        return NominalPeriod(
            DynamicPlant(nominal),
            self.build_inner(nominal, control_period),
            control_period,
            substeps=max(1, math.ceil(control_period / 1e-3 - 1e-9)),
        )

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade:
        """The controller with a freshly initialised emulator (its identification is done by the runner)."""
        uses_velocity = self.emulator == "E1"
        k_v, k_w = self.identification_scale()  # the emulator's range is the identification's
        emulator = Emulator(
            init_mlp(key, 4 if uses_velocity else 2, self.hidden_units, 3),
            emulator_scales(
                control_period, uses_velocity=uses_velocity, max_velocity=k_v * 1.0, max_yaw_rate=k_w * 2.0
            ),
            uses_velocity,
        )
        bandwidth = jnp.asarray(self.inner_bandwidth(nominal), float)
        freeze = self.freeze_time if self.freeze_time is not None else (0.0 if self.identification else 2.0)
        outer = NNAdaptiveBackstepping(
            gains=self.gains,
            emulator=emulator,
            control_period=control_period,
            analytic_coefficients=one_step_coefficient(bandwidth, control_period),
            rates=self.rates,
            gain_momentum=self.gain_momentum,
            max_step=self.max_step,
            gain_min=self.gain_min,
            gain_max=self.gain_max,
            gate_error=self.gate_error,
            leakage=self.leakage,
            gamma=self.gamma,
            learning_rate=self.learning_rate,
            momentum=self.momentum,
            clip_norm=self.gradient_clip,
            freeze_time=freeze,
            max_velocity=self.max_velocity,
            max_yaw_rate=self.max_yaw_rate,
            jacobian=self.jacobian,
            error_jacobian=self.error_jacobian,
            online_learning=self.online_learning,
            learn_saturated=self.learn_saturated,
            structured_jacobian=self.structured_jacobian,
            strict=self.strict,
            nominal_period=self._nominal_period(nominal, control_period),
        )
        return Cascade(outer, self.build_inner(nominal, control_period))


class LTVLQRConfig(_InnerLoopConfig):
    """LTV/LQR unicycle tracker (WPILib's LTVUnicycleController) over a computed-torque or PD inner loop."""

    kind: Literal["ltv_lqr"]
    q_tolerance: PositiveTriple = Field(
        (0.0625, 0.125, 2.0),
        description=(
            "Tolerated (e_x [m], e_y [m], e_theta [rad]); Q = diag(1/q^2) (Bryson's rule, WPILib's defaults)."
        ),
    )
    r_tolerance: tuple[Positive, Positive] = Field(
        (1.0, 2.0), description=("Tolerated velocity correction (v [m/s], omega [rad/s]); R = diag(1/r^2).")
    )
    min_velocity: Positive = Field(
        1e-4, description=("|v_r| below this is linearised at this speed, where e_y stays controllable [m/s].")
    )
    dare_iterations: int = Field(
        32,
        ge=1,
        le=64,
        description=("Doubling steps of the Riccati solver; 20 converge at min_velocity 1e-4 m/s and T_c 10 ms."),
    )
    max_velocity: Positive = Field(2.0, description="Clamp on |v_c| [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Clamp on |omega_c| [rad/s].")

    @model_validator(mode="after")
    def _min_velocity_below_clamp(self) -> LTVLQRConfig:
        if self.min_velocity >= self.max_velocity:
            raise FieldError(
                "min_velocity",
                f"{self.min_velocity:g} m/s must be below max_velocity ({self.max_velocity:g} m/s); WPILib uses 1e-4",
            )
        return self

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade:
        """The controller; ``key`` is unused (nothing is drawn)."""
        outer = LTVUnicycleLQR(
            q_tolerance=self.q_tolerance,
            r_tolerance=self.r_tolerance,
            control_period=control_period,
            min_velocity=self.min_velocity,
            max_velocity=self.max_velocity,
            max_yaw_rate=self.max_yaw_rate,
            dare_iterations=self.dare_iterations,
        )
        # the same inner loops as backstepping, so the comparison is fair (docs/architecture.md)
        return Cascade(outer, self.build_inner(nominal, control_period))


class SlidingModeConfig(_Section):
    """Kanayama backstepping over a sliding-mode inner loop with a boundary layer (Slotine and Li 7.1-7.2)."""

    kind: Literal["sliding_mode_backstepping"]
    gains: PositiveTriple = Field((1.0, 55.0, 15.0), description="[Kx, Ky, Ktheta] of the outer law (eq. 12).")
    kc: tuple[Positive, Positive] = Field((10.0, 10.0), description="K_c of eq. 11, the linear part [1/s].")
    switching_gain: tuple[NonNegative, NonNegative] = Field(
        (1.0, 2.0),
        description=(
            "K_s (v [m/s^2], omega [rad/s^2]): must exceed the matched disturbance as an acceleration; 0 gives "
            "computed torque."
        ),
    )
    boundary_layer: tuple[Positive, Positive] = Field(
        (0.02, 0.04),
        description=(
            "phi, half-width of the boundary layer (v [m/s], omega [rad/s]): wider chatters less, tracks looser."
        ),
    )
    max_velocity: Positive = Field(2.0, description="Clamp on |v_c| [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Clamp on |omega_c| [rad/s].")

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade:
        """The controller; ``key`` is unused (nothing is drawn)."""
        kx, ky, ktheta = self.gains
        outer = Backstepping(
            kx=kx, ky=ky, ktheta=ktheta, max_velocity=self.max_velocity, max_yaw_rate=self.max_yaw_rate
        )
        return Cascade(
            outer,
            SlidingModeTorque(
                nominal, kc=self.kc, switching_gain=self.switching_gain, boundary_layer=self.boundary_layer
            ),
        )


class KinematicBacksteppingConfig(_Section):
    """Kanayama's law on the unicycle with ideal velocity tracking: a reference point (paper eq. 12, model.md §2.4)."""

    kind: Literal["kinematic_backstepping"]
    gains: PositiveTriple = Field((1.0, 55.0, 15.0), description="[Kx, Ky, Ktheta].")
    max_velocity: Positive = Field(2.0, description="Clamp on |v_c| [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Clamp on |omega_c| [rad/s].")

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Backstepping:
        """The velocity law alone, which drives the kinematic plant (:attr:`Setup.plant`); ``key`` is unused."""
        kx, ky, ktheta = self.gains
        return Backstepping(kx=kx, ky=ky, ktheta=ktheta, max_velocity=self.max_velocity, max_yaw_rate=self.max_yaw_rate)


class RegulatedPurePursuitConfig(_InnerLoopConfig):
    """Regulated pure pursuit (Macenski et al. 2023, Nav2) keeping pace with the reference, over an inner loop."""

    kind: Literal["regulated_pure_pursuit"]
    lookahead_time: NonNegative = Field(
        1.5, description=("Lookahead L = |v| * lookahead_time, clipped to [min_lookahead, max_lookahead] [s].")
    )
    min_lookahead: Positive = Field(0.3, description="Smallest lookahead distance [m].")
    max_lookahead: Positive = Field(0.9, description="Largest lookahead distance [m]; equal to min_lookahead: fixed.")
    pace_gain: NonNegative = Field(
        1.0, description=("k_s: desired speed v_r + k_s e_x, so the along-track error e_x decays at this rate [1/s].")
    )
    min_radius: NonNegative = Field(
        0.9,
        description=(
            "Arcs tighter than this radius slow the robot by radius / min_radius; 0 turns the regulation off [m]."
        ),
    )
    min_regulated_speed: NonNegative = Field(
        0.25, description=("The curvature regulation never slows below this (nor above the desired speed) [m/s].")
    )
    approach_distance: Positive = Field(
        0.6,
        description=("Slow down in proportion to the distance to where the reference comes to rest, within this [m]."),
    )
    min_approach_speed: NonNegative = Field(0.05, description="Floor of the approach slow-down [m/s].")
    rotate_to_heading: bool = Field(True, description="Rotate in place while the carrot is far off the heading.")
    rotate_min_angle: Annotated[float, Field(gt=0.0, le=math.pi)] = Field(
        0.785, description=("Bearing of the carrot beyond which the robot rotates in place [rad].")
    )
    rotate_yaw_rate: Positive = Field(1.8, description="Yaw rate of the rotation in place [rad/s].")
    search_horizon: Positive = Field(
        5.0,
        description=(
            "The carrot is searched on the reference over [t, t + search_horizon] [s]; must cover the lookahead."
        ),
    )
    search_samples: int = Field(50, ge=2, le=1000, description="Segments of that search (linear between samples).")
    max_velocity: Positive = Field(2.0, description="Clamp on v_c [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Clamp on |omega_c|, by slowing down on the same arc [rad/s].")

    @model_validator(mode="after")
    def _consistent(self) -> RegulatedPurePursuitConfig:
        if self.min_lookahead > self.max_lookahead:
            raise FieldError(
                "min_lookahead", f"{self.min_lookahead:g} m exceeds max_lookahead ({self.max_lookahead:g} m)"
            )
        if self.rotate_yaw_rate > self.max_yaw_rate:
            raise FieldError(
                "rotate_yaw_rate", f"{self.rotate_yaw_rate:g} rad/s exceeds max_yaw_rate ({self.max_yaw_rate:g} rad/s)"
            )
        return self

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array, *, trajectory: Trajectory) -> Cascade:
        """The controller searching ``trajectory`` for its carrot; ``key`` is unused (nothing is drawn)."""
        outer = RegulatedPurePursuit(
            trajectory=trajectory,
            lookahead_time=self.lookahead_time,
            min_lookahead=self.min_lookahead,
            max_lookahead=self.max_lookahead,
            pace_gain=self.pace_gain,
            min_radius=self.min_radius,
            min_regulated_speed=self.min_regulated_speed,
            approach_distance=self.approach_distance,
            min_approach_speed=self.min_approach_speed,
            rotate_min_angle=self.rotate_min_angle,
            rotate_yaw_rate=self.rotate_yaw_rate,
            max_velocity=self.max_velocity,
            max_yaw_rate=self.max_yaw_rate,
            search_horizon=self.search_horizon,
            search_samples=self.search_samples,
            rotate_to_heading=self.rotate_to_heading,
        )
        # the same inner loops as backstepping, so the comparison is fair (docs/architecture.md)
        return Cascade(outer, self.build_inner(nominal, control_period))


class AdaptiveBacksteppingConfig(_Section):
    """Kanayama backstepping over computed torque that estimates m, I_C (and b_w) online (Fukao et al. 2000)."""

    kind: Literal["adaptive_backstepping"]
    gains: PositiveTriple = Field((1.0, 55.0, 15.0), description="[Kx, Ky, Ktheta] of the outer law (eq. 12).")
    kc: tuple[Positive, Positive] = Field(
        (10.0, 10.0),
        description=("K_c of eq. 11: the inner loop's bandwidth on the nominal model, K_D = M_bar K_c [1/s]."),
    )
    adaptation_gain: tuple[NonNegative, NonNegative, NonNegative] = Field(
        (500.0, 5.0, 1e-4),
        description=(
            "Gamma of the estimates of (m [kg s^2/m^2], I_C [kg m^2 s^2], viscous friction b_w [kg m^2]); "
            "0 freezes that estimate at the [robot] value."
        ),
    )
    estimate_range: tuple[Positive, Positive] = Field(
        (0.5, 2.0), description=("Projection bounds of the m and I_C estimates, as multiples of the [robot] values.")
    )
    max_friction: NonNegative = Field(
        0.05,
        description=(
            "Upper projection bound of the b_w estimate (the lower is 0), at least the [robot] value [N m s/rad]."
        ),
    )
    max_velocity: Positive = Field(2.0, description="Clamp on |v_c| [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Clamp on |omega_c| [rad/s].")
    strict: bool = Field(False, description="Add the strict-backstepping cross term to the torque law.")

    @model_validator(mode="after")
    def _range_holds_the_nominal(self) -> AdaptiveBacksteppingConfig:
        low, high = self.estimate_range
        if not low <= 1.0 <= high or low == high:
            raise FieldError(
                "estimate_range",
                f"{list(self.estimate_range)} must satisfy low <= 1 <= high, "
                "low < high (the estimates start at the [robot] values); e.g. [0.5, 2.0]",
            )
        return self

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade:
        """The controller; ``key`` is unused (nothing is drawn)."""
        kx, ky, ktheta = self.gains
        outer = Backstepping(
            kx=kx,
            ky=ky,
            ktheta=ktheta,
            max_velocity=self.max_velocity,
            max_yaw_rate=self.max_yaw_rate,
            strict=self.strict,
        )
        low, high = self.estimate_range
        inner = AdaptiveComputedTorque(
            nominal,
            kc=self.kc,
            gamma=self.adaptation_gain,
            control_period=control_period,
            lower=(low * nominal.mass, low * nominal.inertia, 0.0),
            upper=(high * nominal.mass, high * nominal.inertia, max(self.max_friction, nominal.viscous_friction)),
        )
        return Cascade(outer, inner)


class MPPIConfig(_Section):
    """Model predictive path integral control of the wheel torques on the nominal model (Williams et al. 2017)."""

    kind: Literal["mppi"]
    samples: int = Field(64, ge=1, le=10_000, description="K: torque sequences sampled per control period.")
    horizon: int = Field(20, ge=1, le=500, description="H: steps per sequence.")
    model_step: Positive = Field(
        0.05,
        le=10.0,
        description=("dt: how long each step of a sequence holds its torque, and the rollout's Euler step [s]."),
    )
    temperature: Positive = Field(
        1.0,
        description=(
            "lambda of the weights exp(-(S - min S) / lambda), in cost units: lower trusts the best samples more."
        ),
    )
    noise_std: tuple[Positive, Positive] = Field(
        (0.2, 0.2), description=("sigma of the sampled torque perturbations, [right, left] wheel [N m].")
    )
    position_weight: NonNegative = Field(100.0, description="q_p of the squared position error, per step [1/m^2].")
    heading_weight: NonNegative = Field(1.0, description="q_th of the squared heading error, per step [1/rad^2].")
    velocity_weight: NonNegative = Field(1.0, description=("q_nu of |nu - nu_r|^2, per step [s^2/m^2 and s^2/rad^2]."))
    effort_weight: NonNegative = Field(0.01, description="r of the squared wheel torques, per step [1/(N m)^2].")
    terminal_weight: NonNegative = Field(
        10.0, description=("q_T: the last step's position and heading terms count again, times this.")
    )
    limit_weight: NonNegative = Field(
        1000.0,
        description=("q_lim of the squared excess of |v| over max_velocity and |omega| over max_yaw_rate, per step."),
    )
    max_velocity: Positive = Field(2.0, description="Soft limit on |v| of the rollouts [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Soft limit on |omega| of the rollouts [rad/s].")

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array, *, trajectory: Trajectory) -> MPPI:
        """The controller previewing ``trajectory``; it samples with the key the simulator hands to ``init``,
        so ``key`` is unused."""
        cost = MPPICost(
            position=self.position_weight,
            heading=self.heading_weight,
            velocity=self.velocity_weight,
            effort=self.effort_weight,
            terminal=self.terminal_weight,
            limit=self.limit_weight,
            max_velocity=self.max_velocity,
            max_yaw_rate=self.max_yaw_rate,
        )
        return MPPI(
            nominal,
            trajectory,
            cost=cost,
            model_step=self.model_step,
            control_period=control_period,
            temperature=self.temperature,
            noise_std=self.noise_std,
            samples=self.samples,
            horizon=self.horizon,
        )


ControllerConfig = Annotated[
    BacksteppingConfig
    | NNAdaptiveConfig
    | LTVLQRConfig
    | SlidingModeConfig
    | KinematicBacksteppingConfig
    | RegulatedPurePursuitConfig
    | AdaptiveBacksteppingConfig
    | MPPIConfig,
    Field(discriminator="kind"),
]

#: the controllers whose outer law is Kanayama's, so that they have gains (Kx, Ky, Ktheta)
KanayamaControllerConfig = (
    BacksteppingConfig | NNAdaptiveConfig | SlidingModeConfig | KinematicBacksteppingConfig | AdaptiveBacksteppingConfig
)


def kanayama_gains(config: ControllerConfig) -> tuple[float, float, float]:
    """(Kx, Ky, Ktheta) of a controller with Kanayama's outer law; a ConfigError naming ``controller.kind`` if not."""
    if isinstance(config, KanayamaControllerConfig):
        return config.gains
    raise ConfigError("controller.kind", f"'{config.kind}' has no Kanayama gains (Kx, Ky, Ktheta)")


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
    simulation, robot, plant, randomize, disturbance, noise, trajectory, initial, controller
        The file's sections: the run's timing and seed, the nominal robot the controller believes in, the true
        plant, its random draws, the wheel-torque disturbance, the measurement noise, the reference, the
        initial state and the controller.
    """

    name: str = Field(min_length=1, max_length=200, description="Name of the scenario.")
    description: str = Field("", max_length=10_000, description="Free text.")
    simulation: SimulationConfig = SimulationConfig()
    robot: RobotConfig = RobotConfig()
    plant: PlantConfig = PlantConfig()
    randomize: RandomizeConfig = RandomizeConfig()
    disturbance: DisturbanceConfig = NoDisturbance()
    noise: NoiseConfig = NoiseConfig()
    trajectory: TrajectoryConfig
    initial: InitialConfig = InitialConfig()
    controller: ControllerConfig = BacksteppingConfig(kind="backstepping")

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

    def divergence_distance(self) -> float:
        """``simulation.divergence_error``, or the bound that scales with the scenario
        (:func:`ddtrack.feasibility.divergence_bound`) [m]."""
        if self.simulation.divergence_error is not None:
            return self.simulation.divergence_error
        from .feasibility import divergence_bound

        return divergence_bound(self)

    def plant_params(self) -> RobotParams:
        """The true plant's nominal values: [plant] over [robot]."""
        true = self.plant.model_dump(exclude={"floor_friction"})  # the floor is not the robot's
        merged = self.robot.model_dump() | {k: v for k, v in true.items() if v is not None}
        return RobotParams(**merged)


# --- registries (what `ddtrack list` shows) -------------------------------------------------------


def _registry(union: Any) -> dict[str, type[BaseModel]]:
    members = typing.get_args(typing.get_args(union)[0]) if typing.get_origin(union) is Annotated else (union,)
    return {typing.get_args(m.model_fields["kind"].annotation)[0]: m for m in members}


TRAJECTORIES = _registry(TrajectoryConfig)
DISTURBANCES = _registry(DisturbanceConfig)
CONTROLLERS = _registry(ControllerConfig)


def summary(model: type[BaseModel]) -> str:
    """First line of a config model's docstring."""
    return (model.__doc__ or "").strip().splitlines()[0]


# --- loading --------------------------------------------------------------------------------------


def load_scenario(
    path: str | PathLike[str],
    *,
    overrides: Sequence[str] = (),
    seed: int | None = None,
    controller: str | None = None,
) -> Scenario:
    """Read, override and validate a scenario file.

    Parameters
    ----------
    path : str or Path
        The TOML file.
    overrides : sequence of str
        ``"section.key=value"`` strings; ``value`` is read as TOML (``1.5``, ``[1, 2]``, ``"pd"``) and as a
        plain string when it is not valid TOML.
    seed : int, optional
        Replaces ``simulation.seed``.
    controller : str, optional
        Replaces ``controller.kind`` before the overrides are applied. The file's ``[controller]`` keys that
        its own kind accepts and the new kind does not (``gains`` when switching backstepping to
        ``regulated_pure_pursuit``) are dropped; every other key is kept, so a shared key (``max_velocity``)
        keeps its value and a key that no kind accepts (a typo) is still an error, as is an override of a key
        the new kind lacks.

    Returns
    -------
    Scenario
        The validated scenario, defaults filled in.

    Raises
    ------
    ConfigError
        naming the field and the fix, for any problem with the file or the overrides.
    """
    path = Path(path)
    data = read_toml(path, "scenario", "docs/scenarios.md")
    if controller is not None:
        switch_controller(data, controller)
    for override in overrides:
        apply_override(data, override)
    if seed is not None:
        data.setdefault("simulation", {})
        if isinstance(data["simulation"], dict):
            data["simulation"]["seed"] = seed
    return validate_scenario(data, base_dir=path.parent)


def switch_controller(data: dict[str, Any], kind: str) -> None:
    """Set ``[controller] kind`` of a raw scenario dict in place, dropping the keys of the previous kind
    that ``kind`` does not accept (see :func:`load_scenario`)."""
    section = data.setdefault("controller", {})
    if not isinstance(section, dict):
        return  # not a table: validation names the problem
    previous = section["kind"] if "kind" in section else "backstepping"  # as validate_scenario reads it
    if isinstance(previous, str) and previous in CONTROLLERS and kind in CONTROLLERS:
        old, new = CONTROLLERS[previous].model_fields, CONTROLLERS[kind].model_fields
        for key in [k for k in section if k in old and k not in new]:
            del section[key]
    section["kind"] = kind


def read_input(path: Path) -> bytes:
    """The bytes of a regular file of at most ``MAX_INPUT_BYTES``; :class:`OSError` for anything else (a
    device such as /dev/zero or a pipe would never end, or fill the memory)."""
    if path.exists() and not path.is_file() and not path.is_dir():
        raise OSError(errno.EINVAL, "not a regular file")
    with path.open("rb") as f:
        data = f.read(MAX_INPUT_BYTES + 1)
    if len(data) > MAX_INPUT_BYTES:
        raise OSError(errno.EFBIG, f"larger than {MAX_INPUT_BYTES // 2**20} MiB")
    return data


def read_toml(path: Path, what: str, reference: str) -> dict[str, Any]:
    """Read a TOML file; every problem (missing, a folder, not UTF-8, unreadable, not TOML) is a
    :class:`ConfigError` saying which ``what`` file and pointing to the ``reference`` document."""
    try:
        text = read_input(path).decode("utf-8")
    except FileNotFoundError:
        raise ConfigError("", f"{what} file '{path}' does not exist", "check the path") from None
    except IsADirectoryError:
        raise ConfigError("", f"'{path}' is a folder, not a {what} file", "give a .toml file") from None
    except UnicodeDecodeError as exc:
        raise ConfigError("", f"{what} file '{path}' is not UTF-8 (byte {exc.start})", "save it as UTF-8") from None
    except OSError as exc:
        raise ConfigError("", f"{what} file '{path}' cannot be read: {exc.strerror}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("", f"'{path}' is not valid TOML: {exc}", f"see {reference} for the format") from None


def validate_scenario(data: dict[str, Any], *, base_dir: Path = Path(".")) -> Scenario:
    """Validate a scenario given as a dict; relative waypoint files are read from ``base_dir``.

    Parameters
    ----------
    data : dict
        The scenario as ``tomllib`` reads it (sections as dicts).
    base_dir : Path
        Folder that a ``[trajectory] file`` is relative to.

    Returns
    -------
    Scenario
        The validated scenario, defaults filled in.

    Raises
    ------
    ConfigError
        Naming the first invalid field and how to fix it.
    """
    controller = data.get("controller")
    if isinstance(controller, dict) and "kind" not in controller:  # a [controller] without kind is backstepping
        data = {**data, "controller": {"kind": "backstepping", **controller}}
    try:
        # JSON mode + strict: TOML arrays become tuples, ints become floats, but "10" and true are not numbers
        text = json.dumps(data, default=str, allow_nan=True)
        scenario = Scenario.model_validate_json(text, strict=True, context={"base_dir": str(base_dir)})
    except ValidationError as exc:
        raise _config_error(exc) from None
    from .feasibility import check

    check(scenario)  # a reference beyond the clamps, degrees for radians, grams for kilograms: refused here
    return scenario


def apply_override(data: dict[str, Any], override: str) -> None:
    """Apply one ``section.key=value`` override to the raw scenario dict, in place."""
    dotted, sep, raw = override.partition("=")
    keys = [k.strip() for k in dotted.split(".")]
    if not sep or not all(keys):
        raise ConfigError(
            "--set",
            f"'{override}' is not of the form section.key=value",
            "e.g. --set robot.mass=12 or --set controller.gains=[1,55,15]",
        )
    try:
        value = tomllib.loads(f"value = {raw}")["value"]
    except tomllib.TOMLDecodeError:
        value = raw
    node = data
    for depth, key in enumerate(keys[:-1]):
        child = node.setdefault(key, {})
        if not isinstance(child, dict):
            raise ConfigError(".".join(keys[: depth + 1]), "is a value, not a section", f"cannot set '{dotted}'")
        node = child
    node[keys[-1]] = value


def _config_error(exc: ValidationError) -> ConfigError:
    """Turn pydantic's first error into a one-line message with the field path and a hint."""
    error = exc.errors()[0]
    model, path = _walk(error["loc"])
    cause = error.get("ctx", {}).get("error")
    if isinstance(cause, FieldError):
        path.append(cause.field)
    field = ".".join(path).replace(".[", "[")
    kind, message = error["type"], error["msg"].removeprefix("Value error, ")
    if kind == "extra_forbidden" and model is not None:
        return ConfigError(field, "unknown key", did_you_mean(path[-1], model.model_fields))
    if kind == "union_tag_invalid":
        choices = [c.strip(" '") for c in str(error["ctx"]["expected_tags"]).split(",")]
        return ConfigError(
            field + ".kind", f"unknown kind {error['ctx']['tag']!r}", did_you_mean(error["ctx"]["tag"], choices)
        )
    if kind == "union_tag_not_found":
        return ConfigError(field + ".kind", "is missing", 'add kind = "..."; `ddtrack list` shows the kinds')
    if kind == "literal_error":
        choices = [c.strip(" '\"") for c in error["ctx"]["expected"].replace(" or ", ",").split(",")]
        return ConfigError(field, f"{error['input']!r} is not allowed", did_you_mean(str(error["input"]), choices))
    if kind == "missing":
        return ConfigError(field, "is required", "add it to the scenario (docs/scenarios.md lists every key)")
    if kind == "finite_number":
        return ConfigError(field, "must be a finite number (got NaN or inf)")
    got = error.get("input")
    shown = "" if isinstance(got, dict) or kind.startswith("value_error") else f" (got {got!r:.60})"
    return ConfigError(field, message + shown)


def _walk(loc: Iterable[Any]) -> tuple[type[BaseModel] | None, list[str]]:
    """Follow a pydantic error location through the models; drop union tags from the path."""
    model: Any = Scenario
    parent: type[BaseModel] | None = Scenario
    path: list[str] = []
    for part in loc:
        if isinstance(model, dict):  # a discriminated union: the part is the tag
            model = model.get(part)
            continue
        path.append(f"[{part}]" if isinstance(part, int) else str(part))
        parent = model if isinstance(model, type) and issubclass(model, BaseModel) else None
        if parent is None or part not in parent.model_fields:
            model = None
            continue
        annotation = parent.model_fields[part].annotation
        model = _model_of(annotation)
    return parent, path


def _model_of(annotation: Any) -> Any:
    """The model (or tag -> model dict for a union) behind a field annotation, else None."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if typing.get_origin(annotation) is Annotated:
        return _model_of(typing.get_args(annotation)[0])
    if typing.get_origin(annotation) in (Union, types.UnionType):
        members = [a for a in typing.get_args(annotation) if isinstance(a, type) and issubclass(a, BaseModel)]
        if len(members) == 1:
            return members[0]
        if members and all("kind" in m.model_fields for m in members):
            return {typing.get_args(m.model_fields["kind"].annotation)[0]: m for m in members}
    return None


# --- runtime objects -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Setup:
    """Everything :func:`ddtrack.sim.simulate` needs, built from a scenario (randomness not yet drawn)."""

    nominal: RobotParams
    plant_params: RobotParams
    controller: Any
    trajectory: Trajectory
    x0: jax.Array
    disturbance: WheelDisturbance
    noise: MeasurementNoise
    identification: Any = None  #: the emulator's identification, for controllers that have one
    kinematic: bool = False  #: the controller drives the unicycle with ideal velocity tracking

    @property
    def plant(self) -> DynamicPlant | KinematicPlant:
        """What the run simulates: the true robot (``plant_params``), or for a kinematic controller the
        unicycle that applies (v, omega) at once (its [plant], [randomize] and [disturbance] have no effect)."""
        return KinematicPlant() if self.kinematic else DynamicPlant(self.plant_params)


def build(
    scenario: Scenario, plant_params: RobotParams | None = None, controller_key: jax.Array | None = None
) -> Setup:
    """Build the runtime objects; ``plant_params`` replaces the plant (e.g. a random draw) and
    ``controller_key`` seeds the controller's construction (e.g. the emulator's initial weights)."""
    nominal = scenario.robot.params()
    sim = scenario.simulation
    trajectory = scenario.trajectory.build()
    if scenario.initial.pose is None:
        ref0 = trajectory(0.0)
        pose = (float(ref0.x), float(ref0.y), float(ref0.theta))
    else:
        pose = scenario.initial.pose
    x0 = jnp.asarray([*pose, *scenario.initial.velocity], dtype=float)
    config, key = scenario.controller, controller_key if controller_key is not None else jax.random.PRNGKey(0)
    controller: Controller
    if isinstance(config, (RegulatedPurePursuitConfig, MPPIConfig)):  # they look ahead along the reference itself
        controller = config.build(nominal, sim.control_period, key, trajectory=trajectory)
    else:
        controller = config.build(nominal, sim.control_period, key)
    return Setup(
        nominal=nominal,
        plant_params=plant_params if plant_params is not None else scenario.plant_params(),
        controller=controller,
        trajectory=trajectory,
        x0=x0,
        disturbance=scenario.disturbance.build(),
        noise=scenario.noise.build(),
        kinematic=isinstance(config, KinematicBacksteppingConfig),
    )


def to_toml_dict(scenario: Scenario) -> dict[str, Any]:
    """The fully resolved scenario (defaults included, no None values) as a TOML-ready dict."""
    return _drop_none(scenario.model_dump(mode="json"))


def _drop_none(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, list):
        return [_drop_none(v) for v in value]
    return value


__all__ = [
    "CONTROLLERS",
    "DISTURBANCES",
    "TRAJECTORIES",
    "Scenario",
    "Setup",
    "apply_override",
    "build",
    "load_scenario",
    "read_waypoints",
    "summary",
    "to_toml_dict",
    "validate_scenario",
]
