"""The registries of the kinds a scenario can name: controllers, plants and trajectories, and what each can do.

One table per kind answers every question that used to be a list or an ``isinstance`` somewhere else: which
controllers a scenario may name (``ddtrack list``), which have Kanayama gains (the Gymnasium environment's gains
mode), which ``ddtrack tune`` can differentiate, which look ahead along the reference and what they output; which
plant ``[plant] model`` names; which ``[trajectory] kind``. The built-in kinds are registered here through
:func:`register_controller`, :func:`register_plant` and :func:`register_trajectory`, as a plugin's are;
pip-installed plugins are found through the ``ddtrack.controllers``, ``ddtrack.plants`` and
``ddtrack.trajectories`` entry-point groups the first time any registry is consulted (docs/plugins.md).
"""

from __future__ import annotations

import json
import typing
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Annotated, Any, Literal, Protocol, Union

from pydantic import BaseModel, Field, GetCoreSchemaHandler, GetJsonSchemaHandler, TypeAdapter, ValidationError
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import PydanticCustomError, core_schema

from ..errors import ConfigError, did_you_mean
from ..model import DynamicPlant, KinematicPlant, Plant, RobotParams
from ..trajectories import Trajectory
from ._base import FieldError
from .baseline_configs import (
    AdaptiveBacksteppingConfig,
    AdaptiveCompensatorConfig,
    KinematicBacksteppingConfig,
    LTVLQRConfig,
    MPPIConfig,
    RegulatedPurePursuitConfig,
    SlidingModeConfig,
)
from .controller_configs import BacksteppingConfig, NNAdaptiveConfig
from .motor_configs import lag_plant, motor_torque_plant, motor_velocity_plant
from .replay_config import ReplayConfig
from .slip_configs import slip_plant_config, slip_velocity_plant_config
from .trajectory_configs import (
    CircleTrajectory,
    FigureEightTrajectory,
    LineTrajectory,
    SinusoidTrajectory,
    SquareTrajectory,
    WaypointsTrajectory,
)

#: the entry-point groups a plugin package registers its kinds through (each entry: a module, or a function
#: called with no argument, that calls the register functions)
PLUGIN_GROUPS = ("ddtrack.controllers", "ddtrack.plants", "ddtrack.trajectories")
ENTRY_POINT_GROUP = PLUGIN_GROUPS[0]


class TrajectoryConfig(Protocol):
    """What the code asks of a ``[trajectory]`` model (a pydantic model, see :func:`register_trajectory`)."""

    @property
    def kind(self) -> str:
        """The kind's name, as a scenario file writes it."""
        ...

    def build(self) -> Trajectory:
        """The reference trajectory."""
        ...


class ControllerConfig(Protocol):
    """What the code asks of a ``[controller]`` model (a pydantic model, see :func:`register_controller`)."""

    @property
    def kind(self) -> str:
        """The kind's name, as a scenario file writes it."""
        ...

    def build(self, *args: Any, **kwargs: Any) -> Any:
        """(nominal, control_period, key[, trajectory=]) -> the controller."""
        ...


@dataclass(frozen=True)
class ControllerKind:
    """A registered controller kind and its declared capabilities (see :func:`register_controller`)."""

    name: str
    config: type[BaseModel]
    has_kanayama_gains: bool
    differentiable: bool
    needs_reference: bool
    output: Literal["torque", "velocity"]
    tracks_reference: bool = True

    @property
    def tunable(self) -> bool:
        """``ddtrack tune`` can tune its gains: Kanayama's, on the torque plant, differentiated through rollouts
        (with its default inner loop: :func:`controller_output` says what a given config outputs)."""
        return self.differentiable and self.has_kanayama_gains and self.output == "torque"


def controller_output(config: Any) -> Literal["torque", "velocity"]:
    """What the controller of ``config`` hands the plant: the config's own answer where its keys decide it (a
    ``controller_output()`` method, e.g. ``inner = "none"`` gives velocity), else its kind's registered output."""
    decides = getattr(config, "controller_output", None)
    return decides() if callable(decides) else controller_kind(config.kind).output


_KINDS: dict[str, ControllerKind] = {}
_plugins: list[str] = []  # the entry points loaded so far ("name = value"); empty before the first look
_plugin_error: list[ConfigError] = []  # a broken plugin's error, raised at every look (never half a registry)


