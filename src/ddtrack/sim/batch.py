"""A batch of runs: ``jax.vmap`` of :func:`simulate` over a leading axis of every argument."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp

from .result import SimResult
from .simulate import DIVERGENCE_SPEED, simulate


def stack(trees: Sequence[Any]) -> Any:
    """Stack pytrees of one structure along a new leading axis (the batch axis)."""
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack([jnp.asarray(leaf) for leaf in leaves]), *trees)


def vmap_runs(function: Callable) -> Callable:
    """``jax.vmap(function)`` over a leading run axis, a batch of one computed as two copies of the run.

    XLA compiles a batch of one (or a lone run) to the unbatched program, which rounds a few values
    differently in the last bit; through this, a run gives the same bits alone or as any batch's row.
    """

    def batched(*args: Any) -> Any:
        if len(jax.tree_util.tree_leaves(args)[0]) != 1:
            return jax.vmap(function)(*args)
        doubled = jax.tree_util.tree_map(lambda leaf: jnp.concatenate([leaf, leaf]), args)
        return jax.tree_util.tree_map(lambda leaf: leaf[:1], jax.vmap(function)(*doubled))

    return batched


@partial(jax.jit, static_argnames=("n_steps", "substeps"))
def simulate_batch(
    plant: Any,
    controller: Any,
    trajectory: Any,
    x0: Any,
    draws: Any,
    disturbance: Any,
    noise: Any,
    *,
    n_steps: int,
    control_period: float,
    substeps: int,
    divergence_error: float,
    divergence_speed: float = DIVERGENCE_SPEED,
) -> SimResult:
    """Run B simulations at once; every argument but the static ones has a leading batch axis B.

    Row i is the run :func:`simulate` would give for the arguments' row i (the same code, vmapped).
    """

    def one(plant, controller, trajectory, x0, draws, disturbance, noise):
        return simulate(
            plant,
            controller,
            trajectory,
            x0,
            draws,
            n_steps=n_steps,
            control_period=control_period,
            substeps=substeps,
            disturbance=disturbance,
            noise=noise,
            divergence_error=divergence_error,
            divergence_speed=divergence_speed,
        )

    return vmap_runs(one)(plant, controller, trajectory, x0, draws, disturbance, noise)


@partial(jax.jit, static_argnames=("n_steps", "substeps"))
def simulate_alone(
    plant: Any,
    controller: Any,
    trajectory: Any,
    x0: Any,
    draws: Any,
    disturbance: Any,
    noise: Any,
    *,
    n_steps: int,
    control_period: float,
    substeps: int,
    divergence_error: float,
    divergence_speed: float = DIVERGENCE_SPEED,
) -> SimResult:
    """One run (arguments without a batch axis) as row 0 of :func:`simulate_batch`, so that its bits equal its row
    in any batch; adding and removing the batch axis happen inside this one compiled program (no per-leaf dispatch).
    """
    runs = jax.tree_util.tree_map(
        lambda leaf: jnp.asarray(leaf)[None], (plant, controller, trajectory, x0, draws, disturbance, noise)
    )
    batch = simulate_batch(
        *runs,
        n_steps=n_steps,
        control_period=control_period,
        substeps=substeps,
        divergence_error=divergence_error,
        divergence_speed=divergence_speed,
    )
    return jax.tree_util.tree_map(lambda leaf: leaf[0], batch)
