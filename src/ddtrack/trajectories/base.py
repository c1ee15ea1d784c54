"""The reference signal and the trajectory protocol (model.md §2.1)."""

from __future__ import annotations

from typing import NamedTuple, Protocol

import jax
import jax.numpy as jnp
from jax import Array

from ..geometry import wrap_angle


class Reference(NamedTuple):
    """Reference at one instant (float64 scalars, or arrays when batched)."""

    x: Array  #: reference point [m]
    y: Array  #: reference point [m]
    theta: Array  #: heading [rad], in (-pi, pi]
    v: Array  #: feed-forward speed v_r >= 0 [m/s]
    omega: Array  #: feed-forward yaw rate omega_r [rad/s]
    v_dot: Array  #: dv_r/dt [m/s^2]
    omega_dot: Array  #: d omega_r/dt [rad/s^2]


jax.export.register_namedtuple_serialization(Reference, serialized_name="ddtrack.Reference")  # in a SimResult


class Trajectory(Protocol):
    """A time-parametrised reference: a pure function ``t [s] -> Reference``."""

    def __call__(self, t: Array | float) -> Reference: ...


class ParametricCurve:
    """Mixin for smooth curves given by ``position(t) -> [x, y]``.

    Velocities and their derivatives are exact, from forward-mode autodiff of ``position``:
    v = |p'|, theta = atan2(p'), omega = (x'y'' - y'x'') / v^2, and their time derivatives.
    The curve must never stop (v > 0).
    """

    def position(self, t: Array) -> Array:
        raise NotImplementedError

    def __call__(self, t: Array | float) -> Reference:
        t = jnp.asarray(t, dtype=float)

        def derivative(f):
            return lambda s: jax.jvp(f, (s,), (jnp.ones_like(s),))[1]

        d1 = derivative(self.position)
        d2 = derivative(d1)
        d3 = derivative(d2)
        p, p1, p2, p3 = self.position(t), d1(t), d2(t), d3(t)
        speed = jnp.hypot(p1[0], p1[1])
        cross = p1[0] * p2[1] - p1[1] * p2[0]
        cross_dot = p1[0] * p3[1] - p1[1] * p3[0]
        v_dot = (p1[0] * p2[0] + p1[1] * p2[1]) / speed
        omega = cross / speed**2
        omega_dot = cross_dot / speed**2 - 2.0 * cross * v_dot / speed**3
        theta = wrap_angle(jnp.arctan2(p1[1], p1[0]))
        return Reference(p[0], p[1], theta, speed, omega, v_dot, omega_dot)
