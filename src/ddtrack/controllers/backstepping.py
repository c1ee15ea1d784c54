"""Kanayama backstepping: the kinematic law (paper eq. 12), its analytic derivative (model.md §2.5) and
the Lyapunov function (eq. 13)."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jax import Array
from pydantic import Field

from .._pytree import pytree_dataclass
from ..geometry import error_rates, posture_error
from ..layout import POSTURE_ERROR, pose, velocity
from ..parameters import Parameters, Positive, declared
from ..trajectories import Reference
from .base import Logs, VelocityCommand, commanded


def kanayama_command(error: Array, ref: Reference, gains: Array) -> Array:
    """nu_c = [v_r cos e_th + Kx e_x, omega_r + v_r (Ky e_y + Kth sin e_th)] (paper eq. 12, model.md §2.4).

    ``error`` = [e_x, e_y, e_theta] (model.md §2.2); ``gains`` = [Kx, Ky, Ktheta] > 0.
    """
    e_x, e_y, e_th = (POSTURE_ERROR.read(error, name) for name in POSTURE_ERROR.names)
    kx, ky, kth = gains[0], gains[1], gains[2]
    return jnp.stack([ref.v * jnp.cos(e_th) + kx * e_x, ref.omega + ref.v * (ky * e_y + kth * jnp.sin(e_th))])


def kanayama_command_rate(error: Array, nu: Array, ref: Reference, gains: Array) -> Array:
    """Analytic d nu_c / dt with the gains held and the measured nu in the error dynamics (model.md §2.5)."""
    e_y, e_th = POSTURE_ERROR.read(error, "e_y"), POSTURE_ERROR.read(error, "e_theta")
    kx, ky, kth = gains[0], gains[1], gains[2]
    de_x, de_y, de_th = error_rates(error, nu[0], nu[1], ref.v, ref.omega)
    v_dot = ref.v_dot * jnp.cos(e_th) - ref.v * jnp.sin(e_th) * de_th + kx * de_x
    omega_dot = (
        ref.omega_dot + ref.v_dot * (ky * e_y + kth * jnp.sin(e_th)) + ref.v * (ky * de_y + kth * jnp.cos(e_th) * de_th)
    )
    return jnp.stack([v_dot, omega_dot])


def lyapunov(error: Array, ky: Array) -> Array:
    """V_L = (e_x^2 + e_y^2)/2 + (1 - cos e_th)/Ky (paper eq. 13)."""
    return 0.5 * (error[0] ** 2 + error[1] ** 2) + (1.0 - jnp.cos(error[2])) / ky


def clamp_command(nu_c: Array, nu_c_dot: Array, limits: Array) -> tuple[Array, Array, Array]:
    """Clamp |v_c| <= limits[0], |omega_c| <= limits[1]; a clamped channel's derivative becomes 0 (model.md §2.5).

    Returns the clamped command, its derivative and 1.0 if any channel was clamped (else 0.0).
    """
    clamped = jnp.abs(nu_c) > limits
    return (jnp.clip(nu_c, -limits, limits), jnp.where(clamped, 0.0, nu_c_dot), jnp.any(clamped).astype(nu_c.dtype))


def velocity_command(
    error: Array, nu: Array, ref: Reference, gains: Array, limits: Array, strict: Array | bool
) -> VelocityCommand:
    """The Kanayama command for ``gains``, its analytic rate, the clamps, and (``strict``) the cross term
    [e_x, sin(e_th)/Ky] for the inner loop: what every Kanayama-based outer law hands the inner loop."""
    nu_c, nu_c_dot, saturated = clamp_command(
        kanayama_command(error, ref, gains), kanayama_command_rate(error, nu, ref, gains), limits
    )
    feedback = jnp.where(strict, jnp.stack([error[0], jnp.sin(error[2]) / gains[1]]), 0.0)  # a select: a number
    return VelocityCommand(nu_c, nu_c_dot, feedback, saturated)


#: Kanayama's gains (Kx [1/s], Ky [1/m^2], Ktheta [1/m]) of the paper's experiments, the default of every law with them
KANAYAMA_GAINS = (1.0, 55.0, 15.0)
#: the default clamps on the velocity command, |v_c| [m/s] and |omega_c| [rad/s]
MAX_VELOCITY, MAX_YAW_RATE = 2.0, 4.0


class KanayamaGains(Parameters):
    """Kanayama's gains (paper eq. 12)."""

    gains: tuple[Positive, Positive, Positive] = Field(
        KANAYAMA_GAINS, description="[Kx [1/s], Ky [1/m^2], Ktheta [1/m]] of Kanayama's law (paper eq. 12)."
    )


class VelocityClamps(Parameters):
    """The clamps on the velocity command (v_c, omega_c)."""

    max_velocity: Positive = Field(MAX_VELOCITY, description="Clamp on |v_c| [m/s].")
    max_yaw_rate: Positive = Field(MAX_YAW_RATE, description="Clamp on |omega_c| [rad/s].")


class StrictTerm(Parameters):
    """Whether the inner loop adds the strict-backstepping cross term (model.md §2.4, not in the paper)."""

    strict: bool = Field(False, description="Add the strict-backstepping cross term (computed torque only).")


@pytree_dataclass
class Backstepping:
    """Kanayama backstepping velocity law (paper eq. 12; model.md §2.4, 2.5).

    In: measured state y = [x, y, theta, v, omega] and the reference. Out: nu_c = (v_c [m/s],
    omega_c [rad/s]) clamped to ``max_velocity`` and ``max_yaw_rate``, with its analytic derivative.
    As a whole controller (``step``) it drives a kinematic plant; over a dynamic plant compose it
    with an inner loop in a :class:`~ddtrack.controllers.Cascade`. ``strict`` adds the cross term
    [e_x, sin(e_th)/Ky] to the inner loop's u (model.md §2.4, not in the paper). Logs the gains.
    """

    kx: Array | float = KANAYAMA_GAINS[0]
    ky: Array | float = KANAYAMA_GAINS[1]
    ktheta: Array | float = KANAYAMA_GAINS[2]
    max_velocity: Array | float = declared(VelocityClamps)
    max_yaw_rate: Array | float = declared(VelocityClamps)
    strict: Array | bool = declared(StrictTerm)
    output_kind: ClassVar[str] = "velocity"  #: as a whole controller (``step``): what it hands the plant

    @property
    def gains(self) -> Array:
        return jnp.stack([jnp.asarray(self.kx, float), jnp.asarray(self.ky, float), jnp.asarray(self.ktheta, float)])

    def init(self, x0: Array, ref0: Reference, key: Array) -> tuple[()]:
        return ()

    def command(self, t: Array, y: Array, ref: Reference, memory: tuple[()]) -> tuple[VelocityCommand, tuple[()], Logs]:
        gains = self.gains
        error = posture_error(*pose(y), ref.x, ref.y, ref.theta)
        limits = jnp.stack([jnp.asarray(self.max_velocity, float), jnp.asarray(self.max_yaw_rate, float)])
        command = velocity_command(error, velocity(y), ref, gains, limits, self.strict)
        return command, memory, {"kx": gains[0], "ky": gains[1], "ktheta": gains[2]}

    def observe(self, memory: tuple[()], saturated: Array) -> tuple[()]:
        return memory

    def step(self, t: Array, y: Array, ref: Reference, memory: tuple[()]) -> tuple[Array, tuple[()], Logs]:
        command, memory, logs = self.command(t, y, ref, memory)
        return (
            command.nu_c,
            memory,
            {**commanded(command.nu_c), "saturated": command.saturated, **logs},
        )
