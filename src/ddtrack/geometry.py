"""Planar geometry shared by the model, the controllers and the metrics (model.md §0, 2.2)."""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array


def wrap_angle(angle: Array) -> Array:
    """Map an angle to (-pi, pi] [rad]."""
    wrapped = jnp.mod(angle + jnp.pi, 2.0 * jnp.pi) - jnp.pi
    return jnp.where(wrapped == -jnp.pi, jnp.pi, wrapped)


def rotation(theta: Array) -> Array:
    """R_3(theta): body-to-world rotation of a pose increment (model.md §3.3)."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    zero, one = jnp.zeros_like(theta), jnp.ones_like(theta)
    return jnp.array([[c, -s, zero], [s, c, zero], [zero, zero, one]])


def posture_error(x: Array, y: Array, theta: Array, x_r: Array, y_r: Array, theta_r: Array) -> Array:
    """Kanayama posture error e_p = T_e(theta) (q_r - q), e_theta wrapped (model.md §2.2; paper eq. 12 corrected).

    Returns ``[e_x, e_y, e_theta]``: along-track [m] (positive: reference ahead), lateral [m]
    (positive: reference to the robot's left), heading [rad].
    """
    c, s = jnp.cos(theta), jnp.sin(theta)
    dx, dy = x_r - x, y_r - y
    return jnp.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(theta_r - theta)])


def error_rates(error: Array, v: Array, omega: Array, v_r: Array, omega_r: Array) -> Array:
    """Kanayama error dynamics d/dt [e_x, e_y, e_theta] (model.md §2.3)."""
    e_x, e_y, e_theta = error[0], error[1], error[2]
    return jnp.stack(
        [
            omega * e_y - v + v_r * jnp.cos(e_theta),
            -omega * e_x + v_r * jnp.sin(e_theta),
            omega_r - omega,
        ]
    )


def body_increment(pose: Array, next_pose: Array) -> Array:
    """One-step pose increment in the body frame of ``pose`` (model.md §3.7, emulator E1 target):
    [c dx + s dy, -s dx + c dy, wrap(theta' - theta)]."""
    c, s = jnp.cos(pose[2]), jnp.sin(pose[2])
    dx, dy = next_pose[0] - pose[0], next_pose[1] - pose[1]
    return jnp.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(next_pose[2] - pose[2])])
