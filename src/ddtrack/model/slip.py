"""The robot on a floor of finite grip: wheels that can slip (model.md §1.10).

The no-slip constraint of model.md §1.1 is replaced by contact forces. The body moves in the plane with three
velocities at the axle midpoint A, in the body frame: forward speed u, lateral speed w and yaw rate r; each wheel
spins at its own speed phi_dot_i. Each wheel's contact point slides over the floor at

    s_R = (u + L r - R phi_dot_R, w),        s_L = (u - L r - R phi_dot_L, w)

and the floor pushes back along a regularised Coulomb friction circle, F_i = -mu N_i s_i / sqrt(|s_i|^2 + eps_s^2),
with the static normal load N_i = m g (1 - d / l_c) / 2 of a frictionless caster at body x = l_c. With the centre
of mass at height h, accelerating and turning move load (the body neither pitches nor rolls; moments about the
axle's contact line and about the body's x axis):

    N_R = m g (1 - d / l_c) / 2 + h F_x / (2 l_c) + h F_y / (2 L),   N_L = ... - h F_y / (2 L)

F_x, F_y the floor's total force (m times the centre of mass's acceleration); as the forces scale with the loads,
the two loads solve a 2 x 2 linear system, and a load that would go negative (a wheel lifting) is held at 0.
Newton-Euler about the centre of mass C = (d, 0) and each wheel's spin give

    m (u_dot - r w - d r^2) = F_Rx + F_Lx
    m (w_dot + d r_dot + r u) = F_Ry + F_Ly
    I_C r_dot = L (F_Rx - F_Lx) - d (F_Ry + F_Ly)
    J_w phi_ddot_i = tau_i - tau_f,i - tau_dw,i - R F_ix

so the wheels need spin inertia (J_w > 0). The contact is stiff: :func:`contact_stiffness` estimates its fastest
rate and :func:`choose_integration` the scheme and sub-steps from it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from functools import partial
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from .._pytree import pytree_dataclass, static_field
from ..integrators import Solver, rosenbrock2
from ..layout import WHEEL_TORQUES, Layout, pose_vector, velocity
from ..parameters import TIMING
from .dynamics import wheel_friction
from .motors import DCMotor, drive_torque
from .params import RobotParams
from .traction import GRAVITY

#: the state of :class:`SlipPlant`: pose of A, its body-frame velocity and yaw rate, the wheels' spin speeds
SLIP_STATE = Layout(
    ("x", "y", "theta", "u", "w", "r", "phidot_r", "phidot_l"),
    ("m", "m", "rad", "m/s", "m/s", "rad/s", "rad/s", "rad/s"),
)


def wheel_spins(x: Array) -> Array:
    """(phidot_R, phidot_L) [rad/s] of a :data:`SLIP_STATE` vector (or one that begins with it)."""
    return SLIP_STATE.span(x, "phidot_r", "phidot_l")


#: what it logs each period: applied torques (named as DynamicPlant's), slip speeds, the floor's forces and loads
SLIP_LOGS = Layout(
    ("tau_r", "tau_l", "slip_r", "slip_l", "slip_lateral", "force_rx", "force_lx", "force_y", "normal_r", "normal_l"),
    ("N m", "N m", "m/s", "m/s", "m/s", "N", "N", "N", "N", "N"),
)
#: |h lambda| an explicit RK4 step stays stable at on the negative real axis is 2.78; kept with a margin
RK4_STABLE_STEP = 2.0
#: RK4 is kept while it needs at most this many times the Rosenbrock scheme's steps: one Rosenbrock step (a 5 x 5
#: Jacobian, its factors, two solves) measured 1.4 RK4 steps in a batch; 2 favours the more accurate RK4 near a tie
ROSENBROCK_COST = 2
#: the Rosenbrock scheme's largest step [s]: stable at any step, it needs this to follow the slow motion and the
#: contact's turn-on (20 sub-steps per 10 ms)
ROSENBROCK_STEP = 5e-4


def require_wheel_inertia(params: RobotParams) -> None:
    """A ValueError unless every J_w > 0: with massless wheels the wheel equation is algebraic, and a wheel pushed
    beyond grip would spin up infinitely fast."""
    if np.any(np.asarray(params.wheel_inertia) <= 0.0):
        raise ValueError(
            "the slip plant needs wheel_inertia J_w > 0 [kg m^2] (wheel plus N^2 J_rotor): with massless wheels "
            "a wheel beyond grip accelerates without bound"
        )


def load_fraction(params: RobotParams, caster: Array | float) -> Array:
    """1 - d / l_c: the share of the weight the drive wheels carry with a caster at body x = l_c (1 with none,
    l_c = inf)."""
    return 1.0 - jnp.asarray(params.com_offset) / jnp.asarray(caster)


@pytree_dataclass
class SlipPlant:
    """The robot with finite grip (model.md §1.10): input wheel torques [N m], state :data:`SLIP_STATE`.

    Attributes
    ----------
    params : RobotParams
        The robot; ``wheel_inertia`` must be > 0.
    friction : float
        Floor friction coefficient mu.
    slip_speed : float
        Regularising slip speed eps_s [m/s] at which friction is fully developed.
    caster : float
        Body x of the frictionless caster l_c [m], same side as the centre of mass; ``inf`` for none (N = m g / 2).
    motor : DCMotor or None
        When given, the torque command goes through its current-controlled driver, so back-EMF bounds the wheels'
        spin; else the torques apply as commanded, within +-``params.max_torque``.
    pwm_model : DCMotor or None
        With a motor: None for a current-controlled board, else the board's model of its motor, through which it
        turns the torque command into a PWM voltage (:func:`~ddtrack.model.motors.drive_torque`).
    com_height : float
        Height h [m] of the centre of mass above the floor; 0: the static loads, no load transfer.
    scheme : str
        ``"rk4"`` or ``"rosenbrock"`` (static).
    substeps : int or Array
        Sub-steps per control period at least (a number, traced: robots and floors that need different counts share
        one compiled program); the solver's count is used when larger.
    """

    params: RobotParams
    friction: Array | float = 0.8
    slip_speed: Array | float = 1e-2
    caster: Array | float = math.inf
    motor: DCMotor | None = None
    pwm_model: DCMotor | None = None
    com_height: Array | float = 0.0
    scheme: str = static_field(default="rk4", why="the integrator, a different program")
    substeps: Array | int = 1
    state_layout: ClassVar[Layout] = SLIP_STATE
    input_layout: ClassVar[Layout] = WHEEL_TORQUES
    logged_layout: ClassVar[Layout] = SLIP_LOGS

    @property
    def input_kind(self) -> str:
        return "torque"

    def init(self, body: Array) -> Array:
        """BODY [x, y, theta, v, omega] with no lateral speed and the wheels rolling without slip."""
        v, omega = velocity(body)
        p = self.params
        spin = jnp.stack([v + p.half_axle * omega, v - p.half_axle * omega]) / p.wheel_radius
        return jnp.concatenate([pose_vector(body), jnp.stack([v, jnp.zeros_like(v), omega]), spin])

    def observe(self, x: Array) -> Array:
        """BODY [x, y, theta, u, r]: the pose of A, its forward speed and the yaw rate."""
        return SLIP_STATE.take(x, "x", "y", "theta", "u", "r")

    def saturate(self, u: Array) -> Array:
        """The command within +-max_torque, or +-the motor's stall torque (the speed-dependent limit acts in the
        ODE)."""
        limit = self.params.max_torque if self.motor is None else self.motor.stall_torque
        return jnp.clip(u, -limit, limit)

    def applied(self, x: Array, u: Array) -> Array:
        """The wheel torques [N m] at state ``x`` under the command ``u``: through the motor's driver if any."""
        if self.motor is None:
            return u
        return drive_torque(self.motor, u, wheel_spins(x), self.pwm_model)[0]

    def slips(self, x: Array) -> tuple[Array, Array, Array]:
        """(longitudinal slip of the right and left contact, lateral slip w) [m/s]."""
        p = self.params
        u, w, r = (SLIP_STATE.read(x, name) for name in ("u", "w", "r"))
        spin_r, spin_l = wheel_spins(x)
        return u + p.half_axle * r - p.wheel_radius * spin_r, u - p.half_axle * r - p.wheel_radius * spin_l, w

    def normals(self, x: Array) -> tuple[Array, Array]:
        """(N_R, N_L) [N]: each drive wheel's load, the static share moved by the body's acceleration.

        N_i = N_0 + a F_x +- b F_y with a = h / (2 l_c), b = h / (2 L), and F = N_R f_R + N_L f_L where f_i is the
        floor's force per newton of load (the friction circle's -mu s_i / sqrt(|s_i|^2 + eps_s^2)): a 2 x 2 linear
        system, solved in closed form. With h = 0 it is N_0 = m g (1 - d / l_c) / 2 exactly.
        """
        p = self.params
        right, left, lateral = self.slips(x)
        eps2 = jnp.asarray(self.slip_speed) ** 2
        unit_r = -self.friction / jnp.sqrt(right**2 + lateral**2 + eps2)
        unit_l = -self.friction / jnp.sqrt(left**2 + lateral**2 + eps2)
        rx, ry, lx, ly = unit_r * right, unit_r * lateral, unit_l * left, unit_l * lateral
        static = p.mass * GRAVITY * load_fraction(p, self.caster) / 2.0
        a = self.com_height / (2.0 * jnp.asarray(self.caster))  # 0 without a caster (l_c = inf)
        b = self.com_height / (2.0 * p.half_axle)
        a11, a12 = 1.0 - a * rx - b * ry, -a * lx - b * ly
        a21, a22 = -a * rx + b * ry, 1.0 - a * lx + b * ly
        det = a11 * a22 - a12 * a21
        # a wheel whose load would go negative has lifted: it carries nothing (the model ends at tipping)
        return jnp.maximum(static * (a22 - a12) / det, 0.0), jnp.maximum(static * (a11 - a21) / det, 0.0)

    def forces(self, x: Array) -> tuple[Array, Array, Array, Array]:
        """(F_Rx, F_Ry, F_Lx, F_Ly) [N]: the floor's force on each wheel in the body frame."""
        right, left, lateral = self.slips(x)
        normal_r, normal_l = self.normals(x)
        eps2 = jnp.asarray(self.slip_speed) ** 2
        # regularised Coulomb circle: the full mu N once the slip is well above eps_s
        scale_r = -self.friction * normal_r / jnp.sqrt(right**2 + lateral**2 + eps2)
        scale_l = -self.friction * normal_l / jnp.sqrt(left**2 + lateral**2 + eps2)
        return scale_r * right, scale_r * lateral, scale_l * left, scale_l * lateral

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        """The state's rate under the wheel torque command ``u`` and disturbance torques ``tau_dist`` [N m]."""
        p = self.params
        theta, fwd, lat, r = (SLIP_STATE.read(x, name) for name in ("theta", "u", "w", "r"))
        f_rx, f_ry, f_lx, f_ly = self.forces(x)
        f_x, f_y = f_rx + f_lx, f_ry + f_ly
        r_dot = (p.half_axle * (f_rx - f_lx) - p.com_offset * f_y) / p.inertia
        u_dot = f_x / p.mass + r * lat + p.com_offset * r**2
        w_dot = f_y / p.mass - p.com_offset * r_dot - r * fwd
        drive = self.applied(x, u) - wheel_friction(p, wheel_spins(x)) - tau_dist
        spin_dot = (drive - p.wheel_radius * jnp.stack([f_rx, f_lx])) / p.wheel_inertia
        c, s = jnp.cos(theta), jnp.sin(theta)
        pose_dot = jnp.stack([fwd * c - lat * s, fwd * s + lat * c, r])
        return jnp.concatenate([pose_dot, jnp.stack([u_dot, w_dot, r_dot]), spin_dot])

    def advance(self, x: Array, u: Array, tau_dist: Array, period: Array | float, solver: Solver) -> Array:
        """The state one ``period`` [s] later in max(``solver.substeps``, its own) steps (traced): by the solver's
        method where the plant's scheme is explicit, by ROS2 where it is ``"rosenbrock"`` (stiff)."""
        steps = jnp.maximum(solver.substeps, self.substeps)

        def rate(z: Array) -> Array:
            return self.derivative(z, u, tau_dist)

        if self.scheme == "rosenbrock":  # implicit in the velocities and spins only: the pose is not stiff
            return rosenbrock2(rate, x, period, steps, stiff=(3, 8))
        return replace(solver, substeps=steps).integrate(rate, x, period)

    def logged(self, x: Array, u: Array) -> dict[str, Array]:
        """Applied torques, slip speeds, the floor's forces and the wheels' loads at the start of the period
        (:data:`SLIP_LOGS`)."""
        tau = self.applied(x, u)
        f_rx, f_ry, f_lx, f_ly = self.forces(x)
        right, left, lateral = self.slips(x)
        normal_r, normal_l = self.normals(x)
        values = (tau[0], tau[1], right, left, lateral, f_rx, f_lx, f_ry + f_ly, normal_r, normal_l)
        return dict(zip(SLIP_LOGS.names, values, strict=True))


