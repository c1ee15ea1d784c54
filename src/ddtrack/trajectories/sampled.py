"""A reference tabulated at a fixed time step, for references without a closed-form pose."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jax import Array

from .._pytree import pytree_dataclass
from ..geometry import wrap_angle
from ..integrators import rk4_step_timed
from .base import Reference


@pytree_dataclass
class SampledTrajectory:
    """Reference rows (x, y, theta, v, omega, v_dot, omega_dot) at t = i * ``step``; a time between
    samples takes the nearest row (the simulator only asks at multiples of its control period)."""

    table: Array
    step: float

    def __call__(self, t: Array | float) -> Reference:
        i = jnp.clip(jnp.round(jnp.asarray(t, float) / self.step).astype(int), 0, self.table.shape[0] - 1)
        return Reference(*self.table[i])


def unicycle_reference(
    speed: Callable[[Array], Array],
    yaw_rate: Callable[[Array], Array],
    *,
    duration: float,
    step: float,
    substeps: int = 10,
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> SampledTrajectory:
    """The virtual unicycle q_r' = S(q_r) (v_r(t), omega_r(t)) (model.md §2.1) from ``pose`` at t = 0,
    integrated by RK4 with ``substeps`` per ``step`` and tabulated every ``step`` [s]."""
    n = round(duration / step) + 1
    h = step / substeps

    def rate(t, q):
        v = speed(t)
        return jnp.stack([v * jnp.cos(q[2]), v * jnp.sin(q[2]), yaw_rate(t)])

    def rk4(carry, _):
        t, q = carry
        return (t + h, rk4_step_timed(rate, t, q, h)), None

    def sample(carry, _):
        (t, q), _ = jax.lax.scan(rk4, carry, None, length=substeps)
        return (t, q), q

    q0 = jnp.asarray(pose, float)
    _, poses = jax.lax.scan(sample, (jnp.asarray(0.0), q0), None, length=n - 1)
    poses = jnp.concatenate([q0[None], poses])
    t = jnp.arange(n) * step
    v, w = jax.vmap(speed)(t), jax.vmap(yaw_rate)(t)
    v_dot, w_dot = jax.vmap(jax.grad(speed))(t), jax.vmap(jax.grad(yaw_rate))(t)
    table = jnp.stack([poses[:, 0], poses[:, 1], wrap_angle(poses[:, 2]), v, w, v_dot, w_dot], axis=1)
    return SampledTrajectory(table=table, step=step)
