"""The registry of controller kinds: each ``[controller] kind``'s config class and what it can do.

One table answers every question that used to be a list or an ``isinstance`` somewhere else: which kinds a
scenario may name (``ddtrack list``), which have Kanayama gains (the Gymnasium environment's gains mode), which
``ddtrack tune`` can differentiate, which look ahead along the reference, and which output velocities. The eight
built-in kinds are registered here through :func:`register_controller`, as a plugin's are; pip-installed plugins
are found through the ``ddtrack.controllers`` entry-point group the first time the registry is consulted
(docs/plugins.md).
"""

from __future__ import annotations

import json
import typing
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Annotated, Any, Literal, Protocol, Union

from pydantic import BaseModel, Field, GetCoreSchemaHandler, GetJsonSchemaHandler, TypeAdapter, ValidationError
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import PydanticCustomError, core_schema

from ..errors import ConfigError, did_you_mean
from ._base import FieldError
from .baseline_configs import (
    AdaptiveBacksteppingConfig,
    KinematicBacksteppingConfig,
    LTVLQRConfig,
    MPPIConfig,
    RegulatedPurePursuitConfig,
    SlidingModeConfig,
)
from .controller_configs import BacksteppingConfig, NNAdaptiveConfig

ENTRY_POINT_GROUP = "ddtrack.controllers"


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

    @property
    def tunable(self) -> bool:
        """``ddtrack tune`` can tune its gains: Kanayama's, on the torque plant, differentiated through rollouts."""
        return self.differentiable and self.has_kanayama_gains and self.output == "torque"


_KINDS: dict[str, ControllerKind] = {}
_plugins: list[str] = []  # the entry points loaded so far ("name = value"); empty before the first look
_plugin_error: list[ConfigError] = []  # a broken plugin's error, raised at every look (never half a registry)


