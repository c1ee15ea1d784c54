"""Inner (dynamic) loops: velocity command -> wheel torques (model.md §2.5, 2.6).

Both saturate at the nominal ``max_torque`` and report whether they did.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import jax.numpy as jnp
from jax import Array
from pydantic import Field

from .._pytree import FloatVector, pytree_dataclass
from ..layout import velocity
from ..model import RobotParams, reduced_coriolis, reduced_input_inverse, reduced_mass, wheel_friction, wheel_speeds
from ..parameters import NonNegative, Parameters, Positive, Structure, Timing, declared
from ..trajectories import Reference
from .base import VelocityCommand


class InnerLoopParameters(Parameters):
    """The shared inner loop's parameters (docs/architecture.md): which loop, and its gains."""

    inner: Structure[Literal["computed_torque", "pd", "none"]] = Field(
        "computed_torque",
        description=(
            "Inner (dynamic) loop: computed torque (eq. 11), wheel PD, or none: the outer law's (v_c, omega_c) go "
            "to the robot as its velocity command (cmd_vel)."
        ),
    )
    kc: tuple[Positive, Positive] = Field((10.0, 10.0), description="K_c of eq. 11 (computed torque) [1/s].")
    kp: Positive = Field(0.125, description="Wheel PD proportional gain [N m s/rad].")
    kd: NonNegative = Field(0.0, description="Wheel PD derivative gain [N m s^2/rad].")


class HeldLoop(NamedTuple):
    """An inner loop as the check of its sampling sees it: linearised at zero tracking error, on the nominal model,
    per channel (v, omega), rates in 1/s (model.md §2.7).

    ``kind`` names the loop (``"computed_torque"``, ``"adaptive_computed_torque"``, ``"pd"``, ``"sliding_mode"``)
    and so the gain to advise; ``design`` is its own rate (K_c, or the PD's bandwidth), proportional to ``gain``
    (K_c of the channel, or K_P); ``derivative`` the PD's design K_D / K_P (0 for the others); ``feedforward`` the
    weight of nu_c_dot in the commanded acceleration (1 for computed torque, design K_D / K_P for the PD, the top
    of the estimates' range for the adaptive law); ``feedback`` the outer law's -d nu_c_dot / d nu, the rate at
    which its analytic command rate feeds the measured velocity back; ``layer`` the sliding term's K_s / phi
    inside its boundary layer (0 for the others).
    """

    kind: str
    design: tuple[float, float]
    gain: tuple[float, float]
    derivative: tuple[float, float]
    feedforward: tuple[float, float]
    feedback: tuple[float, float]
    layer: tuple[float, float] = (0.0, 0.0)


def _saturate(tau: Array, limit: Array | float) -> tuple[Array, Array]:
    return jnp.clip(tau, -limit, limit), jnp.any(jnp.abs(tau) > limit).astype(tau.dtype)


@pytree_dataclass
class ComputedTorque:
    """Computed torque on the nominal model (paper eqs. 7, 11; model.md §2.5).

    u = nu_c_dot + K_c (nu_c - nu) [+ strict cross term];
    tau = B_bar^-1 (M_hat u + V_hat(nu) nu) + tau_f_hat(W nu) [N m].
    ``nominal`` is what the controller believes (its friction terms are the friction model, 0 by
    default; its wheel inertia J_w enters M_hat, model.md §1.6); ``kc`` = (k_cv, k_cw) [1/s]. With an exact
    model and no disturbance nu_dot = u (eq. 9).
    """

    nominal: RobotParams
    kc: FloatVector = declared(InnerLoopParameters)

    def init(self, x0: Array, ref0: Reference, key: Array) -> tuple[()]:
        return ()

    def torque(self, y: Array, command: VelocityCommand, memory: tuple[()]) -> tuple[Array, Array, tuple[()]]:
        nu = velocity(y)
        u = command.nu_c_dot + jnp.asarray(self.kc) * (command.nu_c - nu) + command.feedback
        generalised = reduced_mass(self.nominal) @ u + reduced_coriolis(self.nominal, nu)
        tau = reduced_input_inverse(self.nominal) @ generalised + wheel_friction(
            self.nominal, wheel_speeds(self.nominal, nu)
        )
        tau, saturated = _saturate(tau, self.nominal.max_torque)
        return tau, saturated, memory


@pytree_dataclass
class WheelPD:
    """Wheel-space PD, the consistent form of the paper's eq. 21 (model.md §2.6).

    tau = K_P (phi_dot_c - phi_dot) + K_D d/dt (phi_dot_c - phi_dot), phi_dot_c = W nu_c, with
    d/dt phi_dot_c = W nu_c_dot analytic and d/dt phi_dot a backward difference over one control
    period. ``kp`` [N m s/rad], ``kd`` [N m s^2/rad]; kp = 0.125 gives about k_v = 10, k_w = 10.7 1/s
    on the default robot. Memory: the previous measured wheel speeds. Ignores the strict cross term.
    """

    nominal: RobotParams
    kp: float = declared(InnerLoopParameters)
    kd: float = declared(InnerLoopParameters)
    control_period: float = declared(Timing)

    def init(self, x0: Array, ref0: Reference, key: Array) -> Array:
        return wheel_speeds(self.nominal, velocity(jnp.asarray(x0)))

    def torque(self, y: Array, command: VelocityCommand, memory: Array) -> tuple[Array, Array, Array]:
        phi_dot = wheel_speeds(self.nominal, velocity(y))
        error = wheel_speeds(self.nominal, command.nu_c) - phi_dot
        error_rate = wheel_speeds(self.nominal, command.nu_c_dot) - (phi_dot - memory) / self.control_period
        tau, saturated = _saturate(self.kp * error + self.kd * error_rate, self.nominal.max_torque)
        return tau, saturated, phi_dot
