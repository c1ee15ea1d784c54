"""Frozen dataclasses that are JAX pytrees: numeric fields are traced leaves, ``static`` fields are not."""

from __future__ import annotations

import dataclasses
from typing import Any, TypeAlias, TypeVar, dataclass_transform

import jax
import numpy as np
from jax import Array

T = TypeVar("T")

FloatVector: TypeAlias = Array | np.ndarray | tuple[float, ...]
"""A short numeric field (gains, one value per wheel): a tuple of floats where a scenario or a default builds it,
an array once batched or traced. Code reads it through ``jnp.asarray``, which takes either."""


@dataclass_transform(frozen_default=True, field_specifiers=(dataclasses.field,))
def pytree_dataclass(cls: type[T]) -> type[T]:
    """Make ``cls`` a frozen dataclass registered as a pytree.

    Fields declared with ``static_field()`` become part of the tree structure (and of the jit
    cache key); every other field is a leaf, so changing a gain or a mass never recompiles.
    """
    cls = dataclasses.dataclass(frozen=True)(cls)
    return jax.tree_util.register_dataclass(cls)


def static_field(**kwargs: Any) -> Any:
    """A dataclass field that is compile-time metadata (hashable, never an array)."""
    return dataclasses.field(metadata={"static": True}, **kwargs)