def register_controller(
    config: type[BaseModel],
    *,
    has_kanayama_gains: bool = False,
    differentiable: bool = False,
    needs_reference: bool = False,
    output: Literal["torque", "velocity"] = "torque",
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
        Wheel torques for the dynamic plant, or (v, omega) for the unicycle with ideal velocity tracking.

    Returns
    -------
    type
        ``config``, so that the call can decorate the class.

    Raises
    ------
    TypeError
        if ``config`` is not such a model, or its kind is already registered to another class.
    """
    if not (isinstance(config, type) and issubclass(config, BaseModel)) or "kind" not in config.model_fields:
        raise TypeError(f"{config!r} is not a pydantic model with a kind field")
    names = typing.get_args(config.model_fields["kind"].annotation)
    if typing.get_origin(config.model_fields["kind"].annotation) is not Literal or len(names) != 1:
        raise TypeError(f"{config.__name__}.kind must be Literal['name'] (one name)")
    name = names[0]
    if not callable(getattr(config, "build", None)):
        raise TypeError(f"{config.__name__} has no build(nominal, control_period, key) method")
    if has_kanayama_gains and "gains" not in config.model_fields:
        raise TypeError(f"{config.__name__} declares Kanayama gains but has no gains field")
    if output not in ("torque", "velocity"):
        raise TypeError(f"output must be 'torque' or 'velocity', not {output!r}")
    if name in _KINDS and _KINDS[name].config is not config:
        raise TypeError(f"controller kind {name!r} is already registered ({_KINDS[name].config.__qualname__})")
    _KINDS[name] = ControllerKind(name, config, has_kanayama_gains, differentiable, needs_reference, output)
    return config


def _load_plugins() -> None:
    """Import every ``ddtrack.controllers`` entry point once: a module, or a function it calls with no argument."""
    if _plugin_error:
        raise _plugin_error[0]
    if _plugins:
        return
    _plugins.append("")  # marks the look done, so a plugin that registers (and so looks) does not recurse
    for point in entry_points(group=ENTRY_POINT_GROUP):
        try:
            loaded = point.load()
            if callable(loaded) and not isinstance(loaded, type):
                loaded()
        except Exception as exc:
            dist = f" (from {point.dist.name})" if point.dist is not None else ""
            _plugin_error.append(
                ConfigError(
                    f"plugin '{point.name}'{dist}",
                    f"the {ENTRY_POINT_GROUP} entry point {point.value!r} failed: {type(exc).__name__}: {exc}",
                    "fix or uninstall that package",
                )
            )
            raise _plugin_error[0] from None
        _plugins.append(f"{point.name} = {point.value}")


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


class _ConfigClasses(Mapping[str, type[BaseModel]]):
    """kind -> config class, read live from the registry (a kind registered later shows up)."""

    def __getitem__(self, name: str) -> type[BaseModel]:
        return controller_kinds()[name].config

    def __iter__(self) -> Iterator[str]:
        return iter(controller_kinds())

    def __len__(self) -> int:
        return len(controller_kinds())

    def __repr__(self) -> str:
        return f"CONTROLLERS({', '.join(self)})"


#: kind -> config class of every registered controller (what ``ddtrack list`` shows)
CONTROLLERS: Mapping[str, type[BaseModel]] = _ConfigClasses()


def kanayama_kinds() -> list[str]:
    """The kinds whose outer law is Kanayama's, so that they have gains (Kx, Ky, Ktheta)."""
    return [name for name, kind in controller_kinds().items() if kind.has_kanayama_gains]


def tunable_kinds() -> list[str]:
    """The kinds ``ddtrack tune`` can tune (:attr:`ControllerKind.tunable`)."""
    return [name for name, kind in controller_kinds().items() if kind.tunable]


def kanayama_gains(config: Any) -> tuple[float, float, float]:
    """(Kx, Ky, Ktheta) of a controller with Kanayama's outer law; a ConfigError naming ``controller.kind`` if not."""
    if controller_kind(config.kind).has_kanayama_gains:
        kx, ky, ktheta = config.gains
        return float(kx), float(ky), float(ktheta)
    raise ConfigError("controller.kind", f"'{config.kind}' has no Kanayama gains (Kx, Ky, Ktheta)")


# --- the [controller] field of a scenario ---------------------------------------------------------


class InvalidController(ValueError):
    """The ``[controller]`` table failed its kind's validation; ``errors`` is that validation's error, which
    the scenario's error translation follows into the kind's model (so messages name ``controller.gains``)."""

    def __init__(self, config: type[BaseModel], errors: ValidationError) -> None:
        super().__init__(str(errors))
        self.config, self.errors = config, errors


def _validate_controller(value: Any, info: core_schema.ValidationInfo) -> BaseModel:
    """Look the table's ``kind`` up in the registry (now, so that a kind registered after import counts) and
    validate the table with that kind's model, as strictly as the scenario (TOML through JSON: strict)."""
    if isinstance(value, BaseModel):
        kind = getattr(value, "kind", None)
        if isinstance(kind, str) and controller_kind(kind).config is type(value):
            return value
        raise PydanticCustomError("model_type", "Input should be a registered controller config or a table")
    if not isinstance(value, dict):
        raise PydanticCustomError("model_type", "Input should be an object")
    kind = value.get("kind")
    kinds = controller_kinds()
    if not isinstance(kind, str) or kind not in kinds:
        raise FieldError("kind", f"unknown kind '{kind}'", did_you_mean(str(kind), kinds))
    config = kinds[kind].config
    try:
        if info.mode == "json":  # the dict came from JSON: validate it as JSON again, keeping strict mode's rules
            return config.model_validate_json(json.dumps(value), strict=True, context=info.context)
        return config.model_validate(value, context=info.context)
    except ValidationError as exc:
        raise InvalidController(config, exc) from None


class ControllerField:
    """Marks the scenario's ``controller`` field: validated through the registry; its JSON Schema is the
    discriminated union (``oneOf`` on ``kind``) of the kinds registered when the schema is made."""

    @classmethod
    def __get_pydantic_core_schema__(cls, source: Any, handler: GetCoreSchemaHandler) -> core_schema.CoreSchema:
        return core_schema.with_info_plain_validator_function(_validate_controller)

    @classmethod
    def __get_pydantic_json_schema__(
        cls, schema: core_schema.CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        configs = tuple(kind.config for kind in controller_kinds().values())
        form: Any = Annotated[Union[configs], Field(discriminator="kind")]  # noqa: UP007 (built at run time)
        union: TypeAdapter[Any] = TypeAdapter(form)
        return handler(union.core_schema)


# the built-in kinds, in the order `ddtrack list` and the reference show them
register_controller(BacksteppingConfig, has_kanayama_gains=True, differentiable=True)
register_controller(NNAdaptiveConfig, has_kanayama_gains=True)
register_controller(LTVLQRConfig)
register_controller(SlidingModeConfig, has_kanayama_gains=True)
register_controller(KinematicBacksteppingConfig, has_kanayama_gains=True, output="velocity")
register_controller(RegulatedPurePursuitConfig, needs_reference=True)
register_controller(AdaptiveBacksteppingConfig, has_kanayama_gains=True)
register_controller(MPPIConfig, needs_reference=True)
