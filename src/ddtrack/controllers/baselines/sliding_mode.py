"""Sliding-mode dynamic layer with a boundary layer: computed torque plus a saturated switching term.

Backstepping over a sliding-mode velocity loop, in the manner of Slotine and Li, *Applied Nonlinear
Control* (1991), sec. 7.1-7.2 (the switching law and its boundary layer), applied to the reduced
dynamics M_bar nu_dot + V_bar(nu) nu + F_bar + tau_bar_d = B_bar tau of model.md §1.3 as in Fierro and
Lewis, "Control of a nonholonomic mobile robot: backstepping kinematics into dynamics" (1997). The
outer law is Kanayama's (paper eq. 12); this module is the inner law::

    s    = nu_c - nu                                     sliding variable (velocity tracking error)
    u    = nu_c_dot + K_c s + K_s sat(s / phi) [+ the outer law's feedback term]
    tau  = B_bar^-1 (M_hat u + V_hat(nu) nu) + tau_f_hat,  saturated at max_torque      (eqs. 7, 11)

i.e. the computed torque of :class:`~ddtrack.controllers.ComputedTorque` plus
B_bar^-1 M_hat K_s sat(s / phi), sat(z) = clip(z, -1, 1) per channel. On the nominal model with a
matched disturbance, s_dot = -K_c s - K_s sat(s / phi) + delta, delta = M_bar^-1 B_bar tau_dw; per channel
|delta_i| <= D_i < K_s,i gives s_i s_i_dot <= -(K_s,i - D_i) |s_i| outside the layer (the sliding
condition, Slotine and Li sec. 7.1): |s_i| reaches phi_i within |s_i(0)| / (K_s,i - D_i) seconds and
stays. Inside the layer the term is linear, K_s s / phi, so there is no discontinuity to chatter on;
the price is a residual |s_i| <= D_i / (K_c,i + K_s,i / phi_i) instead of 0.

The sliding surface is s = nu_c - nu, not s = e + lambda * integral(e): the velocity has relative degree
one (tau appears in s_dot), so s itself is a valid sliding variable, and an integral would need memory
and anti-windup under the torque limit.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array
from pydantic import Field

from ..._pytree import FloatVector, pytree_dataclass
from ...layout import velocity
from ...model import RobotParams
from ...parameters import NonNegative, Parameters, Positive, declared
from ...trajectories import Reference
from ..base import VelocityCommand
from ..inner import ComputedTorque


def switching_term(s: Array, gain: FloatVector, boundary_layer: FloatVector) -> Array:
    """K_s sat(s / phi): magnitude K_s outside |s| > phi, linear K_s s / phi inside (Slotine and Li sec. 7.2)."""
    return jnp.asarray(gain, float) * jnp.clip(s / jnp.asarray(boundary_layer, float), -1.0, 1.0)


class SlidingModeParameters(Parameters):
    """The sliding-mode inner loop's parameters (Slotine and Li 7.1-7.2)."""

    kc: tuple[Positive, Positive] = Field((10.0, 10.0), description="K_c of eq. 11, the linear part [1/s].")
    switching_gain: tuple[NonNegative, NonNegative] = Field(
        (1.0, 2.0),
        description=(
            "K_s (v [m/s^2], omega [rad/s^2]): must exceed the matched disturbance as an acceleration; 0 gives "
            "computed torque."
        ),
    )
    boundary_layer: tuple[Positive, Positive] = Field(
        (0.02, 0.04),
        description=(
            "phi, half-width of the boundary layer (v [m/s], omega [rad/s]): wider chatters less, tracks looser."
        ),
    )


@pytree_dataclass
class SlidingModeTorque:
    """Sliding-mode inner law: velocity command -> wheel torques [N m] (a TorqueLaw; module docstring).

    ``nominal``: what the controller believes; ``kc`` = K_c [1/s]; ``switching_gain`` = K_s
    (m/s^2, rad/s^2), the bound on the matched disturbance it rejects, as an acceleration;
    ``boundary_layer`` = phi (m/s, rad/s). K_s = 0 gives the computed-torque loop exactly. Stateless.
    """

    nominal: RobotParams
    kc: FloatVector = declared(SlidingModeParameters)
    switching_gain: FloatVector = declared(SlidingModeParameters)
    boundary_layer: FloatVector = declared(SlidingModeParameters)

    def init(self, x0: Array, ref0: Reference, key: Array) -> tuple[()]:
        return ()

    def torque(self, y: Array, command: VelocityCommand, memory: tuple[()]) -> tuple[Array, Array, tuple[()]]:
        switching = switching_term(command.nu_c - velocity(y), self.switching_gain, self.boundary_layer)
        # the switching term enters u of eq. 11 additively, so the nominal model, friction and limit are shared
        boosted = command._replace(feedback=command.feedback + switching)
        return ComputedTorque(self.nominal, kc=self.kc).torque(y, boosted, memory)
