"""Wheel-torque disturbances and pose-measurement noise (model.md §1.2, 4.1).

One disturbance form covers every kind the scenarios name (none, constant, sinusoid, gaussian):
``tau_d(t_k) = bias + amplitude * sin(frequency * t_k + phase) + std * xi_k``, with ``xi_k`` standard
normal draws made before the run from its seed and held over control period k.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array
from pydantic import Field

from .._pytree import FloatVector, pytree_dataclass
from ..parameters import NonNegative, Pair, Parameters, declared


class SinusoidTorque(Parameters):
    """The deterministic part of a wheel-torque disturbance, per wheel: bias + amplitude sin(frequency t + phase)
    (model.md §1.4's default), as the scenario's ``[disturbance] kind = "sinusoid"`` declares it."""

    bias: Pair = Field((0.0, 0.0), description="[right, left] constant part [N m].")
    amplitude: Pair = Field(description="[right, left] amplitude [N m].")
    frequency: NonNegative = Field(description="Angular frequency [rad/s].")
    phase: Pair = Field((0.0, 0.0), description="[right, left] phase [rad].")


@pytree_dataclass
class WheelDisturbance:
    """Disturbance torques [tau_R, tau_L] [N m]; positive opposes the drive.

    Attributes
    ----------
    bias
        (2,) constant part [N m]
    amplitude
        (2,) sinusoid amplitude [N m]
    frequency
        sinusoid angular frequency [rad/s]
    phase
        (2,) sinusoid phase [rad]
    std
        (2,) standard deviation of the Gaussian part, held per control period [N m]
    """

    bias: FloatVector = declared(SinusoidTorque)
    amplitude: FloatVector = (0.0, 0.0)  # the section requires one; zero is the other kinds' "no sinusoid"
    frequency: float = 0.0  # likewise
    phase: FloatVector = declared(SinusoidTorque)
    std: FloatVector = (0.0, 0.0)

    def torque(self, t: Array, xi: Array) -> Array:
        """Disturbance at time ``t`` given the standard-normal draw ``xi`` (2,) of that period."""
        bias, amp = jnp.asarray(self.bias), jnp.asarray(self.amplitude)
        return bias + amp * jnp.sin(self.frequency * t + jnp.asarray(self.phase)) + jnp.asarray(self.std) * xi


@pytree_dataclass
class MeasurementNoise:
    """Additive Gaussian noise on what the controller sees, y = X + std * xi, X the plant's observed
    :data:`~ddtrack.layout.BODY` vector.

    Attributes
    ----------
    std
        (5,) standard deviations of BODY's [x, y, theta, v, omega] [m, m, rad, m/s, rad/s]
    """

    std: FloatVector = (0.0, 0.0, 0.0, 0.0, 0.0)

    def measure(self, x: Array, xi: Array) -> Array:
        return x + jnp.asarray(self.std) * xi
