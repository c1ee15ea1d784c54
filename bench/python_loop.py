"""The paper's line case as a plain Python loop: the baseline ddtrack is measured against.

This is what a user would write by hand: floats, the ``math`` module, one Python call per
control period and per RK4 stage; no NumPy arrays and no JAX in the loop. It implements the same
closed loop as ``ddtrack.run`` on ``scenarios/paper_line.toml`` (SPEC 1.3, 2.2-2.5, 2.7):

* plant: reduced dynamics in (v, omega) with tanh-Coulomb + viscous wheel friction and the
  wheel-torque disturbance ``bias + amplitude sin(frequency t + phase)`` (SPEC 1.3, 1.4);
* integration: the torque is held over each control period T_c and the plant is integrated by
  ``substeps`` classical RK4 steps (SPEC 2.7 step 6);
* controller: Kanayama posture error with wrapped e_theta (2.2), the Kanayama law (2.4), its
  analytic derivative (2.5), the velocity clamps (a clamped channel's derivative is 0), computed
  torque on the nominal model (eqs. 7, 11) and the torque limit.

The loop (:func:`simulate`) takes the controller as a function ``step(t, y, ref, memory) ->
(tau, memory)``, so another controller (e.g. the NN-adaptive law, SPEC 3.8) is one more
``*_step`` function and one more ``run_*`` wrapper beside :func:`run_backstepping`.

Deliberately not here (ddtrack has them; they cost it a little): Gaussian disturbance and
measurement noise (they need ddtrack's random streams), random plant draws, divergence/NaN checks,
and recording anything but the state.

Usage::

    import ddtrack
    from python_loop import params_from_scenario, run_backstepping
    states = run_backstepping(**params_from_scenario(ddtrack.load_scenario("scenarios/paper_line.toml")))
    states[-1]   # == ddtrack.run(...).state[-1] to about 1e-12
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

State = tuple[float, float, float, float, float]  # x [m], y [m], theta [rad], v [m/s], omega [rad/s]


# --- parameters ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Robot:
    """One robot model (the true plant, or the controller's nominal model). SI units, SPEC 1.4."""

    mass: float  # m [kg]
    inertia: float  # I_C, about the centre of mass [kg m^2]
    com_offset: float  # d, centre of mass ahead of the axle [m]
    wheel_radius: float  # R [m]
    half_axle: float  # L [m]
    viscous_friction: float  # b_w per wheel [N m s/rad]
    coulomb_friction: float  # tau_c per wheel [N m]
    friction_smoothing: float  # eps_f [rad/s]
    max_torque: float  # per wheel [N m]

    @property
    def inertia_axle(self) -> float:
        """I_A = I_C + m d^2 [kg m^2]."""
        return self.inertia + self.mass * self.com_offset**2


@dataclass(frozen=True)
class Disturbance:
    """Wheel torques [right, left] = bias + amplitude sin(frequency t + phase) [N m], opposing the drive."""

    bias: tuple[float, float]
    amplitude: tuple[float, float]
    frequency: float  # [rad/s]
    phase: tuple[float, float]


@dataclass(frozen=True)
class Line:
    """Straight reference at constant speed from ``start`` along ``heading``."""

    start: tuple[float, float]  # [m]
    heading: float  # [rad]
    speed: float  # v_r [m/s]


# --- small pieces of maths (one function per SPEC equation) --------------------------------------


def wrap_angle(angle: float) -> float:
    """Map an angle to (-pi, pi] (Python's % is a floor modulo, like jnp.mod)."""
    wrapped = (angle + math.pi) % (2.0 * math.pi) - math.pi
    return math.pi if wrapped == -math.pi else wrapped


def line_reference(line: Line, t: float) -> tuple[float, float, float, float, float, float, float]:
    """Reference (x_r, y_r, theta_r, v_r, omega_r, v_r_dot, omega_r_dot) at time t (SPEC 2.1)."""
    dx, dy = line.speed * math.cos(line.heading), line.speed * math.sin(line.heading)
    return (line.start[0] + t * dx, line.start[1] + t * dy, wrap_angle(math.atan2(dy, dx)),
            math.hypot(dx, dy), 0.0, 0.0, 0.0)


def posture_error(x: float, y: float, theta: float, x_r: float, y_r: float,
                  theta_r: float) -> tuple[float, float, float]:
    """Kanayama e_p = T_e(theta) (q_r - q), e_theta wrapped (SPEC 2.2)."""
    c, s = math.cos(theta), math.sin(theta)
    dx, dy = x_r - x, y_r - y
    return c * dx + s * dy, -s * dx + c * dy, wrap_angle(theta_r - theta)


def friction(robot: Robot, phi_dot: float) -> float:
    """Wheel friction tau_f = b_w phi_dot + tau_c tanh(phi_dot / eps_f) [N m] (SPEC 1.2)."""
    return robot.viscous_friction * phi_dot + robot.coulomb_friction * math.tanh(phi_dot / robot.friction_smoothing)


def derivative(robot: Robot, state: State, tau_r: float, tau_l: float, dist_r: float, dist_l: float) -> State:
    """X_dot of the reduced dynamics, scalar form of SPEC 1.3."""
    _, _, theta, v, omega = state
    r, half = robot.wheel_radius, robot.half_axle
    net_r = tau_r - friction(robot, (v + half * omega) / r) - dist_r
    net_l = tau_l - friction(robot, (v - half * omega) / r) - dist_l
    md = robot.mass * robot.com_offset
    v_dot = ((net_r + net_l) / r + md * omega * omega) / robot.mass
    omega_dot = (half * (net_r - net_l) / r - md * omega * v) / robot.inertia_axle
    return v * math.cos(theta), v * math.sin(theta), omega, v_dot, omega_dot


def rk4(f: Callable[[State], State], state: State, duration: float, steps: int) -> State:
    """Integrate X_dot = f(X) over ``duration`` by ``steps`` classical RK4 steps."""
    h = duration / steps
    for _ in range(steps):
        k1 = f(state)
        k2 = f(tuple(s + 0.5 * h * k for s, k in zip(state, k1)))
        k3 = f(tuple(s + 0.5 * h * k for s, k in zip(state, k2)))
        k4 = f(tuple(s + h * k for s, k in zip(state, k3)))
        state = tuple(s + (h / 6.0) * (a + 2.0 * b + 2.0 * c + d) for s, a, b, c, d in zip(state, k1, k2, k3, k4))
    return state


def clamp(value: float, limit: float) -> float:
    return min(max(value, -limit), limit)


# --- controllers ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class BacksteppingGains:
    kx: float
    ky: float
    ktheta: float
    kc: tuple[float, float]  # K_c of eq. 11 [1/s]
    max_velocity: float  # |v_c| clamp [m/s]
    max_yaw_rate: float  # |omega_c| clamp [rad/s]


def kanayama(error: tuple[float, float, float], v: float, omega: float, ref: tuple, kx: float, ky: float,
             ktheta: float) -> tuple[float, float, float, float]:
    """nu_c (SPEC 2.4) and its analytic derivative with the measured nu in the error dynamics (SPEC 2.5).

    Returns (v_c, omega_c, v_c_dot, omega_c_dot), unclamped.
    """
    e_x, e_y, e_th = error
    _, _, _, v_r, omega_r, v_r_dot, omega_r_dot = ref
    sin_e, cos_e = math.sin(e_th), math.cos(e_th)
    v_c = v_r * cos_e + kx * e_x
    omega_c = omega_r + v_r * (ky * e_y + ktheta * sin_e)
    de_x = omega * e_y - v + v_r * cos_e  # SPEC 2.3
    de_y = -omega * e_x + v_r * sin_e
    de_th = omega_r - omega
    v_c_dot = v_r_dot * cos_e - v_r * sin_e * de_th + kx * de_x
    omega_c_dot = omega_r_dot + v_r_dot * (ky * e_y + ktheta * sin_e) + v_r * (ky * de_y + ktheta * cos_e * de_th)
    return v_c, omega_c, v_c_dot, omega_c_dot


def computed_torque(nominal: Robot, v: float, omega: float, v_c: float, omega_c: float, v_c_dot: float,
                    omega_c_dot: float, kc: tuple[float, float]) -> tuple[float, float]:
    """tau = B_bar^-1 (M_hat u + V_hat(nu) nu) + tau_f_hat, u = nu_c_dot + K_c (nu_c - nu), saturated (SPEC 2.5)."""
    u_v = v_c_dot + kc[0] * (v_c - v)
    u_omega = omega_c_dot + kc[1] * (omega_c - omega)
    md = nominal.mass * nominal.com_offset
    force = nominal.mass * u_v - md * omega * omega  # generalised force along v [N]
    torque = nominal.inertia_axle * u_omega + md * omega * v  # and about the axle [N m]
    r, half = nominal.wheel_radius, nominal.half_axle
    tau_r = r / 2.0 * (force + torque / half) + friction(nominal, (v + half * omega) / r)
    tau_l = r / 2.0 * (force - torque / half) + friction(nominal, (v - half * omega) / r)
    return clamp(tau_r, nominal.max_torque), clamp(tau_l, nominal.max_torque)


def backstepping_step(nominal: Robot, gains: BacksteppingGains) -> Callable:
    """Kanayama backstepping over computed torque, as a ``step(t, y, ref, memory) -> (tau, memory)``."""

    def step(t: float, y: State, ref: tuple, memory: Any) -> tuple[tuple[float, float], Any]:
        error = posture_error(y[0], y[1], y[2], ref[0], ref[1], ref[2])
        v_c, omega_c, v_c_dot, omega_c_dot = kanayama(error, y[3], y[4], ref, gains.kx, gains.ky, gains.ktheta)
        if abs(v_c) > gains.max_velocity:  # a clamped channel's derivative is 0 (SPEC 2.5)
            v_c, v_c_dot = clamp(v_c, gains.max_velocity), 0.0
        if abs(omega_c) > gains.max_yaw_rate:
            omega_c, omega_c_dot = clamp(omega_c, gains.max_yaw_rate), 0.0
        tau = computed_torque(nominal, y[3], y[4], v_c, omega_c, v_c_dot, omega_c_dot, gains.kc)
        return tau, memory

    return step


# --- the closed loop -----------------------------------------------------------------------------


def simulate(step: Callable, memory: Any, plant: Robot, disturbance: Disturbance, line: Line, x0: State, *,
             n_steps: int, control_period: float, substeps: int) -> list[State]:
    """The discrete loop of SPEC 2.7 with a zero-order hold; returns the states x_0 .. x_{N-1}
    (the rows of ``ddtrack.SimResult.state``)."""
    state = tuple(float(s) for s in x0)
    states = []
    for k in range(n_steps):
        t = k * control_period
        ref = line_reference(line, t)
        tau, memory = step(t, state, ref, memory)
        tau_r, tau_l = clamp(tau[0], plant.max_torque), clamp(tau[1], plant.max_torque)
        d = disturbance
        dist_r = d.bias[0] + d.amplitude[0] * math.sin(d.frequency * t + d.phase[0])
        dist_l = d.bias[1] + d.amplitude[1] * math.sin(d.frequency * t + d.phase[1])
        states.append(state)
        state = rk4(lambda z: derivative(plant, z, tau_r, tau_l, dist_r, dist_l), state, control_period, substeps)
    return states


def run_backstepping(*, plant: Robot, nominal: Robot, disturbance: Disturbance, line: Line, x0: State,
                     gains: BacksteppingGains, n_steps: int, control_period: float, substeps: int) -> list[State]:
    """One backstepping run; the keyword arguments are what :func:`params_from_scenario` returns."""
    return simulate(backstepping_step(nominal, gains), (), plant, disturbance, line, x0,
                    n_steps=n_steps, control_period=control_period, substeps=substeps)


# --- reading a ddtrack scenario ------------------------------------------------------------------


def _robot(params: Any) -> Robot:
    return Robot(**{name: float(getattr(params, name)) for name in Robot.__dataclass_fields__})


def params_from_scenario(scenario: Any) -> dict[str, Any]:
    """The keyword arguments of :func:`run_backstepping` from a loaded ``ddtrack.Scenario``.

    Refuses, loudly, what this loop does not implement (so a comparison is never silently unfair).
    """
    unsupported = []
    if scenario.trajectory.kind != "line":
        unsupported.append(f"trajectory.kind = {scenario.trajectory.kind!r} (only 'line')")
    if scenario.controller.kind != "backstepping" or scenario.controller.inner != "computed_torque":
        unsupported.append("a controller other than backstepping over computed_torque")
    if scenario.controller.strict:
        unsupported.append("controller.strict = true")
    if scenario.disturbance.kind not in ("none", "constant", "sinusoid"):
        unsupported.append(f"disturbance.kind = {scenario.disturbance.kind!r}")
    if any(scenario.noise.build().std):
        unsupported.append("measurement noise")
    if any(draw is not None for _, draw in scenario.randomize):
        unsupported.append("[randomize] draws")
    if unsupported:
        raise ValueError("bench/python_loop.py does not implement: " + "; ".join(unsupported))

    wheel = scenario.disturbance.build()
    disturbance = Disturbance(bias=tuple(map(float, wheel.bias)), amplitude=tuple(map(float, wheel.amplitude)),
                              frequency=float(wheel.frequency), phase=tuple(map(float, wheel.phase)))
    trajectory = scenario.trajectory
    control = scenario.controller
    kx, ky, ktheta = control.gains
    pose = scenario.initial.pose
    if pose is None:  # start on the reference
        ref0 = line_reference(Line(tuple(trajectory.start), trajectory.heading, trajectory.speed), 0.0)
        pose = ref0[:3]
    sim = scenario.simulation
    return dict(
        plant=_robot(scenario.plant_params()),
        nominal=_robot(scenario.robot.params()),
        disturbance=disturbance,
        line=Line(start=tuple(trajectory.start), heading=float(trajectory.heading), speed=float(trajectory.speed)),
        x0=(*map(float, pose), *map(float, scenario.initial.velocity)),
        gains=BacksteppingGains(kx=kx, ky=ky, ktheta=ktheta, kc=tuple(control.kc), max_velocity=control.max_velocity,
                                max_yaw_rate=control.max_yaw_rate),
        n_steps=sim.n_steps,
        control_period=sim.control_period,
        substeps=sim.substeps,
    )