def _kind_name(config: Any, build: str) -> str:
    """The one name of a config model's ``kind: Literal["name"]`` field; a TypeError if it is not such a model
    with a ``build`` method (whose signature ``build`` describes)."""
    if not (isinstance(config, type) and issubclass(config, BaseModel)) or "kind" not in config.model_fields:
        raise TypeError(f"{config!r} is not a pydantic model with a kind field")
    names = typing.get_args(config.model_fields["kind"].annotation)
    if typing.get_origin(config.model_fields["kind"].annotation) is not Literal or len(names) != 1:
        raise TypeError(f"{config.__name__}.kind must be Literal['name'] (one name)")
    if not callable(getattr(config, "build", None)):
        raise TypeError(f"{config.__name__} has no {build} method")
    return str(names[0])


def register_controller(
    config: type[BaseModel],
    *,
    has_kanayama_gains: bool = False,
    differentiable: bool = False,
    needs_reference: bool = False,
    output: Literal["torque", "velocity"] = "torque",
    tracks_reference: bool = True,
) -> type[BaseModel]:
    """Make a controller kind usable by name in scenario files and every command.

    Parameters
    ----------
    config : type
        The ``[controller]`` section's pydantic model: its ``kind: Literal["name"]`` field names the kind, and
        ``build(nominal, control_period, key)`` returns the controller (``init``/``step``, docs/architecture.md).
    has_kanayama_gains : bool
        Its outer law is Kanayama's with gains ``(Kx, Ky, Ktheta)``: the config has a ``gains`` field and the built
        controller's outer law (or the law itself, for a velocity output) has fields ``kx``, ``ky``, ``ktheta``.
        The Gymnasium environment's gains mode accepts it.
    differentiable : bool
        A rollout is differentiable in those gains (no branch on them, no stop_gradient): ``ddtrack tune`` accepts
        it when it also has Kanayama gains and outputs torques.
    needs_reference : bool
        ``build`` takes the reference too, as ``trajectory=`` (a controller that looks ahead along it).
    output : {"torque", "velocity"}
        Wheel torques for the dynamic plant, or (v, omega) for the unicycle with ideal velocity tracking: the
        default, which a config overrides through a ``controller_output()`` method when a key decides it (the
        shared inner loop's ``inner = "none"``; :func:`controller_output`).
    tracks_reference : bool
        It tracks the reference in closed loop, from what it measures; False for a law that plays a plan back open
        loop (``replay``). ``ddtrack bench`` ranks only the kinds that track (:func:`tracking_kinds`).

    Returns
    -------
    type
        ``config``, so that the call can decorate the class.

    Raises
    ------
    TypeError
        if ``config`` is not such a model, or its kind is already registered to another class.
    """
    name = _kind_name(config, "build(nominal, control_period, key)")
    if has_kanayama_gains and "gains" not in config.model_fields:
        raise TypeError(f"{config.__name__} declares Kanayama gains but has no gains field")
    if output not in ("torque", "velocity"):
        raise TypeError(f"output must be 'torque' or 'velocity', not {output!r}")
    if name in _KINDS and _KINDS[name].config is not config:
        raise TypeError(f"controller kind {name!r} is already registered ({_KINDS[name].config.__qualname__})")
    _KINDS[name] = ControllerKind(
        name, config, has_kanayama_gains, differentiable, needs_reference, output, tracks_reference
    )
    return config


def _load_plugins() -> None:
    """Import every entry point of :data:`PLUGIN_GROUPS` once: a module, or a function it calls with no argument."""
    if _plugin_error:
        raise _plugin_error[0]
    if _plugins:
        return
    _plugins.append("")  # marks the look done, so a plugin that registers (and so looks) does not recurse
    for group in PLUGIN_GROUPS:
        for point in entry_points(group=group):
            try:
                loaded = point.load()
                if callable(loaded) and not isinstance(loaded, type):
                    loaded()
            except Exception as exc:
                dist = f" (from {point.dist.name})" if point.dist is not None else ""
                _plugin_error.append(
                    ConfigError(
                        f"plugin '{point.name}'{dist}",
                        f"the {group} entry point {point.value!r} failed: {type(exc).__name__}: {exc}",
                        "fix or uninstall that package",
                    )
                )
                raise _plugin_error[0] from None
            _plugins.append(f"{group}: {point.name} = {point.value}")


