"""Adaptive computed torque: the inner loop of eqs. 7 and 11 with the inertial parameters estimated online.

In the style of Fukao, Nakagawa & Adachi (2000), "Adaptive tracking control of a nonholonomic mobile
robot", IEEE Trans. Robotics and Automation 16(5), 609-615: kinematic backstepping over a torque layer
that estimates the unknown inertial parameters online with a Lyapunov-based update. The torque layer
is Slotine & Li's adaptive robot controller ("Applied Nonlinear Control", 1991, ch. 9) at velocity
level: tau = B_bar^-1 (Y p_hat + K_D e_c), e_c = nu_c - nu, with a regressor Y of the command (nu_c,
nu_c_dot) rather than of the feedback, and p_hat_dot = Gamma Y^T e_c; here with the regressor of our
reduced model (model.md §1.3).

Linear parametrisation. With the centre-of-mass offset d, R and L known, and p = (m, I_C, b_w)::

    M_bar nu_c_dot + V_bar(nu) nu_c + F_bar_visc(nu_c) = Y(nu, nu_c, nu_c_dot) p
    Y = [[v_c_dot - d w w_c,          0,        2 v_c / R^2    ],
         [d^2 w_c_dot + d w v_c,      w_c_dot,  2 L^2 w_c / R^2]]

since M_bar = diag(m, I_C + m d^2), V_bar(nu) = m d [[0, -w], [w, 0]] and F_bar_visc(nu) = D nu,
D = b_w (2 / R^2) diag(1, L^2), for viscous wheel friction (model.md §1.2, 1.3).

Control, with e = nu - nu_c and K_D = M_bar_nominal K_c (the inner bandwidth K_c [1/s] of eq. 11 on the
nominal model)::

    tau = B_bar^-1 (Y p_hat - K_D e [+ f]) + tau_c_hat tanh(W nu / eps_f)     (nominal Coulomb, not adapted)

where f = [e_x, sin(e_th) / Ky] is the strict-backstepping cross term when the outer law hands one.

Update law. The true plant M_bar nu_dot + V_bar(nu) nu + D nu = B_bar tau closes to
M_bar e_dot + V_bar(nu) e + (D + K_D) e = -Y p_tilde [+ f], p_tilde = p - p_hat. For
V = e^T M_bar e / 2 + p_tilde^T Gamma^-1 p_tilde / 2 (M_bar constant and positive definite, V_bar
skew-symmetric so e^T V_bar e = 0)::

    V_dot = -e^T (D + K_D) e - e^T Y p_tilde - p_tilde^T Gamma^-1 p_hat_dot [+ e^T f]

and the choice p_hat_dot = -Gamma Y^T e cancels the cross term: V_dot = -e^T (D + K_D) e <= 0, so e -> 0
and p_hat stays bounded; p_hat -> p when Y is persistently exciting. (With f, e^T f cancels the
cross term of the kinematic Lyapunov function, eq. 13 and model.md §2.4, as in Fukao et al.) The
regressor holds no feedback term, so a velocity error cannot drift the estimates by itself.
Integrated once per control period (explicit Euler) and projected onto the box [p_min, p_max]: for
diagonal Gamma, clipping is the projection, which keeps V_dot <= 0 when p lies in the box (parameter
projection, Ioannou & Sun, "Robust Adaptive Control", 1996)::

    p_hat(k+1) = clip(p_hat(k) - T_c Gamma Y_k^T (nu_k - nu_c,k), p_min, p_max)

The update pauses in a period where the torque limit acts: the applied torque is then not the law's,
and the error equation behind the update does not hold.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array
from pydantic import Field

from ..._pytree import FloatVector, pytree_dataclass
from ...layout import velocity
from ...model import RobotParams, reduced_input_inverse, reduced_mass, wheel_speeds
from ...parameters import NonNegative, Parameters, Positive, Timing, declared
from ...trajectories import Reference
from ..base import Logs, VelocityCommand

PARAMETERS = ("mass", "inertia", "viscous_friction")  #: the order of p = (m [kg], I_C [kg m^2], b_w [N m s/rad])


def regressor(nominal: RobotParams, nu: Array, nu_c: Array, nu_c_dot: Array) -> Array:
    """Y, 2x3, with M_bar nu_c_dot + V_bar(nu) nu_c + F_bar_visc(nu_c) = Y [m, I_C, b_w] (d, R, L from ``nominal``)."""
    d, r, half = nominal.com_offset, nominal.wheel_radius, nominal.half_axle
    w = nu[1]
    zero = jnp.zeros_like(w)
    return jnp.array(
        [
            [nu_c_dot[0] - d * w * nu_c[1], zero, 2.0 * nu_c[0] / r**2],
            [d**2 * nu_c_dot[1] + d * w * nu_c[0], nu_c_dot[1], 2.0 * half**2 * nu_c[1] / r**2],
        ]
    )


def nominal_parameters(nominal: RobotParams) -> Array:
    """p of the nominal model: [m, I_C, b_w]."""
    return jnp.stack([jnp.asarray(getattr(nominal, name), float) for name in PARAMETERS])


class AdaptiveBacksteppingParameters(Parameters):
    """The adaptive computed-torque loop's parameters (Fukao et al. 2000)."""

    kc: tuple[Positive, Positive] = Field(
        (10.0, 10.0),
        description=("K_c of eq. 11: the inner loop's bandwidth on the nominal model, K_D = M_bar K_c [1/s]."),
    )
    adaptation_gain: tuple[NonNegative, NonNegative, NonNegative] = Field(
        (500.0, 5.0, 1e-4),
        description=(
            "Gamma of the estimates of (m [kg s^2/m^2], I_C [kg m^2 s^2], viscous friction b_w [kg m^2]); "
            "0 freezes that estimate at the [robot] value."
        ),
    )
    estimate_range: tuple[Positive, Positive] = Field(
        (0.5, 2.0), description=("Projection bounds of the m and I_C estimates, as multiples of the [robot] values.")
    )
    max_friction: NonNegative = Field(
        0.05,
        description=(
            "Upper projection bound of the b_w estimate (the lower is 0), at least the [robot] value [N m s/rad]."
        ),
    )
    strict: bool = Field(False, description="Add the strict-backstepping cross term to the torque law.")


