"""Frozen dataclasses that are JAX pytrees: numeric fields are traced leaves, ``static`` fields are not."""

from __future__ import annotations

import dataclasses
from typing import Any, TypeAlias, TypeVar, cast, dataclass_transform

import jax
import numpy as np
from jax import Array

T = TypeVar("T")

FloatVector: TypeAlias = Array | np.ndarray | tuple[float, ...]
"""A short numeric field (gains, one value per wheel): a tuple of floats where a scenario or a default builds it,
an array once batched or traced. Code reads it through ``jnp.asarray``, which takes either."""


@dataclass_transform(frozen_default=True, field_specifiers=(dataclasses.field,))
def pytree_dataclass(cls: type[T]) -> type[T]:
    """Make ``cls`` a frozen dataclass registered as a pytree: how a controller, plant or trajectory of your own
    enters ddtrack's jitted simulator.

    Fields declared with ``static_field()`` become part of the tree structure (and of the jit
    cache key); every other field is a leaf, so changing a gain or a mass never recompiles.

    The class itself is part of the structure too. ``jax.tree_util.register_dataclass`` does not promise that:
    jaxlib 0.10 compares two dataclass nodes by their fields alone, so the structures of two classes with the
    same fields (``DynamicPlant(params)`` and a plugin's 7-state plant) compare equal, and a jitted function
    whose cache entries collide by hash runs the other class's compiled program (a wrong shape, or a wrong
    result, in about one test session in three). A node registered here compares its class, as every
    ``register_pytree_node`` node does. Register your own classes with this decorator, not with
    ``register_dataclass``.

    Parameters
    ----------
    cls
        The class, with annotated fields (it becomes a frozen dataclass).

    Returns
    -------
    type
        The same class, registered.
    """
    cls = dataclasses.dataclass(frozen=True)(declared_fields(cls))
    fields = [f for f in dataclasses.fields(cast(Any, cls)) if f.init]
    data = tuple(f.name for f in fields if not f.metadata.get("static", False))
    meta = tuple(f.name for f in fields if f.metadata.get("static", False))
    keys = tuple(jax.tree_util.GetAttrKey(name) for name in data)

    def flatten(obj: Any) -> tuple[tuple[Any, ...], tuple[Any, ...]]:
        return tuple(getattr(obj, name) for name in data), tuple(getattr(obj, name) for name in meta)

    def flatten_with_keys(obj: Any) -> tuple[tuple[tuple[Any, Any], ...], tuple[Any, ...]]:
        children, aux = flatten(obj)
        return tuple(zip(keys, children, strict=True)), aux

    def unflatten(aux: tuple[Any, ...], children: Any) -> Any:
        obj = object.__new__(cls)  # as register_dataclass does: leaves may be tracers or placeholders, never checked
        for name, value in zip(data, children, strict=True):
            object.__setattr__(obj, name, value)
        for name, value in zip(meta, aux, strict=True):
            object.__setattr__(obj, name, value)
        return obj

    jax.tree_util.register_pytree_with_keys(cls, flatten_with_keys, unflatten, flatten)
    return cls


def declared_fields(cls: type[T]) -> type[T]:
    """Resolve the fields of ``cls`` declared by a parameter model (``ddtrack.parameters.declared``) into their
    ``dataclasses.field``: apply below ``@dataclass`` on a plain dataclass; :func:`pytree_dataclass` does it itself."""
    for name, value in list(vars(cls).items()):
        if hasattr(value, "declared_field") and name in getattr(cls, "__annotations__", {}):
            setattr(cls, name, value.declared_field(name))
    return cls


def static_field(*, why: str = "", **kwargs: Any) -> Any:
    """A field of a :func:`pytree_dataclass` that is compile-time metadata (hashable, never an array): a change
    of its value compiles a new program, as a sample count or a scheme name should.

    Parameters
    ----------
    why
        Why it must be structure and cannot be a traced number (ddtrack's own static fields each say, or are
        declared :data:`~ddtrack.parameters.Structure`; ``tests/test_parameters.py`` holds them to it).
    **kwargs
        Passed to ``dataclasses.field`` (``default=...``).

    Returns
    -------
    dataclasses.Field
        The field, marked static.
    """
    return dataclasses.field(metadata={"static": True, "why": why}, **kwargs)


def parts(obj: Any) -> list[Any]:
    """``obj`` and every dataclass instance inside it, depth first (a cascade's outer law and inner loop, MPPI's
    cost): what a check over a built controller's declared fields walks."""
    if not dataclasses.is_dataclass(obj) or isinstance(obj, type):
        return []
    found = [obj]
    for field in dataclasses.fields(obj):
        found += parts(getattr(obj, field.name))
    return found
