"""Scenario files: TOML -> validated pydantic models -> runtime objects, through registries (docs/guide.md).

Every user mistake becomes a :class:`~ddtrack.errors.ConfigError` naming the field (``robot.mass``)
and how to fix it. Unknown keys, NaN and inf are errors; a ``[plant]`` key left out takes the
``[robot]`` value.
"""

from __future__ import annotations

from ..parameters import PositiveTriple as PositiveTriple
from ._base import MAX_CONTROL_PERIODS as MAX_CONTROL_PERIODS
from ._base import MAX_COORDINATE as MAX_COORDINATE
from ._base import MAX_INPUT_BYTES as MAX_INPUT_BYTES
from ._base import MAX_SEED as MAX_SEED
from ._base import Coordinate as Coordinate
from ._base import FieldError as FieldError
from ._base import Length as Length
from ._base import NonNegative as NonNegative
from ._base import Pair as Pair
from ._base import Position as Position
from ._base import Positive as Positive
from ._base import _Section as _Section
from ._base import read_input as read_input
from .baseline_configs import AdaptiveBacksteppingConfig as AdaptiveBacksteppingConfig
from .baseline_configs import KinematicBacksteppingConfig as KinematicBacksteppingConfig
from .baseline_configs import LTVLQRConfig as LTVLQRConfig
from .baseline_configs import MPPIConfig as MPPIConfig
from .baseline_configs import RegulatedPurePursuitConfig as RegulatedPurePursuitConfig
from .baseline_configs import SlidingModeConfig as SlidingModeConfig
from .build import Setup as Setup
from .build import build as build
from .build import to_toml_dict as to_toml_dict
from .controller_configs import BacksteppingConfig as BacksteppingConfig
from .controller_configs import InnerLoopConfig as InnerLoopConfig
from .controller_configs import NNAdaptiveConfig as NNAdaptiveConfig
from .document import DISTURBANCES as DISTURBANCES
from .document import Scenario as Scenario
from .document import summary as summary
from .files import apply_override as apply_override
from .files import load_scenario as load_scenario
from .files import read_toml as read_toml
from .files import switch_controller as switch_controller
from .files import validate_scenario as validate_scenario
from .registry import CONTROLLERS as CONTROLLERS
from .registry import PLANTS as PLANTS
from .registry import TRAJECTORIES as TRAJECTORIES
from .registry import ControllerConfig as ControllerConfig
from .registry import ControllerKind as ControllerKind
from .registry import PlantKind as PlantKind
from .registry import TrajectoryConfig as TrajectoryConfig
from .registry import controller_kind as controller_kind
from .registry import controller_kinds as controller_kinds
from .registry import controller_output as controller_output
from .registry import kanayama_gains as kanayama_gains
from .registry import kanayama_kinds as kanayama_kinds
from .registry import plant_kind as plant_kind
from .registry import plant_kinds as plant_kinds
from .registry import register_controller as register_controller
from .registry import register_plant as register_plant
from .registry import register_trajectory as register_trajectory
from .registry import tracking_kinds as tracking_kinds
from .registry import trajectory_kinds as trajectory_kinds
from .registry import tunable_kinds as tunable_kinds
from .sections import ConstantDisturbance as ConstantDisturbance
from .sections import DisturbanceConfig as DisturbanceConfig
from .sections import GaussianDisturbance as GaussianDisturbance
from .sections import InitialConfig as InitialConfig
from .sections import NoDisturbance as NoDisturbance
from .sections import NoiseConfig as NoiseConfig
from .sections import ParameterDraw as ParameterDraw
from .sections import PlantConfig as PlantConfig
from .sections import RandomizeConfig as RandomizeConfig
from .sections import RobotConfig as RobotConfig
from .sections import SimulationConfig as SimulationConfig
from .sections import SinusoidDisturbance as SinusoidDisturbance
from .sensing_config import SensingConfig as SensingConfig
from .trajectory_configs import CircleTrajectory as CircleTrajectory
from .trajectory_configs import FigureEightTrajectory as FigureEightTrajectory
from .trajectory_configs import LineTrajectory as LineTrajectory
from .trajectory_configs import SinusoidTrajectory as SinusoidTrajectory
from .trajectory_configs import SquareTrajectory as SquareTrajectory
from .trajectory_configs import WaypointsTrajectory as WaypointsTrajectory
from .waypoint_rows import read_waypoints as read_waypoints

__all__ = [
    "CONTROLLERS",
    "DISTURBANCES",
    "PLANTS",
    "TRAJECTORIES",
    "Scenario",
    "Setup",
    "apply_override",
    "build",
    "controller_kind",
    "controller_kinds",
    "load_scenario",
    "plant_kind",
    "read_waypoints",
    "register_controller",
    "register_plant",
    "register_trajectory",
    "summary",
    "to_toml_dict",
    "validate_scenario",
]