def contact_stiffness(
    params: RobotParams,
    friction: float,
    slip_speed: float,
    caster: float = math.inf,
    motor: DCMotor | None = None,
    speed_gain: float = 0.0,
    com_height: float = 0.0,
) -> float:
    """An upper estimate of the fastest decay rate [1/s] of the slip plant, from nominal (float) numbers.

    Near zero slip the contact is a damper of rate mu N / eps_s on the slip velocities G z, z = (u, w, r, phi_dot_R,
    phi_dot_L), so its fastest mode is (mu N / eps_s) lambda_max(M_z^-1 G^T G), M_z the mass matrix of z (yaw about
    A). Added to it: the wheel friction's slope (b_w + tau_c / eps_f) / J_w and the back-EMF's eta k_t k_e / (R_a J_w)
    (a wheel on the torque-speed curve), each acting on a wheel's spin alone; a PI wheel-speed loop of proportional
    gain ``speed_gain`` k_p [V s/rad] adds eta k_t k_p / (R_a J_w) (model.md §1.10, the velocity-driven variant).
    With the centre of mass at ``com_height`` h the load N is taken at its most, N_0 + mu m g h (1 / (2 |l_c|) +
    1 / (2 L)) (the floor's forces are at most mu m g).
    """
    m, d, inertia = float(params.mass), float(params.com_offset), float(params.inertia)
    radius, half, spin = float(params.wheel_radius), float(params.half_axle), float(params.wheel_inertia)
    mass_matrix = np.diag([m, m, inertia + m * d * d, spin, spin])
    mass_matrix[1, 2] = mass_matrix[2, 1] = m * d
    slip_map = np.array(
        [[1.0, 0.0, half, -radius, 0.0], [0.0, 1.0, 0.0, 0.0, 0.0], [1.0, 0.0, -half, 0.0, -radius], [0, 1, 0, 0, 0]]
    )
    modes = np.linalg.eigvals(np.linalg.solve(mass_matrix, slip_map.T @ slip_map))
    normal = m * GRAVITY * float(load_fraction(params, caster)) / 2.0
    normal += friction * m * GRAVITY * com_height * (1.0 / (2.0 * abs(caster)) + 1.0 / (2.0 * half))
    rate = friction * normal / slip_speed * float(np.max(modes.real))
    rate += (float(params.viscous_friction) + float(params.coulomb_friction) / float(params.friction_smoothing)) / spin
    if motor is not None:
        gain = float(motor.back_emf) + speed_gain  # the voltage falls with the wheel's speed at slope k_e + k_p
        rate += float(motor.efficiency * motor.torque_constant / motor.resistance) * gain / spin
    return rate


