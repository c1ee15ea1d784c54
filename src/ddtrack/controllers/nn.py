"""The emulator network of the NN-adaptive controller (model.md §3.7; paper eqs. 19, 20, 32-34 corrected).

Two layers, tanh hidden units, linear output, biases, with fixed input and output scales:
z~ = z / s_z,  h = tanh(W1 z~ + b1),  y~ = W2 h + b2,  y = s_y * y~.
Pure functions over an :class:`MLP` pytree; training is per-sample backpropagation with momentum
and global gradient-norm clipping.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import Array

from .._ordered import total
from .._pytree import pytree_dataclass


@pytree_dataclass
class MLP:
    """Weights: ``w1`` (N_h, n_in), ``b1`` (N_h,), ``w2`` (n_out, N_h), ``b2`` (n_out,)."""

    w1: Array
    b1: Array
    w2: Array
    b2: Array


@pytree_dataclass
class Scales:
    """Fixed a-priori normalisation (not refitted online, so the Jacobian's scale cannot drift)."""

    inputs: Array  #: s_z (n_in,)
    outputs: Array  #: s_y (n_out,)


def init_mlp(key: Array, n_in: int, n_hidden: int, n_out: int) -> MLP:
    """W1 ~ U(-1, 1)/sqrt(n_in), W2 ~ U(-1, 1)/sqrt(N_h), biases 0 (model.md §3.7)."""
    k1, k2 = jax.random.split(key)
    return MLP(
        w1=jax.random.uniform(k1, (n_hidden, n_in), minval=-1.0, maxval=1.0) / jnp.sqrt(n_in),
        b1=jnp.zeros(n_hidden),
        w2=jax.random.uniform(k2, (n_out, n_hidden), minval=-1.0, maxval=1.0) / jnp.sqrt(n_hidden),
        b2=jnp.zeros(n_out),
    )


def forward(mlp: MLP, z_normalised: Array) -> tuple[Array, Array]:
    """Normalised output y~ and hidden activations h (paper eqs. 19-20 with a linear output, eq. 32)."""
    h = jnp.tanh(mlp.w1 @ z_normalised + mlp.b1)
    return mlp.w2 @ h + mlp.b2, h


def predict(mlp: MLP, scales: Scales, z: Array) -> Array:
    """y = s_y * y~(z / s_z), in physical units."""
    return scales.outputs * forward(mlp, z / scales.inputs)[0]


def input_jacobian(mlp: MLP, scales: Scales, z: Array) -> Array:
    """dy/dz = diag(s_y) W2 diag(1 - h^2) W1 diag(1/s_z) (paper eq. 34 corrected, model.md §3.7), (n_out, n_in)."""
    _, h = forward(mlp, z / scales.inputs)
    return (scales.outputs[:, None] * mlp.w2) @ ((1.0 - h**2)[:, None] * mlp.w1) / scales.inputs[None, :]


def sample_loss(mlp: MLP, z_normalised: Array, target_normalised: Array) -> Array:
    """E = |y~ - y~*|^2 / 2 in normalised units."""
    error = forward(mlp, z_normalised)[0] - target_normalised
    return 0.5 * total(error**2)


def backprop(mlp: MLP, z_normalised: Array, target_normalised: Array) -> MLP:
    """Gradient of :func:`sample_loss` by the closed form of model.md §3.7 (delta_2 = y~ - y~*, ...)."""
    y, h = forward(mlp, z_normalised)
    delta2 = y - target_normalised
    delta1 = (mlp.w2.T @ delta2) * (1.0 - h**2)
    return MLP(w1=jnp.outer(delta1, z_normalised), b1=delta1, w2=jnp.outer(delta2, h), b2=delta2)


def momentum_step(
    mlp: MLP,
    velocity: MLP,
    gradient: MLP,
    *,
    learning_rate: Array | float,
    momentum: Array | float,
    clip_norm: Array | float,
) -> tuple[MLP, MLP]:
    """dW(k) = -eta * clip(grad) + beta * dW(k-1); W <- W + dW, for every weight array (model.md §3.7)."""
    norm = jnp.sqrt(total(jnp.concatenate([jnp.ravel(g**2) for g in jax.tree_util.tree_leaves(gradient)])))
    factor = jnp.minimum(1.0, clip_norm / jnp.maximum(norm, 1e-300))
    velocity = jax.tree_util.tree_map(lambda g, v: -learning_rate * factor * g + momentum * v, gradient, velocity)
    return jax.tree_util.tree_map(jnp.add, mlp, velocity), velocity


def zeros_like(mlp: MLP) -> MLP:
    """An MLP of the same shapes with every weight and bias 0 (the initial momentum of the backpropagation)."""
    return jax.tree_util.tree_map(jnp.zeros_like, mlp)
