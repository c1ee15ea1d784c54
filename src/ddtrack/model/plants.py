"""Plants the simulator integrates. Both share the state ``X = [x, y, theta, v, omega]``.

A plant is three pure functions: ``hold`` (what the held input does to the state at the start of a
control period), ``derivative`` (X_dot under the held input and disturbance) and ``saturate``
(actuator limits).
"""

from __future__ import annotations

from typing import Protocol

import jax.numpy as jnp
from jax import Array

from .._pytree import pytree_dataclass
from .dynamics import body_acceleration, pose_rate
from .params import RobotParams


class Plant(Protocol):
    """What :func:`ddtrack.sim.simulate` needs of a plant."""

    input_kind: str  # "torque" [N m] or "velocity" [m/s, rad/s]

    def hold(self, x: Array, u: Array) -> Array:
        """The state at the start of a control period once the held input ``u`` applies (unchanged for torques;
        the velocities replaced for a velocity input). ``x`` = [x, y, theta, v, omega] [m, m, rad, m/s, rad/s]."""
        ...

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        """X_dot under the held input ``u`` and the wheel disturbance torques ``tau_dist`` (2,) [N m]
        (model.md §1.3): [x_dot, y_dot, theta_dot, v_dot, omega_dot]."""
        ...

    def saturate(self, u: Array) -> Array:
        """``u`` within the actuator limits (e.g. |tau| <= max_torque [N m])."""
        ...


@pytree_dataclass
class DynamicPlant:
    """The Lagrangian robot (model.md §1.3): input wheel torques [N m], saturated at ``params.max_torque``."""

    params: RobotParams
    input_kind = "torque"

    def hold(self, x: Array, u: Array) -> Array:
        return x

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        return jnp.concatenate([pose_rate(x[2], x[3], x[4]), body_acceleration(self.params, x[3:5], u, tau_dist)])

    def saturate(self, u: Array) -> Array:
        return jnp.clip(u, -self.params.max_torque, self.params.max_torque)


@pytree_dataclass
class KinematicPlant:
    """The unicycle with ideal velocity tracking: input nu = (v, omega), applied at once and held.

    Disturbances have no effect (there are no torques); for tests and the kinematic baseline.
    """

    input_kind = "velocity"

    def hold(self, x: Array, u: Array) -> Array:
        return x.at[3:5].set(u)

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        return jnp.concatenate([pose_rate(x[2], x[3], x[4]), jnp.zeros(2)])

    def saturate(self, u: Array) -> Array:
        return u
