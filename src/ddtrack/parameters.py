"""Parameters declared once: the scenario's validated model and the runtime pytree both read one declaration.

A controller's (or any component's) parameters are the fields of a pydantic model derived from
:class:`Parameters`: each field carries its type, its bounds, its default and its description (with the unit).
The scenario's ``[controller]`` section inherits that model, so it validates exactly what is declared; the runtime
dataclass takes each field it shares with the model through :func:`declared`, so its default is the declaration's.
A field whose type is wrapped in :data:`Structure` (a scheme, a sample count, a switch that changes the traced
program) becomes a static field of the pytree, part of the compiled program's key; every other field is a traced
number, so changing it never compiles a new program.
"""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any, TypeVar

from pydantic import BaseModel, ConfigDict, Field

from ._pytree import declared_fields as declared_fields  # re-exported: a plain dataclass's declared fields

T = TypeVar("T")

Positive = Annotated[float, Field(gt=0.0)]
NonNegative = Annotated[float, Field(ge=0.0)]
PositiveTriple = tuple[Positive, Positive, Positive]
Pair = tuple[float, float]  #: [right, left] per wheel, or any two numbers
MAX_COORDINATE = 1e6  # [m]: 1000 km; far larger positions and lengths break the plots (ticks of 1e308 m)
Coordinate = Annotated[float, Field(ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Position = tuple[Coordinate, Coordinate]
Length = Annotated[float, Field(gt=0.0, le=MAX_COORDINATE)]


class _StructureMark:
    """The mark :data:`Structure` puts in a field's metadata (pydantic keeps metadata it does not know)."""

    def __repr__(self) -> str:
        return "Structure"


STRUCTURE = _StructureMark()
Structure = Annotated[T, STRUCTURE]
"""``Structure[T]``: a parameter that shapes the compiled program (static in the runtime pytree); a change of its
value compiles another program, as a change of a sample count or of a scheme must."""


class Parameters(BaseModel):
    """The base of every parameter declaration and scenario section: unknown keys and non-finite numbers are
    errors, and a validated section is frozen."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True, strict=False)


class Timing(Parameters):
    """When the controller samples and how finely the plant is integrated in between: declared once for the
    scenario's ``[simulation]`` section, the simulator's closed loop and every part that samples time (each part
    is handed the scenario's period when it is built; the default is what a part built alone takes)."""

    control_period: Positive = Field(0.01, description="Controller sampling period T_c [s].")
    substeps: Structure[int] = Field(10, ge=1, le=1000, description="RK4 steps per control period.")


TIMING = Timing()  #: the declared defaults, for a function's keyword defaults


def is_structure(model: type[BaseModel], name: str) -> bool:
    """Whether ``model``'s field ``name`` is declared :data:`Structure`."""
    return any(item is STRUCTURE for item in model.model_fields[name].metadata)


@dataclasses.dataclass(frozen=True)
class Declared:
    """A runtime field's reference to its declaration: ``model``'s field ``name`` (the runtime field's own name
    when None), resolved by :func:`ddtrack._pytree.pytree_dataclass` into the dataclass field."""

    model: type[BaseModel]
    name: str | None = None

    def declared_field(self, field_name: str) -> Any:
        """The ``dataclasses.field`` of the runtime field ``field_name``: the declared default, static iff the
        declaration is :data:`Structure`."""
        name = self.name or field_name
        if name not in self.model.model_fields:
            raise TypeError(f"{field_name} is declared by {self.model.__name__}.{name}, which has no such field")
        default = self.model.model_fields[name].default
        structure = is_structure(self.model, name)
        return dataclasses.field(default=default, metadata={"static": structure, "declared": (self.model, name)})


def declared(model: type[BaseModel], name: str | None = None) -> Any:
    """A runtime pytree field whose default (and whether it is static) is ``model``'s declaration of ``name`` (the
    field's own name by default). Use in a :func:`~ddtrack._pytree.pytree_dataclass` body::

        rates: FloatVector = declared(NNAdaptiveParameters)
    """
    return Declared(model, name)


def declaration(cls: type, field_name: str) -> tuple[type[BaseModel], str] | None:
    """(model, name) that declares the runtime dataclass ``cls``'s field ``field_name``; None if it has none."""
    field = {f.name: f for f in dataclasses.fields(cls)}[field_name]
    return field.metadata.get("declared")