@pytree_dataclass
class AdaptiveComputedTorque:
    """Computed torque on online estimates of (m, I_C, b_w) (module docstring; Fukao et al. 2000).

    In: measured state y, the outer law's command (nu_c [m/s, rad/s], nu_c_dot, strict term). Out:
    wheel torques [N m] saturated at the nominal ``max_torque``. ``kc`` = (k_cv, k_cw) [1/s];
    ``gamma`` = diag(Gamma) for (m, I_C, b_w) [kg s^2/m^2, kg m^2 s^2, kg m^2] (0 freezes that
    estimate); ``lower``, ``upper`` the projection box; ``control_period`` T_c [s]. Memory: p_hat,
    starting at the nominal values. Logs: ``m_hat`` [kg], ``inertia_hat`` (I_C) [kg m^2],
    ``friction_hat`` (b_w) [N m s/rad]: the estimate this period's torque used.
    """

    nominal: RobotParams
    kc: FloatVector = declared(AdaptiveBacksteppingParameters)
    gamma: FloatVector = declared(AdaptiveBacksteppingParameters, "adaptation_gain")
    lower: FloatVector = (5.0, 0.28, 0.0)
    upper: FloatVector = (20.0, 1.12, 0.05)
    control_period: float = declared(Timing)

    def init(self, x0: Array, ref0: Reference, key: Array) -> Array:
        return jnp.clip(nominal_parameters(self.nominal), jnp.asarray(self.lower), jnp.asarray(self.upper))

    def torque(self, y: Array, command: VelocityCommand, memory: Array) -> tuple[Array, Array, Array]:
        nu = velocity(y)
        error = nu - command.nu_c
        y_matrix = regressor(self.nominal, nu, command.nu_c, command.nu_c_dot)
        damping = reduced_mass(self.nominal) @ (jnp.asarray(self.kc) * error)
        coulomb = self.nominal.coulomb_friction * jnp.tanh(
            wheel_speeds(self.nominal, nu) / self.nominal.friction_smoothing
        )
        tau = reduced_input_inverse(self.nominal) @ (y_matrix @ memory - damping + command.feedback) + coulomb
        limit = self.nominal.max_torque
        saturated = jnp.any(jnp.abs(tau) > limit).astype(tau.dtype)
        updated = jnp.clip(
            memory - self.control_period * jnp.asarray(self.gamma) * (y_matrix.T @ error),
            jnp.asarray(self.lower),
            jnp.asarray(self.upper),
        )
        # a saturated torque is not the law's: the error equation behind the update does not hold
        memory = jnp.where(saturated > 0.0, memory, updated)
        return jnp.clip(tau, -limit, limit), saturated, memory

    def logs(self, memory: Array) -> Logs:
        return {"m_hat": memory[0], "inertia_hat": memory[1], "friction_hat": memory[2]}