def choose_integration(stiffness: float, period: float, substeps: int) -> tuple[str, int]:
    """(scheme, sub-steps per period) for a plant of fastest rate ``stiffness`` [1/s] at control ``period`` [s].

    RK4 needs n = max(``substeps``, ceil(period stiffness / 2)) steps, so that h lambda <= 2 inside RK4's stability
    interval (2.78). The Rosenbrock step, stable at any step, needs max(``substeps``, ceil(period / 0.5 ms)); RK4
    is chosen while it needs at most twice as many steps.
    """
    explicit = max(substeps, _rk4_steps(stiffness, period))
    implicit = max(substeps, math.ceil(period / ROSENBROCK_STEP - 1e-9))
    if explicit <= ROSENBROCK_COST * implicit:
        return "rk4", explicit
    return "rosenbrock", implicit


def _check_caster(params: RobotParams, caster: float) -> None:
    ratio = np.asarray(params.com_offset) / caster
    if np.any(ratio < 0.0) or np.any(ratio >= 1.0):
        raise ValueError(
            f"the caster at body x = {caster} m must lie beyond the centre of mass, on its side (0 <= d / l_c < 1)"
        )


def slip_plant_model(
    nominal: RobotParams,
    *,
    friction: float = 0.8,
    slip_speed: float = 1e-2,
    caster: float | None = None,
    motor: DCMotor | None = None,
    period: float = TIMING.control_period,
    substeps: int = TIMING.substeps,
    scheme: str | None = None,
    pwm_model: DCMotor | None = None,
    com_height: float = 0.0,
) -> Callable[[RobotParams], SlipPlant]:
    """A ``Setup.plant_model`` giving the :class:`SlipPlant` of a drawn robot, alone or as a batch (the scalars
    take the parameters' leading batch axis), its integration chosen once from the ``nominal`` robot (floats) by
    :func:`choose_integration` at control ``period`` [s] and the simulator's ``substeps``.

    ``scheme`` forces ``"rk4"`` (with the steps the stability rule needs) or ``"rosenbrock"``. Raises ValueError for
    J_w <= 0 or a caster not beyond the centre of mass (here and for every drawn robot). ``pwm_model``: the board's
    model of ``motor`` when it offers PWM only (:class:`SlipPlant`); ``com_height``: the centre of mass's height h [m].
    """
    l_c, chosen, steps = slip_integration(
        nominal, friction, slip_speed, caster, motor, period, substeps, scheme, com_height=com_height
    )

    def plant_model(params: RobotParams) -> SlipPlant:
        check_drawn(params, l_c)  # a drawn robot too
        mu, eps, held_caster, height = broadcast_like(params, (friction, slip_speed, l_c, com_height))
        motors = broadcast_like(params, motor), broadcast_like(params, pwm_model)
        count = jnp.broadcast_to(steps, jnp.shape(params.mass))  # an integer per robot, traced
        return SlipPlant(params, mu, eps, held_caster, *motors, com_height=height, scheme=chosen, substeps=count)

    return plant_model


