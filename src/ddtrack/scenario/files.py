"""Reading a scenario: files read safely, TOML parsed, ``--set`` overrides applied, the controller swapped, and
every validation error translated into a :class:`~ddtrack.errors.ConfigError` naming the field.
"""

from __future__ import annotations

import json
import tomllib
import types
import typing
from collections.abc import Iterable, Sequence
from os import PathLike
from pathlib import Path
from typing import Annotated, Any, Union

from pydantic import BaseModel, ValidationError

from ..errors import ConfigError, did_you_mean
from ._base import (
    FieldError,
    read_input,
)
from .document import Scenario
from .registry import CONTROLLERS, InvalidController

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
    from ..feasibility import check

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


def _config_error(exc: ValidationError, root: type[BaseModel] = Scenario, prefix: Sequence[str] = ()) -> ConfigError:
    """Turn pydantic's first error into a one-line message with the field path and a hint."""
    error = exc.errors()[0]
    model, path = _walk(error["loc"], root)
    path = [*prefix, *path]
    cause = error.get("ctx", {}).get("error")
    if isinstance(cause, InvalidController):  # the controller's own model failed: follow its error inside it
        return _config_error(cause.errors, cause.config, path)
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
    return ConfigError(field, message + shown, cause.hint if isinstance(cause, FieldError) else "")


def _walk(loc: Iterable[Any], root: type[BaseModel]) -> tuple[type[BaseModel] | None, list[str]]:
    """Follow a pydantic error location through the models from ``root``; drop union tags from the path."""
    model: Any = root
    parent: type[BaseModel] | None = root
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
