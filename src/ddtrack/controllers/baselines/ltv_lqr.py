"""LTV/LQR unicycle tracker: an LQR on the posture error, linearised about the reference speed.

The law of WPILib's ``LTVUnicycleController`` (T. Veness, *Controls Engineering in FRC*, sec. 8.9,
theorem 8.9.1), here solved on line for the current v_r instead of read from a table. One control
period::

    e      = posture_error(y, ref)                                 model.md §2.2, robot frame
    v_l    = v_r, or min_velocity where |v_r| < min_velocity       keeps e_y controllable
    A, B   = [[0,0,0],[0,0,v_l],[0,0,0]], [[1,0],[0,0],[0,1]]       Kanayama error dynamics (model.md §2.3)
                                                                   linearised at e = 0, omega_r terms dropped
    A_d, B_d = I + A T_c, (T_c I + A T_c^2 / 2) B                  exact zero-order hold (A^2 = 0)
    P      = DARE(A_d, B_d, Q, R), Q = diag(1/q_tol^2), R = diag(1/r_tol^2)    Bryson's rule
    K      = (R + B_d' P B_d)^-1 B_d' P A_d
    nu_c   = clamp((v_r, omega_r) + K e)
    nu_c_dot = (v_r_dot, omega_r_dot) + K e_dot, e_dot of model.md §2.3 with the measured nu, K held

The DARE is solved by a fixed number of structure-preserving doubling steps (SDA; Chu, Fan, Lin and
Wang, "Structure-preserving algorithms for periodic discrete-time algebraic Riccati equations",
Int. J. Control 77(8), 2004), so it is a pure function that jit and vmap accept. The error of the
doubling falls like rho^(2^k), rho the closed-loop spectral radius: 20 steps reach the fixed point
(relative 1e-13) at v_l = 1e-4 m/s and T_c = 10 ms, the slowest case; each tenfold shorter T_c or
smaller ``min_velocity`` costs about 3.3 more.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
from jax import Array
from pydantic import Field

from ..._pytree import FloatVector, pytree_dataclass
from ...geometry import error_rates, posture_error
from ...layout import pose, velocity
from ...parameters import Parameters, Positive, PositiveTriple, Structure, Timing, declared
from ...trajectories import Reference
from ..backstepping import VelocityClamps, clamp_command
from ..base import Logs, VelocityCommand, commanded


def unicycle_error_model(v: Array, control_period: float) -> tuple[Array, Array]:
    """(A_d, B_d) of the posture error linearised at speed ``v`` [m/s], zero-order hold over ``control_period`` [s].

    State (e_x, e_y, e_theta), input the velocity correction (dv, domega) in WPILib's sign convention
    (the state is the pose offset, the law is u = K e). A = [[0,0,0],[0,0,v],[0,0,0]] is nilpotent, so
    exp(A T) = I + A T and the integral of exp(A s) B over [0, T] is (T I + A T^2/2) B exactly.
    """
    zero = jnp.zeros_like(v)
    a = jnp.array([[zero, zero, zero], [zero, zero, v], [zero, zero, zero]])
    b = jnp.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    t = control_period
    return jnp.eye(3) + a * t, (t * jnp.eye(3) + a * (t * t / 2.0)) @ b


def solve_dare(a: Array, b: Array, q: Array, r: Array, iterations: int) -> Array:
    """P solving P = A'PA - A'PB (R + B'PB)^-1 B'PA + Q, by ``iterations`` doubling steps (SDA).

    A_0 = A, G_0 = B R^-1 B', H_0 = Q; with W = I + G_k H_k:
    A_{k+1} = A_k W^-1 A_k,  G_{k+1} = G_k + A_k W^-1 G_k A_k',  H_{k+1} = H_k + A_k' H_k W^-1 A_k;
    H_k -> P quadratically for a stabilisable, detectable pair.
    """

    def double(_, carry):
        a_k, g_k, h_k = carry
        w = jnp.eye(a.shape[0]) + g_k @ h_k
        w_inv_a = jnp.linalg.solve(w, a_k)
        w_inv_g = jnp.linalg.solve(w, g_k)
        return a_k @ w_inv_a, g_k + a_k @ w_inv_g @ a_k.T, h_k + a_k.T @ h_k @ w_inv_a

    _, _, p = jax.lax.fori_loop(0, iterations, double, (a, b @ jnp.linalg.solve(r, b.T), q))
    return 0.5 * (p + p.T)  # symmetric to rounding


def lqr_gain(a: Array, b: Array, q: Array, r: Array, iterations: int) -> Array:
    """K = (R + B'PB)^-1 B'PA of the discrete LQR u = -K x (here u = K e, e = -x)."""
    p = solve_dare(a, b, q, r, iterations)
    return jnp.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)


class LTVLQRParameters(Parameters):
    """The LTV/LQR law's parameters (WPILib's LTVUnicycleController's tolerances)."""

    q_tolerance: PositiveTriple = Field(
        (0.0625, 0.125, 2.0),
        description=(
            "Tolerated (e_x [m], e_y [m], e_theta [rad]); Q = diag(1/q^2) (Bryson's rule, WPILib's defaults)."
        ),
    )
    r_tolerance: tuple[Positive, Positive] = Field(
        (1.0, 2.0), description=("Tolerated velocity correction (v [m/s], omega [rad/s]); R = diag(1/r^2).")
    )
    min_velocity: Positive = Field(
        1e-4, description=("|v_r| below this is linearised at this speed, where e_y stays controllable [m/s].")
    )
    dare_iterations: Structure[int] = Field(
        32,
        ge=1,
        le=64,
        description=("Doubling steps of the Riccati solver; 20 converge at min_velocity 1e-4 m/s and T_c 10 ms."),
    )


@pytree_dataclass
class LTVUnicycleLQR:
    """LTV/LQR unicycle tracker (WPILib ``LTVUnicycleController``; Veness, sec. 8.9). A velocity law.

    In: measured state y = [x, y, theta, v, omega] and the reference. Out: nu_c = (v_r, omega_r) + K(v_r) e
    (v_c [m/s], omega_c [rad/s]) clamped to ``max_velocity`` and ``max_yaw_rate``, with its rate.
    ``q_tolerance`` = tolerated (e_x [m], e_y [m], e_theta [rad]), ``r_tolerance`` = tolerated correction
    (v [m/s], omega [rad/s]): Q = diag(1/q_tol^2), R = diag(1/r_tol^2) (Bryson's rule). Below
    ``min_velocity`` [m/s] the model is linearised at ``min_velocity`` (WPILib: 1e-4), where (A, B)
    would lose e_y. nu_c_dot holds K over the period, as model.md §2.5 does for gains: a finite difference
    would be late by a period and spike at corners. Stateless.
    """

    q_tolerance: FloatVector = declared(LTVLQRParameters)
    r_tolerance: FloatVector = declared(LTVLQRParameters)
    control_period: float = declared(Timing)
    min_velocity: float = declared(LTVLQRParameters)
    max_velocity: float = declared(VelocityClamps)
    max_yaw_rate: float = declared(VelocityClamps)
    dare_iterations: int = declared(LTVLQRParameters)
    output_kind: ClassVar[str] = "velocity"  #: as a whole controller (``step``): what it hands the plant

    def gain(self, v_r: Array) -> Array:
        """K(v_r), (2, 3): rows (dv, domega) per unit (e_x, e_y, e_theta)."""
        v = jnp.where(jnp.abs(v_r) < self.min_velocity, self.min_velocity, v_r)
        a, b = unicycle_error_model(jnp.asarray(v, float), self.control_period)
        q = jnp.diag(1.0 / jnp.asarray(self.q_tolerance, float) ** 2)
        r = jnp.diag(1.0 / jnp.asarray(self.r_tolerance, float) ** 2)
        return lqr_gain(a, b, q, r, self.dare_iterations)

    def init(self, x0: Array, ref0: Reference, key: Array) -> tuple[()]:
        return ()

    def command(self, t: Array, y: Array, ref: Reference, memory: tuple[()]) -> tuple[VelocityCommand, tuple[()], Logs]:
        error = posture_error(*pose(y), ref.x, ref.y, ref.theta)
        k = self.gain(ref.v)
        nu_c = jnp.stack([ref.v, ref.omega]) + k @ error
        nu = velocity(y)
        nu_c_dot = jnp.stack([ref.v_dot, ref.omega_dot]) + k @ error_rates(error, nu[0], nu[1], ref.v, ref.omega)
        limits = jnp.stack([jnp.asarray(self.max_velocity, float), jnp.asarray(self.max_yaw_rate, float)])
        nu_c, nu_c_dot, saturated = clamp_command(nu_c, nu_c_dot, limits)
        return VelocityCommand(nu_c, nu_c_dot, jnp.zeros(2), saturated), memory, {}

    def observe(self, memory: tuple[()], saturated: Array) -> tuple[()]:
        return memory

    def step(self, t: Array, y: Array, ref: Reference, memory: tuple[()]) -> tuple[Array, tuple[()], Logs]:
        """As a whole controller of a kinematic plant: the clamped command."""
        command, memory, _ = self.command(t, y, ref, memory)
        return (
            command.nu_c,
            memory,
            {**commanded(command.nu_c), "saturated": command.saturated},
        )