def controller_kinds() -> dict[str, ControllerKind]:
    """Every registered kind (plugins included), built-ins first, in registration order."""
    _load_plugins()
    return dict(_KINDS)


def controller_kind(name: str, field: str = "controller.kind") -> ControllerKind:
    """The registered kind ``name``; a :class:`ConfigError` naming ``field`` with a did-you-mean if there is none."""
    kinds = controller_kinds()
    if name not in kinds:
        raise ConfigError(field, f"unknown kind {name!r}", did_you_mean(str(name), kinds))
    return kinds[name]


class _LiveMapping(Mapping[str, Any]):
    """name -> what ``read`` gives for it, read live from a registry (a kind registered later shows up)."""

    def __init__(self, label: str, kinds: Callable[[], Mapping[str, Any]], read: Callable[[Any], Any]) -> None:
        self._label, self._kinds, self._read = label, kinds, read

    def __getitem__(self, name: str) -> Any:
        return self._read(self._kinds()[name])

    def __iter__(self) -> Iterator[str]:
        return iter(self._kinds())

    def __len__(self) -> int:
        return len(self._kinds())

    def __repr__(self) -> str:
        return f"{self._label}({', '.join(self)})"


#: kind -> config class of every registered controller (what ``ddtrack list`` shows)
CONTROLLERS: Mapping[str, type[BaseModel]] = _LiveMapping("CONTROLLERS", controller_kinds, lambda kind: kind.config)


def kanayama_kinds() -> list[str]:
    """The kinds whose outer law is Kanayama's, so that they have gains (Kx, Ky, Ktheta)."""
    return [name for name, kind in controller_kinds().items() if kind.has_kanayama_gains]


def tracking_kinds() -> list[str]:
    """The kinds that track a reference in closed loop (:attr:`ControllerKind.tracks_reference`): what a benchmark
    ranks."""
    return [name for name, kind in controller_kinds().items() if kind.tracks_reference]


def tunable_kinds() -> list[str]:
    """The kinds ``ddtrack tune`` can tune (:attr:`ControllerKind.tunable`)."""
    return [name for name, kind in controller_kinds().items() if kind.tunable]


def kanayama_gains(config: Any) -> tuple[float, float, float]:
    """(Kx, Ky, Ktheta) of a controller with Kanayama's outer law; a ConfigError naming ``controller.kind`` if not."""
    if controller_kind(config.kind).has_kanayama_gains:
        kx, ky, ktheta = config.gains
        return float(kx), float(ky), float(ktheta)
    raise ConfigError("controller.kind", f"'{config.kind}' has no Kanayama gains (Kx, Ky, Ktheta)")


# --- trajectories ----------------------------------------------------------------------------------

_TRAJECTORIES: dict[str, type[BaseModel]] = {}


def register_trajectory(config: type[BaseModel]) -> type[BaseModel]:
    """Make a reference trajectory usable by name as ``[trajectory] kind``.

    Parameters
    ----------
    config : type
        The ``[trajectory]`` section's pydantic model: its ``kind: Literal["name"]`` field names the kind and
        ``build()`` returns the :class:`~ddtrack.trajectories.Trajectory`.

    Returns
    -------
    type
        ``config``, so that the call can decorate the class.

    Raises
    ------
    TypeError
        if ``config`` is not such a model, or its kind is already registered to another class.
    """
    name = _kind_name(config, "build()")
    if name in _TRAJECTORIES and _TRAJECTORIES[name] is not config:
        raise TypeError(f"trajectory kind {name!r} is already registered ({_TRAJECTORIES[name].__qualname__})")
    _TRAJECTORIES[name] = config
    return config


def trajectory_kinds() -> dict[str, type[BaseModel]]:
    """Every registered trajectory kind (plugins included) -> its config class, in registration order."""
    _load_plugins()
    return dict(_TRAJECTORIES)


#: kind -> config class of every registered trajectory (what ``ddtrack list`` shows)
TRAJECTORIES: Mapping[str, type[BaseModel]] = _LiveMapping("TRAJECTORIES", trajectory_kinds, lambda config: config)


