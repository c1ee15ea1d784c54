"""Kinematics and Lagrangian dynamics of the differential-drive robot (model.md §1; paper eqs. 1-9).

State ``X = [x, y, theta, v, omega]``: pose of the axle midpoint A [m, m, rad], forward speed [m/s]
and yaw rate [rad/s]. Wheel torques ``tau = [tau_R, tau_L]`` [N m].
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array

from .params import RobotParams

# --- kinematics (model.md §1.1) -------------------------------------------------------------------


def constraint_matrix(theta: Array) -> Array:
    """A(q) = [-sin, cos, 0]: no lateral slip, A(q) q_dot = 0 (paper eq. 1 corrected)."""
    return jnp.array([[-jnp.sin(theta), jnp.cos(theta), 0.0]])


def velocity_basis(theta: Array) -> Array:
    """S(q) = H(q), 3x2, with q_dot = S(q) nu (paper eqs. 2-3, 10)."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.array([[c, 0.0], [s, 0.0], [0.0, 1.0]])


def pose_rate(theta: Array, v: Array, omega: Array) -> Array:
    """q_dot = S(q) nu = [v cos theta, v sin theta, omega]."""
    return jnp.stack([v * jnp.cos(theta), v * jnp.sin(theta), omega])


def wheel_speeds(params: RobotParams, nu: Array) -> Array:
    """W nu = [phi_dot_R, phi_dot_L] = [(v + L w)/R, (v - L w)/R] [rad/s]."""
    v, omega = nu[0], nu[1]
    return jnp.stack([v + params.half_axle * omega, v - params.half_axle * omega]) / params.wheel_radius


def body_velocity(params: RobotParams, phi_dot: Array) -> Array:
    """Inverse of :func:`wheel_speeds`: nu = R/2 [[1, 1], [1/L, -1/L]] phi_dot."""
    r, half = params.wheel_radius, params.half_axle
    return jnp.stack([r * (phi_dot[0] + phi_dot[1]) / 2.0, r * (phi_dot[0] - phi_dot[1]) / (2.0 * half)])


# --- full Lagrangian model (model.md §1.2; paper eqs. 4-5 corrected), used to check the reduced one ----


def mass_matrix(params: RobotParams, theta: Array) -> Array:
    """M(q) of the Euler-Lagrange equations with signed centre-of-mass offset d."""
    m, d = params.mass, params.com_offset
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.array(
        [
            [m, 0.0, -m * d * s],
            [0.0, m, m * d * c],
            [-m * d * s, m * d * c, params.inertia + m * d**2],
        ]
    )


def coriolis_vector(params: RobotParams, theta: Array, theta_dot: Array) -> Array:
    """V(q, q_dot) = [-m d theta_dot^2 cos, -m d theta_dot^2 sin, 0]."""
    k = -params.mass * params.com_offset * theta_dot**2
    return jnp.stack([k * jnp.cos(theta), k * jnp.sin(theta), jnp.zeros_like(theta)])


def input_matrix(params: RobotParams, theta: Array) -> Array:
    """B(q) = 1/R [[cos, cos], [sin, sin], [L, -L]]: wheel torques to generalised forces."""
    c, s, half = jnp.cos(theta), jnp.sin(theta), params.half_axle
    return jnp.array([[c, c], [s, s], [half, -half]]) / params.wheel_radius


# --- reduced dynamics in nu = (v, omega) (model.md §1.3; paper eqs. 6-7) -----------------------------


def reduced_mass(params: RobotParams) -> Array:
    """M_bar = diag(m + 2 J_w / R^2, I_A + 2 J_w L^2 / R^2) (model.md §1.6); S^T M S = diag(m, I_A) for J_w = 0."""
    return jnp.diag(
        jnp.stack([jnp.asarray(params.effective_mass, float), jnp.asarray(params.effective_inertia_axle, float)])
    )


def reduced_coriolis(params: RobotParams, nu: Array) -> Array:
    """V_bar(nu) nu = [-m d omega^2, m d omega v] (skew-symmetric V_bar: no power)."""
    md = params.mass * params.com_offset
    return jnp.stack([-md * nu[1] ** 2, md * nu[1] * nu[0]])


def reduced_input(params: RobotParams) -> Array:
    """B_bar = S^T B = 1/R [[1, 1], [L, -L]]."""
    half = params.half_axle
    return jnp.array([[1.0, 1.0], [half, -half]]) / params.wheel_radius


def reduced_input_inverse(params: RobotParams) -> Array:
    """B_bar^{-1} = R/2 [[1, 1/L], [1, -1/L]]."""
    inv_half = 1.0 / params.half_axle
    return params.wheel_radius / 2.0 * jnp.array([[1.0, inv_half], [1.0, -inv_half]])


def wheel_friction(params: RobotParams, phi_dot: Array) -> Array:
    """tau_f = b_w phi_dot + tau_c tanh(phi_dot / eps_f), per wheel, opposing the drive (model.md §1.2)."""
    return params.viscous_friction * phi_dot + params.coulomb_friction * jnp.tanh(phi_dot / params.friction_smoothing)


def body_acceleration(params: RobotParams, nu: Array, tau: Array, tau_dist: Array) -> Array:
    """nu_dot from M_bar nu_dot + V_bar nu + F_bar + tau_bar_d = B_bar tau (model.md §1.3, scalar form).

    ``tau_dist`` are wheel disturbance torques that oppose the drive when positive [N m]. The wheels' spin
    inertia J_w adds 2 J_w / R^2 to the mass and 2 J_w L^2 / R^2 to the yaw inertia (model.md §1.6).
    """
    net = tau - wheel_friction(params, wheel_speeds(params, nu)) - tau_dist
    drive = reduced_input(params) @ net
    coriolis = reduced_coriolis(params, nu)
    return jnp.stack(
        [(drive[0] - coriolis[0]) / params.effective_mass, (drive[1] - coriolis[1]) / params.effective_inertia_axle]
    )


def energy(params: RobotParams, nu: Array) -> Array:
    """Kinetic energy 1/2 (m v^2 + I_A omega^2) + 1/2 J_w (phi_dot_R^2 + phi_dot_L^2) [J], the wheels' spin
    included (model.md §1.6); conserved with no torque, friction or disturbance."""
    return 0.5 * (params.effective_mass * nu[0] ** 2 + params.effective_inertia_axle * nu[1] ** 2)
