"""Martins et al.'s adaptive dynamic compensator: Kanayama's kinematic law outside, the inverse of the identified
velocity-lag model inside, its six parameters adapted online (model.md §2.8).

F. N. Martins, W. C. Celeste, R. Carelli, M. Sarcinelli-Filho, T. F. Bastos-Filho, "An adaptive dynamic controller
for autonomous mobile robot trajectory tracking", Control Engineering Practice 16:1354-1363, 2008. A base that takes
velocity commands nu* = (v*, omega*) follows them with the lag of model.md §1.8, which is linear in theta::

    v*     = theta_1 v_dot - theta_3 omega^2 + theta_4 v
    omega* = theta_2 omega_dot + theta_5 v omega + theta_6 omega          i.e. nu* = G(nu_dot, nu) theta

with the regressor G(a, nu) = [[a_1, 0, -omega^2, v, 0, 0], [0, a_2, 0, 0, v omega, omega]]. The compensator asks
for the acceleration sigma = nu_c_dot + K (nu_c - nu) and commands nu* = G(sigma, nu) theta_hat: with theta_hat =
theta the base's acceleration is sigma exactly, so the velocity error e = nu_c - nu obeys e_dot = -K e.

Adaptation. With theta_tilde = theta_hat - theta and H = diag(theta_1, theta_2) > 0 the closed loop is
H (e_dot + K e) = -G(sigma, nu) theta_tilde. For V = e^T H e / 2 + theta_tilde^T Gamma^-1 theta_tilde / 2::

    V_dot = -e^T H K e - e^T G theta_tilde + theta_tilde^T Gamma^-1 theta_hat_dot

and theta_hat_dot = Gamma G^T e cancels the cross term: V_dot = -e^T H K e <= 0. Without persistent excitation the
estimates may drift under noise or unmodelled dynamics, so a leakage lambda pulls them back toward the prior theta_0
(sigma-modification, Ioannou and Sun 1996, 8.5; Martins et al. leak toward zero, theta_0 = 0 here)::

    theta_hat_dot = Gamma G^T (nu_c - nu) - lambda (theta_hat - theta_0)

which adds -lambda theta_tilde^T Gamma^-1 (theta_tilde + theta - theta_0) to V_dot: e and theta_tilde stay
ultimately bounded, in a set that shrinks with |theta - theta_0|. Integrated once per control period (explicit
Euler), with this period's regressor and error. The command is clamped to the kinematic law's limits, and the update
pauses in a period where a clamp acts: a base that cannot follow the command leaves a velocity error that
adaptation would otherwise integrate without bound (windup), since with nu_c_dot = 0 the update of theta_1 is
gamma_1 k_v e_v^2 >= 0.
"""

from __future__ import annotations

from typing import ClassVar, Literal, NamedTuple

import jax.numpy as jnp
from jax import Array
from pydantic import Field

from ..._pytree import FloatVector, pytree_dataclass
from ...layout import velocity
from ...model.lag import PIONEER_3DX_WITH_LASER
from ...parameters import NonNegative, Parameters, Positive, Structure, Timing, declared
from ...trajectories import Reference
from ..backstepping import Backstepping
from ..base import Logs, commanded

#: the log names of theta_hat_1..theta_hat_6 [s, s, s m/rad^2, 1, s/m, 1]
THETA_LOGS = tuple(f"theta{i}_hat" for i in range(1, 7))


def lag_regressor(acceleration: Array, nu: Array) -> Array:
    """G(a, nu), 2x6, with G(nu_dot, nu) theta = nu* for the lag model (model.md §1.8; Martins et al. 2008)."""
    v, omega = nu[0], nu[1]
    zero = jnp.zeros_like(v)
    return jnp.array(
        [
            [acceleration[0], zero, -(omega**2), v, zero, zero],
            [zero, acceleration[1], zero, zero, v * omega, omega],
        ]
    )


def compensator_command(theta_hat: Array, sigma: Array, nu: Array) -> Array:
    """nu* = G(sigma, nu) theta_hat [m/s, rad/s]: the command under which the model with theta_hat accelerates at
    ``sigma`` [m/s^2, rad/s^2] from the velocity ``nu`` (the model's exact inverse)."""
    return lag_regressor(sigma, nu) @ theta_hat


def theta_rate(
    theta_hat: Array, regressor: Array, velocity_error: Array, gamma: Array, leakage: Array, theta0: Array
) -> Array:
    """theta_hat_dot = Gamma G^T (nu_c - nu) - lambda (theta_hat - theta_0) (module docstring), per second."""
    return gamma * (regressor.T @ velocity_error) - leakage * (theta_hat - theta0)


class CompensatorMemory(NamedTuple):
    """What the compensator carries from one period to the next."""

    theta_hat: Array  #: the estimate (6,) this period's command uses
    previous_command: Array  #: nu_c of the previous period, for the finite-difference rate (2,)


