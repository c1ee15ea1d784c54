"""A batch of runs: ``jax.vmap`` of :func:`simulate` over a leading axis of every argument."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import Any, TypeVar

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..precision import float64_in_this_thread
from .result import SimResult
from .simulate import ClosedLoop, Draws, simulate


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


@partial(jax.jit, static_argnames=("n_steps",))
def simulate_batch(loop: ClosedLoop, x0: Array, draws: Draws, *, n_steps: int) -> SimResult:
    """Run B simulations at once: every leaf of ``loop`` (its numbers included: each run has its own control period
    and bounds, so a study's cells can share a batch), ``x0`` and ``draws`` has a leading run axis B.

    Row i is the run :func:`simulate` would give for the arguments' row i (the same code, vmapped).
    """
    return vmap_runs(partial(simulate, n_steps=n_steps))(loop, x0, draws)


@partial(jax.jit, static_argnames=("n_steps",))
def simulate_alone(loop: ClosedLoop, x0: Array, draws: Draws, *, n_steps: int) -> SimResult:
    """One run (arguments without a run axis) as row 0 of :func:`simulate_batch`, so that its bits equal its row
    in any batch; adding and removing the run axis happen inside this one compiled program (no per-leaf dispatch).
    """
    runs = jax.tree_util.tree_map(lambda leaf: jnp.asarray(leaf)[None], (loop, x0, draws))
    return jax.tree_util.tree_map(lambda leaf: leaf[0], simulate_batch(*runs, n_steps=n_steps))


def repeated(loop: ClosedLoop, runs: int) -> ClosedLoop:
    """``loop`` whose numbers shared by every run (control period, bounds: scalars) are repeated along a leading run
    axis of ``runs``, its other leaves (already stacked, e.g. a prepared batch's plants) as they are."""
    numbers: dict[str, Any] = {
        name: np.full(runs, getattr(loop, name), dtype=float)
        for name in ("control_period", "divergence_error", "divergence_speed")
    }
    return dataclasses.replace(loop, **numbers)


Batched = TypeVar("Batched")


def in_shares(function: Callable[..., Batched], *args: Batched) -> Batched:
    """``function(*args)`` for a batch of runs (every array's leading axis is the run), the runs split evenly into
    one share per JAX device (``ddtrack`` asks for one per core: ``jax_num_cpu_devices``), each share computed as a
    batch of its own, from a thread of its own (in the caller's float64 setting, a ``with jax.enable_x64(True):``
    block included), all on the first device: one compiled program serves every share (a program per device
    compiled it once for each), and XLA runs the threads' calls side by side. The results are joined on the host.
    Left whole with one device, when the runs do not split evenly, or when a share would be a single run (computed
    as a lone run, it would round differently from its row in a batch: ``sim.vmap_runs``). Each share runs the
    program a batch of its size gets, so each row is the bits that batch gives it (its single run's, below 16 runs
    per share: docs/reliability.md); one program partitioned over the devices was not, for the NN-adaptive law (its
    emulator's rows moved in the last bits)."""
    shares = len(jax.devices())
    runs = len(jax.tree_util.tree_leaves(args)[0])
    if shares == 1 or runs % shares or runs < 2 * shares:
        return function(*args)
    share = runs // shares
    host = jax.tree_util.tree_map(np.asarray, args)  # cut on the host: a slice in JAX compiles a program per shape
    float64 = jax.config.read("jax_enable_x64")  # this thread's: `with jax.enable_x64(True):` holds only in it
    device = jax.devices()[0]  # the same device for every share: its program is compiled once

    def compute(i: int) -> Batched:
        rows = slice(i * share, (i + 1) * share)
        with float64_in_this_thread(float64):
            part = function(*jax.device_put(jax.tree_util.tree_map(lambda leaf: leaf[rows], host), device))
        return jax.tree_util.tree_map(np.asarray, part)

    # a thread per share: called one after another from one thread, the NN identification's shares ran one after
    # another, no faster than one share (docs/benchmarks.md, "ddtrack mc"); from a thread each, side by side
    pool = ThreadPoolExecutor(shares)
    try:
        parts = list(pool.map(compute, range(shares)))
    finally:  # on Ctrl-C, return at once (the shares still computing end unwatched): waiting held `mc` for seconds
        pool.shutdown(wait=False, cancel_futures=True)
    return jax.tree_util.tree_map(lambda *leaves: np.concatenate(leaves), *parts)