def slip_integration(
    nominal: RobotParams,
    friction: float,
    slip_speed: float,
    caster: float | None,
    motor: DCMotor | None,
    period: float,
    substeps: int,
    scheme: str | None,
    speed_gain: float = 0.0,
    com_height: float = 0.0,
) -> tuple[float, str, int]:
    """(l_c, scheme, sub-steps) of a slip plant for the ``nominal`` robot (floats), checked as
    :func:`slip_plant_model` says; ``speed_gain`` the proportional gain of a PI wheel-speed loop, if any;
    ``com_height`` the centre of mass's height [m]."""
    require_wheel_inertia(nominal)
    l_c = math.inf if caster is None else float(caster)
    _check_caster(nominal, l_c)
    stiffness = contact_stiffness(nominal, friction, slip_speed, l_c, motor, speed_gain, com_height)
    chosen, steps = choose_integration(stiffness, period, substeps)
    if scheme is not None and scheme != chosen:  # forced: with the steps the rule gives that scheme
        chosen = scheme
        if scheme == "rosenbrock":
            steps = max(substeps, math.ceil(period / ROSENBROCK_STEP - 1e-9))
        else:
            steps = max(substeps, _rk4_steps(stiffness, period))
    return l_c, chosen, steps


def check_drawn(params: RobotParams, caster: float) -> None:
    """:func:`slip_plant_model`'s checks on a drawn robot, unless its parameters are traced (they cannot be)."""
    if not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(params)):
        require_wheel_inertia(params)
        _check_caster(params, caster)


def broadcast_like(params: RobotParams, value: Any) -> Any:
    """``value`` (a float or a pytree of them) with every leaf broadcast to the parameters' leading batch shape."""
    return jax.tree_util.tree_map(partial(_broadcast, jnp.shape(params.mass)), value)


def _rk4_steps(stiffness: float, period: float) -> int:
    return math.ceil(period * stiffness / RK4_STABLE_STEP)


def _broadcast(batch: tuple[int, ...], value: Any) -> Array:
    return jnp.broadcast_to(jnp.asarray(value, dtype=float), batch)


def slip_plant(params: RobotParams, **options: Any) -> SlipPlant:
    """The :class:`SlipPlant` of one robot (floats), options as :func:`slip_plant_model`'s."""
    return slip_plant_model(params, **options)(params)
