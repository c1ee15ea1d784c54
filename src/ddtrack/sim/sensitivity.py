"""One control period of the nominal model, differentiable: the NN-adaptive gain law's model Jacobians.

The paper's gain law needs J = d q(k+1) / d nu_c(k) (model.md §3.4). Besides the emulator's Jacobian (eq. 34) and the
analytic approximations (a), (b), this gives the exact per-sample sensitivity of the *nominal* model: one period of
the controller's own model of the robot under its inner loop, with nu_c held, differentiated by ``jax.jacfwd``.
It lives in ``sim`` because it integrates; the scenario layer hands it to the controller, which sees it only
through :meth:`NominalPeriod.jacobian`, to which it hands its own command type (so ``sim`` imports no controller).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jax import Array

from .._pytree import pytree_dataclass, static_field
from ..integrators import rk4
from ..layout import pose_vector


@pytree_dataclass
class NominalPeriod:
    """``plant`` (the nominal model) under ``inner`` (the controller's inner loop) for one period T_c."""

    plant: Any
    inner: Any
    control_period: float
    substeps: int = static_field(default=10, why="a loop bound")

    def increment(self, nu: Array, command: Any) -> Array:
        """Body-frame pose increment (dx_b, dy_b, dtheta) over one period from velocity ``nu``, ``command`` (what the
        inner loop takes: a ``VelocityCommand``) held."""
        x = jnp.concatenate([jnp.zeros(3), nu])
        tau, _, _ = self.inner.torque(x, command, self.inner.init(x, None, None))
        tau = self.plant.saturate(tau)
        end = rk4(
            lambda z: self.plant.derivative(z, tau, jnp.zeros(2)),
            self.plant.hold(x, tau),
            self.control_period,
            self.substeps,
        )
        return pose_vector(end)

    def jacobian(self, nu: Array, nu_c: Array, command_of: Callable[[Array], Any]) -> Array:
        """J_b = d increment / d nu_c (3x2), ``command_of(nu_c)`` building the held command: zero in a channel
        whose torque saturates, as on the robot."""
        return jax.jacfwd(lambda c: self.increment(nu, command_of(c)))(nu_c)