class CompensatorParameters(Parameters):
    """Martins et al.'s adaptive compensator's parameters (model.md §2.8)."""

    compensator_gain: tuple[Positive, Positive] = Field(
        (4.0, 4.0),
        description=(
            "K (k_v, k_omega): the velocity error nu_c - nu decays at this rate on an exactly known base [1/s]."
        ),
    )
    adaptation_rate: tuple[NonNegative, NonNegative, NonNegative, NonNegative, NonNegative, NonNegative] = Field(
        (0.05, 0.05, 0.0, 0.05, 0.0, 0.05),
        description=(
            "Gamma, one rate per theta_1..theta_6 (0 freezes that estimate at theta0); the coupling terms "
            "theta_3, theta_5 are frozen by default."
        ),
    )
    leakage: NonNegative = Field(
        0.01, description="lambda: the estimates leak back toward theta0 at this rate (sigma-modification) [1/s]."
    )
    theta0: tuple[Positive, Positive, float, float, float, float] = Field(
        PIONEER_3DX_WITH_LASER,
        description=(
            "The prior and initial estimate of theta_1..theta_6 [s, s, s m/rad^2, 1, s/m, 1]; the default is the "
            "Pioneer 3-DX's identified set (with laser)."
        ),
    )
    command_rate: Structure[Literal["analytic", "difference"]] = Field(
        "analytic",
        description=(
            "nu_c_dot from the kinematic law's analytic derivative, or as (nu_c - previous nu_c) / T_c from memory."
        ),
    )


@pytree_dataclass
class AdaptiveDynamicCompensator:
    """Kanayama's law over Martins et al.'s adaptive inverse of the velocity-lag model (module docstring).

    In: measured state y = [x, y, theta, v, omega] and the reference. Out: the velocity command nu* = (v* [m/s],
    omega* [rad/s]) for a velocity-commanded base. ``outer`` is the kinematic law; its clamps bound nu_c and nu*,
    and the estimates hold still in a period where either clamp acts (set them to the base's limits).
    ``compensator_gain`` = K (k_v, k_omega) [1/s]; ``adaptation_rate`` = diag(Gamma), one per theta_i (0 freezes
    it); ``leakage`` = lambda [1/s]; ``theta0`` the prior and initial estimate; ``command_rate`` how nu_c_dot is
    had: ``"analytic"`` (the kinematic law's own derivative, model.md §2.5) or ``"difference"`` ((nu_c,k -
    nu_c,k-1) / T_c from memory: late by half a period, and it amplifies pose noise, which then drifts theta_hat).

    Memory: :class:`CompensatorMemory`. Logs: ``v_cmd``, ``omega_cmd`` (nu_c), ``v_star``, ``omega_star`` (nu*,
    what the base is sent), ``saturated`` (a clamp on nu_c or nu* acted), the gains, ``theta1_hat`` ..
    ``theta6_hat`` (the estimate this period's command used), ``v_error``, ``omega_error`` (nu_c - nu) and
    ``v_accel_cmd``, ``omega_accel_cmd`` (sigma [m/s^2, rad/s^2]).
    """

    outer: Backstepping
    compensator_gain: FloatVector = declared(CompensatorParameters)
    adaptation_rate: FloatVector = declared(CompensatorParameters)
    leakage: Array | float = declared(CompensatorParameters)
    theta0: FloatVector = declared(CompensatorParameters)
    control_period: float = declared(Timing)
    command_rate: str = declared(CompensatorParameters)
    output_kind: ClassVar[str] = "velocity"  #: what it hands the plant

    def init(self, x0: Array, ref0: Reference, key: Array) -> CompensatorMemory:
        command, _, _ = self.outer.command(jnp.zeros(()), x0, ref0, ())
        return CompensatorMemory(jnp.asarray(self.theta0, float), command.nu_c)

    def step(
        self, t: Array, y: Array, ref: Reference, memory: CompensatorMemory
    ) -> tuple[Array, CompensatorMemory, Logs]:
        command, _, outer_logs = self.outer.command(t, y, ref, ())
        nu = velocity(y)
        if self.command_rate == "difference":
            nu_c_dot = (command.nu_c - memory.previous_command) / self.control_period
        else:
            nu_c_dot = command.nu_c_dot
        error = command.nu_c - nu
        sigma = nu_c_dot + jnp.asarray(self.compensator_gain, float) * error
        regressor = lag_regressor(sigma, nu)
        limits = jnp.stack([jnp.asarray(self.outer.max_velocity, float), jnp.asarray(self.outer.max_yaw_rate, float)])
        wanted = regressor @ memory.theta_hat
        nu_star = jnp.clip(wanted, -limits, limits)
        saturated = jnp.maximum(command.saturated, jnp.any(nu_star != wanted).astype(float))
        rate = theta_rate(
            memory.theta_hat,
            regressor,
            error,
            jnp.asarray(self.adaptation_rate, float),
            jnp.asarray(self.leakage, float),
            jnp.asarray(self.theta0, float),
        )
        # a clamped command is not the law's: the error equation behind the update does not hold (no windup)
        theta_next = jnp.where(saturated > 0.0, memory.theta_hat, memory.theta_hat + self.control_period * rate)
        updated = CompensatorMemory(theta_next, command.nu_c)
        logs = {
            **commanded(command.nu_c),
            "saturated": saturated,
            **outer_logs,
            **{name: memory.theta_hat[i] for i, name in enumerate(THETA_LOGS)},
            "v_star": nu_star[0],
            "omega_star": nu_star[1],
            "v_error": error[0],
            "omega_error": error[1],
            "v_accel_cmd": sigma[0],
            "omega_accel_cmd": sigma[1],
        }
        return nu_star, updated, logs
