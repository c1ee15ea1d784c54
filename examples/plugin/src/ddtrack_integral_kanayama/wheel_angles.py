"""A ddtrack plant plugin: the Lagrangian robot with its two wheel angles as states, seven in all.

The plant declares its layouts (the five body states, then ``phi_r`` and ``phi_l`` [rad]) and advances like the
built-in ``dynamic`` plant, so its runs track exactly as the five-state robot's do; the wheel angles are recorded
as two more columns of ``timeseries.parquet``. ``register`` is the ``ddtrack.plants`` entry point
(pyproject.toml): from then on ``[plant] model = "wheel_angles"`` works in scenario files and every command.
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jax import Array

import ddtrack
from ddtrack.layout import BODY, WHEEL_TORQUES, Layout, velocity
from ddtrack.model import DynamicPlant, ODEPlant, RobotParams, wheel_speeds


@ddtrack.pytree_dataclass
class WheelAnglePlant(ODEPlant):
    """The Lagrangian robot with its wheel angles (phi_r, phi_l) [rad] as two more states."""

    params: RobotParams
    state_layout: ClassVar[Layout] = Layout((*BODY.names, "phi_r", "phi_l"), (*BODY.units, "rad", "rad"))
    logged_layout: ClassVar[Layout] = WHEEL_TORQUES

    def init(self, body: Array) -> Array:
        return jnp.concatenate([body, jnp.zeros(2)])  # the wheels start at angle 0

    def observe(self, x: Array) -> Array:
        return x[: len(BODY)]

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        body = DynamicPlant(self.params).derivative(x[: len(BODY)], u, tau_dist)
        return jnp.concatenate([body, wheel_speeds(self.params, velocity(x))])

    def saturate(self, u: Array) -> Array:
        return DynamicPlant(self.params).saturate(u)

    def logged(self, x: Array, u: Array) -> dict[str, Array]:
        return WHEEL_TORQUES.columns(u)


def register() -> None:
    """The ``ddtrack.plants`` entry point: make ``model = "wheel_angles"`` known to ddtrack."""
    ddtrack.register_plant("wheel_angles", WheelAnglePlant, summary="The Lagrangian robot with its wheel angles.")