# --- plants ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PlantKind:
    """A registered plant (see :func:`register_plant`)."""

    name: str
    build: Callable[..., Plant]  #: the true robot's plant from its parameters (and the scenario, if it reads it)
    summary: str
    reads_scenario: bool = False  #: ``build(params, scenario)``: it takes more than the parameters from the scenario

    def model(self, scenario: Any) -> Callable[[RobotParams], Plant]:
        """``Setup.plant_model`` for ``scenario``: the plant of a drawn robot's parameters."""
        if not self.reads_scenario:
            return self.build
        build = self.build
        return lambda params: build(params, scenario)


_PLANTS: dict[str, PlantKind] = {}


def register_plant(name: str, build: Callable[..., Plant], *, summary: str = "", reads_scenario: bool = False) -> None:
    """Make a plant usable by name as ``[plant] model``.

    Parameters
    ----------
    name : str
        The name a scenario gives (letters, digits and ``_``).
    build : callable
        ``build(params)`` -> the plant (:class:`~ddtrack.model.Plant`: ``init``/``saturate``/``advance``/
        ``observe``/``logged`` and its layouts) for the true robot's :class:`~ddtrack.model.RobotParams`; a plant
        class whose one field is ``params`` is such a callable.
    summary : str
        One line for ``ddtrack list plants`` (default: the first line of ``build``'s docstring).
    reads_scenario : bool
        ``build(params, scenario)`` takes the validated scenario too, for what its plant reads beyond the robot's
        parameters (a motor from ``[robot] preset``, a driver's gains from ``[plant]``); it raises
        :class:`~ddtrack.errors.ConfigError` naming the field when the scenario lacks it.

    Raises
    ------
    TypeError
        if ``name`` is not a name, ``build`` is not callable, or the name is taken by another plant.
    """
    if not (isinstance(name, str) and name.isidentifier()):
        raise TypeError(f"a plant's name must be letters, digits and '_', not {name!r}")
    if not callable(build):
        raise TypeError(f"{build!r} is not callable: give build(params) -> plant")
    if name in _PLANTS and _PLANTS[name].build is not build:
        raise TypeError(f"plant {name!r} is already registered ({_PLANTS[name].build!r})")
    line = summary or ((build.__doc__ or "").strip().splitlines() or [""])[0]
    _PLANTS[name] = PlantKind(name, build, line, reads_scenario)


def plant_kinds() -> dict[str, PlantKind]:
    """Every registered plant (plugins included), in registration order."""
    _load_plugins()
    return dict(_PLANTS)


def is_plant(name: str) -> bool:
    """Whether ``name`` is a registered plant (plugins are looked for only when it is not a built-in one)."""
    return name in _PLANTS or name in plant_kinds()


def plant_kind(name: str, field: str = "plant.model") -> PlantKind:
    """The registered plant ``name``; a :class:`ConfigError` naming ``field`` with a did-you-mean if there is none."""
    kinds = plant_kinds()
    if name not in kinds:
        raise ConfigError(field, f"unknown plant {name!r}", did_you_mean(str(name), kinds))
    return kinds[name]


#: name -> summary of every registered plant (what ``ddtrack list`` shows)
PLANTS: Mapping[str, str] = _LiveMapping("PLANTS", plant_kinds, lambda kind: kind.summary)


# --- a scenario's kind-selected tables ----------------------------------------------------------


class InvalidKind(ValueError):
    """A ``[controller]`` or ``[trajectory]`` table failed its kind's validation; ``errors`` is that validation's
    error, which the scenario's error translation follows into the kind's model (so messages name
    ``controller.gains``)."""

    def __init__(self, config: type[BaseModel], errors: ValidationError) -> None:
        super().__init__(str(errors))
        self.config, self.errors = config, errors


InvalidController = InvalidKind  # the name it had when only controllers were registered


