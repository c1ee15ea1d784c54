"""Fixed-step integration, low enough that plants, references, the simulator and model-based controllers share it;
:class:`Solver`, the method a plant is advanced with (an argument of ``plant.advance``, as diffrax's solver is)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar, Protocol

import jax
import jax.numpy as jnp
from jax import Array, lax

from ._pytree import pytree_dataclass
from .parameters import Timing, declared


def rk4_step_timed(f: Callable[[Array | float, Array], Array], t: Array | float, x: Array, h: Array | float) -> Array:
    """One classical fourth-order Runge-Kutta step of x_dot = f(t, x) from ``t`` with step ``h`` (error O(h^4))."""
    k1 = f(t, x)
    k2 = f(t + 0.5 * h, x + 0.5 * h * k1)
    k3 = f(t + 0.5 * h, x + 0.5 * h * k2)
    k4 = f(t + h, x + h * k3)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def rk4_step(f: Callable[[Array], Array], x: Array, h: Array | float) -> Array:
    """One RK4 step of the autonomous x_dot = f(x) (:func:`rk4_step_timed`)."""
    return rk4_step_timed(lambda _, z: f(z), 0.0, x, h)


def rk4(f: Callable[[Array], Array], x: Array, duration: Array | float, steps: int | Array) -> Array:
    """Integrate x_dot = f(x) over ``duration`` in ``steps`` equal RK4 steps. A traced ``steps`` makes the loop a
    ``while_loop`` (one program for every count; forward-mode differentiable only), a Python int a ``scan``."""
    h = duration / steps
    return lax.fori_loop(0, steps, lambda _, z: rk4_step(f, z, h), x)


class Solver(Protocol):
    """A fixed-step method for x_dot = f(x) in ``substeps`` equal steps, which ``plant.advance`` integrates with.

    A solver is a dataclass (a :func:`~ddtrack._pytree.pytree_dataclass` whose ``substeps`` is a static field), so
    ``dataclasses.replace(solver, substeps=n)`` is the same method at ``n`` steps: the sensing chain shares a period's
    steps between its pieces this way, and a slip plant raises them to its own floor, there a traced integer (its
    ``integrate`` must take a traced count as a loop bound, as ``lax.fori_loop`` does).
    """

    __dataclass_fields__: ClassVar[dict[str, Any]]  # a dataclass: dataclasses.replace gives another step count

    @property
    def substeps(self) -> int:
        """Steps per call: a loop bound, so structure (part of the jit key)."""
        ...

    def integrate(self, f: Callable[[Array], Array], x: Array, duration: Array | float) -> Array:
        """The state ``duration`` [s] after ``x`` under x_dot = ``f(x)``, in ``substeps`` equal steps."""
        ...


@pytree_dataclass
class RK4:
    """Classical RK4 in ``substeps`` equal steps (:func:`rk4`): the :class:`Solver` the simulator passes plants."""

    substeps: int = declared(Timing)  # Timing.substeps (10), static: the loop bound

    def integrate(self, f: Callable[[Array], Array], x: Array, duration: Array | float) -> Array:
        """:func:`rk4` over ``duration`` [s] in ``substeps`` steps (the same bits)."""
        return rk4(f, x, duration, self.substeps)


def semi_implicit_euler_step(
    acceleration: Callable[[Array, Array], Array],
    displacement: Callable[[Array, Array, float], Array],
    q: Array,
    v: Array,
    h: float,
) -> tuple[Array, Array]:
    """One semi-implicit (symplectic) Euler step of v_dot = acceleration(q, v) and the positions: the velocities
    first, v' = v + h a(q, v), then the positions moved by them, q' = q + displacement(q, v', h) (h q_dot(q, v'), given
    as a function of h so that a kinematic map linear in v can scale v first). First order, but it keeps a lightly
    damped oscillation bounded where explicit Euler inflates it (MPPI's cheap rollouts use it)."""
    v_next = v + h * acceleration(q, v)
    return q + displacement(q, v_next, h), v_next


#: gamma of the two-stage Rosenbrock method ROS2 (Verwer et al. 1999): 1 + 1/sqrt(2) makes it L-stable
ROS2_GAMMA = 1.0 + 1.0 / 2.0**0.5


def lu_unpivoted(a: Array) -> list[list[Array]]:
    """The LU factors of a small (n, n) matrix by Gaussian elimination without pivoting, unrolled into scalar
    operations (so a vmapped batch runs them elementwise, many times faster than batched LAPACK calls). For
    matrices whose leading minors stay well away from zero, such as I - gamma h J of a damped system; n <= ~10."""
    n = a.shape[0]
    m = [[a[i, j] for j in range(n)] for i in range(n)]
    for k in range(n):
        inverse = 1.0 / m[k][k]
        for i in range(k + 1, n):
            m[i][k] = m[i][k] * inverse  # the multiplier, stored where the zero would be
            for j in range(k + 1, n):
                m[i][j] = m[i][j] - m[i][k] * m[k][j]
    return m


def lu_solve_unpivoted(factors: list[list[Array]], b: Array) -> Array:
    """The solution x of A x = b from :func:`lu_unpivoted`'s factors of A."""
    n = len(factors)
    y = [b[i] for i in range(n)]
    for i in range(n):  # forward: L y = b, unit diagonal
        for j in range(i):
            y[i] = y[i] - factors[i][j] * y[j]
    x: list[Array] = [y[0]] * n
    for i in reversed(range(n)):  # backward: U x = y
        total = y[i]
        for j in range(i + 1, n):
            total = total - factors[i][j] * x[j]
        x[i] = total / factors[i][i]
    return jnp.stack(x)


def rosenbrock2_step(
    f: Callable[[Array], Array], x: Array, h: Array | float, stiff: tuple[int, int] | None = None
) -> Array:
    """One linearly implicit two-stage Rosenbrock step (ROS2) of the autonomous x_dot = f(x), second order.

    With A = df/dx at ``x`` (``jax.jacfwd``) and W = I - gamma h A: W k1 = f(x), W k2 = f(x + h k1) - 2 k1,
    x' = x + h (3 k1 + k2) / 2. It solves two linear systems instead of iterating and is L-stable: a stiff,
    decaying mode is damped at any step h, where explicit RK4 needs h |lambda| < 2.8. The method is second order
    for any matrix A, so ``stiff = (lo, hi)`` may restrict A to the block of x[lo:hi] (the stiff states): the
    others are then stepped explicitly, and only an (hi - lo)-square Jacobian is formed and factored.
    """
    lo, hi = stiff if stiff is not None else (0, x.shape[0])
    jac = jax.jacfwd(lambda z: f(x.at[lo:hi].set(z))[lo:hi])(x[lo:hi])
    factors = lu_unpivoted(jnp.eye(hi - lo) - ROS2_GAMMA * h * jac)

    def solve(r: Array) -> Array:
        return r.at[lo:hi].set(lu_solve_unpivoted(factors, r[lo:hi]))

    k1 = solve(f(x))
    k2 = solve(f(x + h * k1) - 2.0 * k1)
    return x + h * (1.5 * k1 + 0.5 * k2)


def rosenbrock2(
    f: Callable[[Array], Array],
    x: Array,
    duration: Array | float,
    steps: int | Array,
    stiff: tuple[int, int] | None = None,
) -> Array:
    """Integrate x_dot = f(x) over ``duration`` in ``steps`` equal :func:`rosenbrock2_step` steps (traced or a
    Python int, as :func:`rk4`'s)."""
    h = duration / steps
    return lax.fori_loop(0, steps, lambda _, z: rosenbrock2_step(f, z, h, stiff), x)
