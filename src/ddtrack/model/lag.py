"""The identified velocity-lag model of a velocity-commanded base (model.md §1.8).

A commercial base takes a velocity command nu* = (v*, omega*) and its own motor loop tracks it with a lag. Martins
et al. (2008) and De La Cruz and Carelli (2008) identify that behaviour with six parameters theta_1..theta_6::

    v_dot     = ( theta_3 omega^2   - theta_4 v     + v*     ) / theta_1
    omega_dot = (-theta_5 v omega   - theta_6 omega + omega* ) / theta_2

with the unicycle kinematics x_dot = v cos theta, y_dot = v sin theta, theta_dot = omega (model.md §1.1). Without
the coupling terms (theta_3 = theta_5 = 0) each speed is a first-order lag: time constant theta_1 / theta_4 and DC
gain 1 / theta_4 for v, theta_2 / theta_6 and 1 / theta_6 for omega. The model is linear in theta, which is what
makes it identifiable by least squares and adaptable on line.

Sources: F. N. Martins, W. C. Celeste, R. Carelli, M. Sarcinelli-Filho, T. F. Bastos-Filho, "An adaptive dynamic
controller for autonomous mobile robot trajectory tracking", Control Engineering Practice 16:1354-1363, 2008;
C. De La Cruz, R. Carelli, "Dynamic model based formation control and obstacle avoidance of multi-robot systems",
Robotica 26:345-356, 2008; F. N. Martins et al., J. Intell. Robot. Syst. 85:277-292, 2017.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import ClassVar

import jax.numpy as jnp
from jax import Array

from .._pytree import FloatVector, pytree_dataclass
from ..layout import VELOCITY_COMMAND, Layout, pose, velocity
from .dynamics import pose_rate
from .params import RobotParams
from .plants import ODEPlant

#: A Pioneer 3-DX carrying a laser scanner, theta_1..theta_6 [s, s, s m/rad^2, 1, s/m, 1] as distributed with
#: Martins et al.'s public code (lags theta_1/theta_4 = 0.26 s, theta_2/theta_6 = 0.23 s; gains close to 1)
PIONEER_3DX_WITH_LASER = (0.2604, 0.2509, -0.0005, 0.9965, 0.0026, 1.0768)
#: the other Pioneer 3-DX set distributed with the same code (lags 0.56 s and 0.20 s)
PIONEER_3DX_ALTERNATIVE = (0.5338, 0.2168, -0.0134, 0.9560, -0.0843, 1.0590)


@pytree_dataclass
class LagPlant(ODEPlant):
    """A velocity-commanded base with the identified lag dynamics (model.md §1.8); input (v*, omega*).

    Its state is the :data:`~ddtrack.layout.BODY` vector [x, y, theta, v, omega]; the speeds follow the command
    through the lag, not at once as :class:`~ddtrack.model.KinematicPlant`'s do. Wheel disturbance torques have no
    effect (the identified model has no torques). ``saturate`` clips the command to the optional speed limits
    (infinite by default: the identity).

    Attributes
    ----------
    theta : tuple of 6 floats or Array
        theta_1..theta_6 of Martins et al. (e.g. :data:`PIONEER_3DX_WITH_LASER`); theta_1, theta_2 > 0.
    max_speed : float
        |v*| <= max_speed [m/s].
    max_yaw_rate : float
        |omega*| <= max_yaw_rate [rad/s].
    """

    theta: FloatVector
    max_speed: Array | float = math.inf
    max_yaw_rate: Array | float = math.inf
    input_layout: ClassVar[Layout] = VELOCITY_COMMAND

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        """[x_dot, y_dot, theta_dot, v_dot, omega_dot] under the held command ``u`` = (v*, omega*)."""
        _, _, heading = pose(x)
        v, omega = velocity(x)
        theta = jnp.asarray(self.theta)
        t1, t2, t3, t4, t5, t6 = (theta[i] for i in range(6))
        v_dot = (t3 * omega**2 - t4 * v + u[0]) / t1
        omega_dot = (-t5 * v * omega - t6 * omega + u[1]) / t2
        return jnp.concatenate([pose_rate(heading, v, omega), jnp.stack([v_dot, omega_dot])])

    def saturate(self, u: Array) -> Array:
        """``u`` with |v*| <= ``max_speed`` and |omega*| <= ``max_yaw_rate``."""
        limits = jnp.stack([jnp.asarray(self.max_speed, dtype=float), jnp.asarray(self.max_yaw_rate, dtype=float)])
        return jnp.clip(u, -limits, limits)

    def steady_speeds(self, command: Array) -> Array:
        """(v, omega) the base settles at under a constant command without the coupling terms (theta_3 = theta_5
        = 0 or one speed zero): (v* / theta_4, omega* / theta_6)."""
        theta = jnp.asarray(self.theta)
        return jnp.asarray(command) / jnp.stack([theta[3], theta[5]])

    def time_constants(self) -> Array:
        """(theta_1 / theta_4, theta_2 / theta_6) [s]: the lags of v and omega without the coupling terms."""
        theta = jnp.asarray(self.theta)
        return jnp.stack([theta[0] / theta[3], theta[1] / theta[5]])


def lag_plant_model(
    theta: FloatVector, max_speed: float = math.inf, max_yaw_rate: float = math.inf
) -> Callable[[RobotParams], LagPlant]:
    """A ``Setup.plant_model`` that simulates the lag plant ``theta`` whatever the drawn robot.

    The identified model has no mass or wheel radius, so the robot's parameters are ignored; its leaves take the
    parameters' leading batch axis, so the same model serves a single run and a batch
    (``dataclasses.replace(setup, plant_model=lag_plant_model(PIONEER_3DX_WITH_LASER))``).
    """

    def plant_model(params: RobotParams) -> LagPlant:
        batch = jnp.shape(params.mass)
        return LagPlant(
            theta=jnp.broadcast_to(jnp.asarray(theta, dtype=float), (*batch, 6)),
            max_speed=jnp.broadcast_to(jnp.asarray(max_speed, dtype=float), batch),
            max_yaw_rate=jnp.broadcast_to(jnp.asarray(max_yaw_rate, dtype=float), batch),
        )

    return plant_model
