"""Small matrix products and sums written as a fixed sequence of elementwise operations.

XLA compiles ``a @ b`` and ``jnp.sum`` to dot and reduce kernels whose order of summation depends on the
operands' shapes, batch axis included: the emulator identified in a batch of 64 runs rounded differently
from the same run's in a batch of 2. Spelled out term by term, a sum leaves XLA nothing to reorder, so a
run and its row in any batch give the same bits (docs/reliability.md, tests/test_determinism.py).
"""
from __future__ import annotations

import jax.numpy as jnp
from jax import Array


def matmul(a: Array, b: Array) -> Array:
    """``a @ b`` for a matrix or vector ``a`` and ``b``, summed over k = 0, 1, ... in that order."""
    a2 = a if a.ndim == 2 else a[None, :]
    b2 = b if b.ndim == 2 else b[:, None]
    out = a2[:, 0:1] * b2[0:1, :]
    for k in range(1, a2.shape[1]):
        out = out + a2[:, k:k + 1] * b2[k:k + 1, :]
    if a.ndim == 1:
        out = out[0]
    return out[..., 0] if b.ndim == 1 else out


def total(x: Array) -> Array:
    """The sum of every element of ``x``, added in row-major order."""
    flat = jnp.ravel(x)
    out = flat[0]
    for k in range(1, flat.shape[0]):
        out = out + flat[k]
    return out
