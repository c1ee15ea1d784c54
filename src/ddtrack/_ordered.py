"""Sums written as a fixed tree of elementwise additions.

XLA compiles ``jnp.sum`` to a reduce kernel whose order of summation depends on the operand's shape, batch
axis included: the emulator identified in a batch of 64 runs rounded differently from the same run's in a
batch of 2, through its gradient norm. Added pairwise by explicit slices, a sum leaves XLA nothing to reorder,
so a run and its row in any batch give the same bits (docs/reliability.md, tests/test_determinism.py).
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array


def total(x: Array) -> Array:
    """The sum of every element of ``x`` (row-major): halves added elementwise, level by level, an odd last term
    carried up; log2(size) dependent additions."""
    terms = jnp.ravel(x)
    while terms.shape[0] > 1:
        half = terms.shape[0] // 2
        paired = terms[:half] + terms[half : 2 * half]
        terms = paired if terms.shape[0] % 2 == 0 else jnp.concatenate([paired, terms[2 * half :]])
    return terms[0]