class KindField:
    """Marks a scenario field validated through a registry (``kinds``: name -> config class): the table's
    ``kind`` is looked up when it is validated (so a kind registered after import counts) and the table is
    validated with that kind's model, as strictly as the scenario. Its JSON Schema is the discriminated union
    (``oneOf`` on ``kind``) of the kinds registered when the schema is made."""

    def __init__(self, kinds: Callable[[], Mapping[str, type[BaseModel]]]) -> None:
        self.kinds = kinds

    def validate(self, value: Any, info: core_schema.ValidationInfo) -> BaseModel:
        kinds = self.kinds()
        if isinstance(value, BaseModel):
            kind = getattr(value, "kind", None)
            if isinstance(kind, str) and kinds.get(kind) is type(value):
                return value
            raise PydanticCustomError("model_type", "Input should be a registered kind's config or a table")
        if not isinstance(value, dict):
            raise PydanticCustomError("model_type", "Input should be an object")
        kind = value.get("kind")
        if kind is None:
            raise FieldError("kind", "is missing", 'add kind = "..."; `ddtrack list` shows the kinds')
        if not isinstance(kind, str) or kind not in kinds:
            raise FieldError("kind", f"unknown kind '{kind}'", did_you_mean(str(kind), kinds))
        config = kinds[kind]
        try:
            if info.mode == "json":  # the dict came from JSON: validate it as JSON again, keeping strict mode's rules
                return config.model_validate_json(json.dumps(value), strict=True, context=info.context)
            return config.model_validate(value, context=info.context)
        except ValidationError as exc:
            raise InvalidKind(config, exc) from None

    def __get_pydantic_core_schema__(self, source: Any, handler: GetCoreSchemaHandler) -> core_schema.CoreSchema:
        return core_schema.with_info_plain_validator_function(self.validate)

    def __get_pydantic_json_schema__(
        self, schema: core_schema.CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        configs = tuple(self.kinds().values())
        form: Any = Annotated[Union[configs], Field(discriminator="kind")]  # noqa: UP007 (built at run time)
        union: TypeAdapter[Any] = TypeAdapter(form)
        return handler(union.core_schema)


def ControllerField() -> KindField:
    """The scenario's ``controller`` field's marker: validated through the controller registry."""
    return KindField(lambda: CONTROLLERS)


def TrajectoryField() -> KindField:
    """The scenario's ``trajectory`` field's marker: validated through the trajectory registry."""
    return KindField(trajectory_kinds)


# the built-in kinds, in the order `ddtrack list` and the reference show them
register_controller(BacksteppingConfig, has_kanayama_gains=True, differentiable=True)
register_controller(NNAdaptiveConfig, has_kanayama_gains=True)
register_controller(LTVLQRConfig)
register_controller(SlidingModeConfig, has_kanayama_gains=True)
register_controller(KinematicBacksteppingConfig, has_kanayama_gains=True, output="velocity")
register_controller(RegulatedPurePursuitConfig, needs_reference=True)
register_controller(AdaptiveBacksteppingConfig, has_kanayama_gains=True)
register_controller(MPPIConfig, needs_reference=True)
register_controller(AdaptiveCompensatorConfig, output="velocity")
register_controller(ReplayConfig, output="velocity", tracks_reference=False)
for _trajectory in (LineTrajectory, SquareTrajectory, CircleTrajectory, FigureEightTrajectory, SinusoidTrajectory):
    register_trajectory(_trajectory)
register_trajectory(WaypointsTrajectory)
register_plant("dynamic", DynamicPlant, summary="The Lagrangian robot driven by wheel torques (the default).")
_SCENARIO_PLANTS = (  # each builds its plant from the scenario too (a preset's motor, a driver's gains)
    ("motor_torque", motor_torque_plant, "The robot's geared DC motors under current control: torque commands "
     "within the torque-speed curve."),
    ("motor_velocity", motor_velocity_plant, "The robot's motors under a PI wheel-speed loop: (v, omega) commands, "
     "as ROS bases take cmd_vel."),
    ("lag", lag_plant, "A velocity-commanded base's identified first-order lags (Martins et al.), from "
     "[robot] preset."),
    ("slip", slip_plant_config, "The robot on a floor of finite grip, its wheels free to slip (needs "
     "wheel_inertia > 0)."),
    ("slip_velocity", slip_velocity_plant_config, "The robot's motors under a PI wheel-speed loop on a floor of finite "
     "grip: (v, omega) commands, wheels free to slip."),
)  # fmt: skip
for _name, _build, _summary in _SCENARIO_PLANTS:
    register_plant(_name, _build, summary=_summary, reads_scenario=True)
register_plant(
    "unicycle",
    lambda params: KinematicPlant(),
    summary="The unicycle with ideal velocity tracking, driven by (v, omega) commands.",
)
