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
(tau, memory)``, so another controller is one more ``*_step`` function and one more ``run_*``
wrapper beside :func:`run_backstepping`. The NN-adaptive backstepping law (SPEC 3, pseudo-code 3.8)
is the second: :func:`run_nn_adaptive`, with the emulator network as nested lists of floats (forward
pass, input Jacobian, online backpropagation with gradient clipping and momentum) and the gain law
with its clip, bounds and gate, all in scalar loops. Its initial weights are ddtrack's (drawn from the
seed, or identified): :func:`params_from_nn_setup` reads them from ``ddtrack.prepare``'s setup.

Deliberately not here (ddtrack has them; they cost it a little): Gaussian disturbance and
measurement noise (they need ddtrack's random streams), random plant draws, divergence/NaN checks,
and recording anything but the state.

Usage::

    import ddtrack

    ddtrack.enable_float64()
    from python_loop import params_from_scenario, run_backstepping
    states = run_backstepping(**params_from_scenario(ddtrack.load_scenario("scenarios/paper_line.toml")))
    states[-1]   # == ddtrack.run(...).state[-1] to about 1e-12

    scenario = ddtrack.load_scenario("scenarios/paper_line.toml", controller="nn_adaptive_backstepping",
                                     overrides=["controller.identification=false"])
    setup, _ = ddtrack.prepare(scenario)
    states = run_nn_adaptive(**params_from_nn_setup(scenario, setup))
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
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
    return (
        line.start[0] + t * dx,
        line.start[1] + t * dy,
        wrap_angle(math.atan2(dy, dx)),
        math.hypot(dx, dy),
        0.0,
        0.0,
        0.0,
    )


def posture_error(
    x: float, y: float, theta: float, x_r: float, y_r: float, theta_r: float
) -> tuple[float, float, float]:
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
        k2 = f(tuple(s + 0.5 * h * k for s, k in zip(state, k1, strict=True)))
        k3 = f(tuple(s + 0.5 * h * k for s, k in zip(state, k2, strict=True)))
        k4 = f(tuple(s + h * k for s, k in zip(state, k3, strict=True)))
        state = tuple(
            s + (h / 6.0) * (a + 2.0 * b + 2.0 * c + d) for s, a, b, c, d in zip(state, k1, k2, k3, k4, strict=True)
        )
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


def kanayama(
    error: tuple[float, float, float], v: float, omega: float, ref: tuple, kx: float, ky: float, ktheta: float
) -> tuple[float, float, float, float]:
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


def clamp_command(
    v_c: float, omega_c: float, v_c_dot: float, omega_c_dot: float, max_velocity: float, max_yaw_rate: float
) -> tuple[float, float, float, float, bool]:
    """|v_c| <= v_max, |omega_c| <= w_max; a clamped channel's derivative is 0 (SPEC 2.5). Last: any clamped."""
    saturated = False
    if abs(v_c) > max_velocity:
        v_c, v_c_dot, saturated = clamp(v_c, max_velocity), 0.0, True
    if abs(omega_c) > max_yaw_rate:
        omega_c, omega_c_dot, saturated = clamp(omega_c, max_yaw_rate), 0.0, True
    return v_c, omega_c, v_c_dot, omega_c_dot, saturated


def computed_torque(
    nominal: Robot,
    v: float,
    omega: float,
    v_c: float,
    omega_c: float,
    v_c_dot: float,
    omega_c_dot: float,
    kc: tuple[float, float],
) -> tuple[float, float]:
    """tau = B_bar^-1 (M_hat u + V_hat(nu) nu) + tau_f_hat, u = nu_c_dot + K_c (nu_c - nu), saturated (SPEC 2.5)."""
    tau_r, tau_l = unsaturated_torque(nominal, v, omega, v_c, omega_c, v_c_dot, omega_c_dot, kc)
    return clamp(tau_r, nominal.max_torque), clamp(tau_l, nominal.max_torque)


def unsaturated_torque(
    nominal: Robot,
    v: float,
    omega: float,
    v_c: float,
    omega_c: float,
    v_c_dot: float,
    omega_c_dot: float,
    kc: tuple[float, float],
) -> tuple[float, float]:
    """:func:`computed_torque` before the torque limit (eqs. 7, 11)."""
    u_v = v_c_dot + kc[0] * (v_c - v)
    u_omega = omega_c_dot + kc[1] * (omega_c - omega)
    md = nominal.mass * nominal.com_offset
    force = nominal.mass * u_v - md * omega * omega  # generalised force along v [N]
    torque = nominal.inertia_axle * u_omega + md * omega * v  # and about the axle [N m]
    r, half = nominal.wheel_radius, nominal.half_axle
    tau_r = r / 2.0 * (force + torque / half) + friction(nominal, (v + half * omega) / r)
    tau_l = r / 2.0 * (force - torque / half) + friction(nominal, (v - half * omega) / r)
    return tau_r, tau_l


def backstepping_step(nominal: Robot, gains: BacksteppingGains) -> Callable:
    """Kanayama backstepping over computed torque, as a ``step(t, y, ref, memory) -> (tau, memory)``."""

    def step(t: float, y: State, ref: tuple, memory: Any) -> tuple[tuple[float, float], Any]:
        error = posture_error(y[0], y[1], y[2], ref[0], ref[1], ref[2])
        v_c, omega_c, v_c_dot, omega_c_dot, _ = clamp_command(
            *kanayama(error, y[3], y[4], ref, gains.kx, gains.ky, gains.ktheta), gains.max_velocity, gains.max_yaw_rate
        )
        tau = computed_torque(nominal, y[3], y[4], v_c, omega_c, v_c_dot, omega_c_dot, gains.kc)
        return tau, memory

    return step


# --- NN-adaptive backstepping (SPEC 3) -----------------------------------------------------------


@dataclass
class Network:
    """The emulator's weights as nested lists (SPEC 3.7): w1 (N_h x n_in), b1 (N_h), w2 (n_out x N_h), b2 (n_out)."""

    w1: list[list[float]]
    b1: list[float]
    w2: list[list[float]]
    b2: list[float]

    def copy(self) -> Network:
        return Network([row[:] for row in self.w1], self.b1[:], [row[:] for row in self.w2], self.b2[:])

    def zeros(self) -> Network:
        return Network(
            [[0.0] * len(row) for row in self.w1],
            [0.0] * len(self.b1),
            [[0.0] * len(row) for row in self.w2],
            [0.0] * len(self.b2),
        )


@dataclass(frozen=True)
class AdaptiveOptions:
    """The NN-adaptive law's settings, as resolved by ddtrack (SPEC 3.6, 3.7)."""

    gains: tuple[float, float, float]  # initial (Kx, Ky, Ktheta), also the leakage target
    kc: tuple[float, float]  # K_c of eq. 11 [1/s]
    max_velocity: float  # |v_c| clamp [m/s]
    max_yaw_rate: float  # |omega_c| clamp [rad/s]
    control_period: float  # T_c [s]
    rates: tuple[float, float, float]  # Lambda [1/s], for the normalised Jacobian
    gain_momentum: float  # beta_K
    max_step: tuple[float, float, float]  # clip of the gain change per period
    gain_min: tuple[float, float, float]
    gain_max: tuple[float, float, float]
    gate_error: float  # gains adapt only while e_tr is below this [m]
    leakage: float  # sigma [1/s]
    gamma: tuple[float, float, float]  # Gamma of eq. 22
    learning_rate: float  # emulator eta
    momentum: float  # emulator beta
    clip_norm: float  # emulator gradient-norm clip
    freeze_time: float  # no gain change before [s]
    input_scales: tuple[float, float, float, float]  # s_z
    output_scales: tuple[float, float, float]  # s_y
    jacobian_scale: float  # c_bar (= c_v of SPEC 3.4 (a)), normalises the emulator's Jacobian


@dataclass
class AdaptiveMemory:
    """What the NN-adaptive law carries from one control period to the next (updated in place)."""

    gains: list[float]  # current (Kx, Ky, Ktheta)
    network: Network  # emulator weights
    velocity: Network  # their momentum
    last_step: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # previous gain change
    previous_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)  # measured q_{k-1}
    previous_input: list[float] = field(default_factory=list)  # z_{k-1} = [v_c, omega_c, v, omega]
    previous_saturated: bool = False  # a clamp or the torque limit acted at k-1
    started: bool = False  # a transition exists to learn from


def body_increment(pose: tuple, next_pose: tuple) -> tuple[float, float, float]:
    """The emulator's target: the step q_k -> q_k+1 in the body frame of q_k, heading wrapped (SPEC 3.7, E1).
    It is the posture error of ``next_pose`` seen from ``pose``."""
    return posture_error(pose[0], pose[1], pose[2], next_pose[0], next_pose[1], next_pose[2])


def hidden_layer(network: Network, z_normalised: list[float]) -> list[float]:
    """h = tanh(W1 z~ + b1) (paper eq. 19, N_h tanh units)."""
    return [
        math.tanh(sum(w * z for w, z in zip(row, z_normalised, strict=True)) + b)
        for row, b in zip(network.w1, network.b1, strict=True)
    ]


def output_layer(network: Network, h: list[float]) -> list[float]:
    """y~ = W2 h + b2 (paper eq. 20 with the linear output of eq. 32)."""
    return [
        sum(w * h_l for w, h_l in zip(row, h, strict=True)) + b for row, b in zip(network.w2, network.b2, strict=True)
    ]


def train_step(
    network: Network, velocity: Network, z_normalised: list[float], target: list[float], options: AdaptiveOptions
) -> None:
    """One backpropagation step on E = |y~ - y~*|^2 / 2, in place (SPEC 3.7): delta_2 = y~ - y~*,
    delta_1 = (W2^T delta_2) (1 - h^2), grad W2 = delta_2 h^T, grad W1 = delta_1 z~^T; the whole gradient
    scaled down to norm <= clip_norm; dW(k) = -eta grad + beta dW(k-1), W <- W + dW, for every array."""
    h = hidden_layer(network, z_normalised)
    delta2 = [y - y_star for y, y_star in zip(output_layer(network, h), target, strict=True)]
    delta1 = [sum(network.w2[i][k] * d for i, d in enumerate(delta2)) * (1.0 - h_k * h_k) for k, h_k in enumerate(h)]
    squares = (
        sum((d * z) ** 2 for d in delta1 for z in z_normalised)
        + sum(d * d for d in delta1)
        + sum((d * h_l) ** 2 for d in delta2 for h_l in h)
        + sum(d * d for d in delta2)
    )
    rate = -options.learning_rate * min(1.0, options.clip_norm / max(math.sqrt(squares), 1e-300))
    beta = options.momentum

    def update(weights: list[float], momenta: list[float], delta: float, inputs: list[float]) -> None:
        for j, x in enumerate(inputs):  # one row of a weight matrix: gradient delta * inputs
            momenta[j] = rate * (delta * x) + beta * momenta[j]
            weights[j] += momenta[j]

    for k, d in enumerate(delta1):
        update(network.w1[k], velocity.w1[k], d, z_normalised)
    update(network.b1, velocity.b1, 1.0, delta1)
    for i, d in enumerate(delta2):
        update(network.w2[i], velocity.w2[i], d, h)
    update(network.b2, velocity.b2, 1.0, delta2)


def emulator_jacobian(network: Network, options: AdaptiveOptions, z: list[float]) -> list[list[float]]:
    """J_b^n (3 x 2): the emulator's d y / d(v_c, omega_c) at z over c_bar (SPEC 3.4 (c)), with
    d y_i / d z_j = s_y,i sum_l W2_il (1 - h_l^2) W1_lj / s_z,j (paper eq. 34 corrected, SPEC 3.7)."""
    h = hidden_layer(network, [z_j / s for z_j, s in zip(z, options.input_scales, strict=True)])
    slope = [1.0 - h_l * h_l for h_l in h]
    return [
        [
            s_y
            * sum(w2_l * slope_l * w1_l[j] for w2_l, slope_l, w1_l in zip(row, slope, network.w1, strict=True))
            / options.input_scales[j]
            / options.jacobian_scale
            for j in (0, 1)
        ]
        for row, s_y in zip(network.w2, options.output_scales, strict=True)
    ]


def gain_gradient(
    error: tuple[float, float, float], v_r: float, gamma: tuple[float, float, float], jacobian: list[list[float]]
) -> tuple[float, float, float]:
    """dJ/d(Kx, Ky, Ktheta) = e^T Gamma D_b J_b^n Phi for J = e^T Gamma e / 2 (eqs. 22-24 corrected, SPEC 3.5
    generic form), with the exact D_b = [[-1, 0, e_y], [0, -1, -e_x], [0, 0, -1]] (SPEC 3.3) and
    Phi = [[e_x, 0, 0], [0, v_r e_y, v_r sin e_th]] (SPEC 3.2)."""
    e_x, e_y, e_th = error
    g_x, g_y, g_th = gamma[0] * e_x, gamma[1] * e_y, gamma[2] * e_th
    row = (-g_x, -g_y, g_x * e_y - g_y * e_x - g_th)  # e^T Gamma D_b
    along_v = sum(r * j[0] for r, j in zip(row, jacobian, strict=True))  # ... J_b^n, the v_c column
    along_omega = sum(r * j[1] for r, j in zip(row, jacobian, strict=True))  # and the omega_c column
    return along_v * e_x, along_omega * (v_r * e_y), along_omega * (v_r * math.sin(e_th))


def nn_adaptive_step(nominal: Robot, options: AdaptiveOptions) -> Callable:
    """NN-adaptive backstepping over computed torque (SPEC 3.8), as a ``step(t, y, ref, memory) -> (tau, memory)``
    with an :class:`AdaptiveMemory`."""
    limits = (options.max_velocity, options.max_yaw_rate)
    tc = options.control_period

    def step(t: float, y: State, ref: tuple, memory: AdaptiveMemory) -> tuple[tuple[float, float], AdaptiveMemory]:
        error = posture_error(y[0], y[1], y[2], ref[0], ref[1], ref[2])
        v, omega = y[3], y[4]
        # a saturated transition says nothing about the command's effect (the actuators ignored it):
        # neither learn from it nor adapt the gains after it
        usable = memory.started and not memory.previous_saturated
        if usable:  # learn the last transition (SPEC 3.7, online)
            z_normalised = [z / s for z, s in zip(memory.previous_input, options.input_scales, strict=True)]
            target = [
                d / s for d, s in zip(body_increment(memory.previous_pose, y), options.output_scales, strict=True)
            ]
            train_step(memory.network, memory.velocity, z_normalised, target, options)

        gains = memory.gains
        if usable and math.hypot(error[0], error[1]) < options.gate_error and t >= options.freeze_time:  # SPEC 3.6
            v_c, omega_c = kanayama(error, v, omega, ref, *gains)[:2]  # the current gains' command, clamped
            jacobian = emulator_jacobian(
                memory.network, options, [clamp(v_c, limits[0]), clamp(omega_c, limits[1]), v, omega]
            )
            gradient = gain_gradient(error, ref[3], options.gamma, jacobian)
            for i in range(3):  # eq. 26 made implementable: momentum, leakage, clip, box (SPEC 3.6)
                change = (
                    -tc * options.rates[i] * gradient[i]
                    + options.gain_momentum * memory.last_step[i]
                    - tc * options.leakage * (gains[i] - options.gains[i])
                )
                memory.last_step[i] = clamp(change, options.max_step[i])
                gains[i] = min(max(gains[i] + memory.last_step[i], options.gain_min[i]), options.gain_max[i])
        else:
            memory.last_step = [0.0, 0.0, 0.0]  # a closed gate also stops the gain momentum

        v_c, omega_c, v_c_dot, omega_c_dot, saturated = clamp_command(*kanayama(error, v, omega, ref, *gains), *limits)
        tau_r, tau_l = unsaturated_torque(nominal, v, omega, v_c, omega_c, v_c_dot, omega_c_dot, options.kc)
        memory.previous_saturated = saturated or abs(tau_r) > nominal.max_torque or abs(tau_l) > nominal.max_torque
        memory.previous_pose, memory.previous_input, memory.started = (y[0], y[1], y[2]), [v_c, omega_c, v, omega], True
        return (clamp(tau_r, nominal.max_torque), clamp(tau_l, nominal.max_torque)), memory

    return step


# --- the closed loop -----------------------------------------------------------------------------


def simulate(
    step: Callable,
    memory: Any,
    plant: Robot,
    disturbance: Disturbance,
    line: Line,
    x0: State,
    *,
    n_steps: int,
    control_period: float,
    substeps: int,
) -> list[State]:
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
        inputs = (tau_r, tau_l, dist_r, dist_l)
        state = rk4(lambda z, u=inputs: derivative(plant, z, *u), state, control_period, substeps)
    return states


def run_backstepping(
    *,
    plant: Robot,
    nominal: Robot,
    disturbance: Disturbance,
    line: Line,
    x0: State,
    gains: BacksteppingGains,
    n_steps: int,
    control_period: float,
    substeps: int,
) -> list[State]:
    """One backstepping run; the keyword arguments are what :func:`params_from_scenario` returns."""
    return simulate(
        backstepping_step(nominal, gains),
        (),
        plant,
        disturbance,
        line,
        x0,
        n_steps=n_steps,
        control_period=control_period,
        substeps=substeps,
    )


def run_nn_adaptive(
    *,
    plant: Robot,
    nominal: Robot,
    disturbance: Disturbance,
    line: Line,
    x0: State,
    adaptive: AdaptiveOptions,
    network: Network,
    n_steps: int,
    control_period: float,
    substeps: int,
) -> list[State]:
    """One NN-adaptive run; the keyword arguments are what :func:`params_from_nn_setup` returns.
    ``network`` holds the emulator's initial weights; it is copied, so every run starts from them."""
    memory = AdaptiveMemory(gains=list(adaptive.gains), network=network.copy(), velocity=network.zeros())
    return simulate(
        nn_adaptive_step(nominal, adaptive),
        memory,
        plant,
        disturbance,
        line,
        x0,
        n_steps=n_steps,
        control_period=control_period,
        substeps=substeps,
    )


# --- reading a ddtrack scenario ------------------------------------------------------------------


def _robot(params: Any) -> Robot:
    return Robot(**{name: float(getattr(params, name)) for name in Robot.__dataclass_fields__})


# the NN-adaptive options this loop implements: the defaults of ddtrack's NNAdaptiveConfig
NN_CHOICES = {
    "jacobian": "network",
    "error_jacobian": "exact",
    "emulator": "E1",
    "online_learning": True,
    "learn_saturated": False,
    "structured_jacobian": False,
}


def params_from_scenario(scenario: Any) -> dict[str, Any]:
    """The keyword arguments of :func:`run_backstepping` from a loaded ``ddtrack.Scenario``.

    Refuses, loudly, what this loop does not implement (so a comparison is never silently unfair).
    """
    params = _loop_params(scenario, "backstepping", [])
    control = scenario.controller
    kx, ky, ktheta = control.gains
    params["gains"] = BacksteppingGains(
        kx=kx,
        ky=ky,
        ktheta=ktheta,
        kc=tuple(control.kc),
        max_velocity=control.max_velocity,
        max_yaw_rate=control.max_yaw_rate,
    )
    return params


def params_from_nn_setup(scenario: Any, setup: Any) -> dict[str, Any]:
    """The keyword arguments of :func:`run_nn_adaptive` from a loaded NN-adaptive ``ddtrack.Scenario`` and
    its ``ddtrack.prepare(scenario)[0]``: the emulator's weights (drawn from the seed, or identified), its
    scales and c_bar are taken from the setup's controller as lists of floats; everything per step is then
    this module's. Refuses, loudly, the options this loop does not implement.
    """
    control = scenario.controller
    unsupported = [
        f"controller.{name} = {getattr(control, name)!r}"
        for name, value in NN_CHOICES.items()
        if getattr(control, name, value) != value
    ]
    params = _loop_params(scenario, "nn_adaptive_backstepping", unsupported)
    law = setup.controller.outer
    floats = lambda values: tuple(float(x) for x in values)  # noqa: E731
    mlp = law.emulator.mlp
    params["network"] = Network(w1=mlp.w1.tolist(), b1=mlp.b1.tolist(), w2=mlp.w2.tolist(), b2=mlp.b2.tolist())
    params["adaptive"] = AdaptiveOptions(
        gains=floats(law.gains),
        kc=floats(control.kc),
        max_velocity=float(law.max_velocity),
        max_yaw_rate=float(law.max_yaw_rate),
        control_period=float(law.control_period),
        rates=floats(law.rates),
        gain_momentum=float(law.gain_momentum),
        max_step=floats(law.max_step),
        gain_min=floats(law.gain_min),
        gain_max=floats(law.gain_max),
        gate_error=float(law.gate_error),
        leakage=float(law.leakage),
        gamma=floats(law.gamma),
        learning_rate=float(law.learning_rate),
        momentum=float(law.momentum),
        clip_norm=float(law.gradient_clip),
        freeze_time=float(law.freeze_time),
        input_scales=floats(law.emulator.scales.inputs),
        output_scales=floats(law.emulator.scales.outputs),
        jacobian_scale=float(law.analytic_coefficients[0]),
    )
    return params


def _loop_params(scenario: Any, controller: str, unsupported: list[str]) -> dict[str, Any]:
    """The plant, nominal model, disturbance, line, initial state and time grid of a run of ``controller``
    (a ``controller.kind``); raises on anything this module does not implement, ``unsupported`` included."""
    unsupported = list(unsupported)
    if scenario.trajectory.kind != "line":
        unsupported.append(f"trajectory.kind = {scenario.trajectory.kind!r} (only 'line')")
    if scenario.controller.kind != controller or scenario.controller.inner != "computed_torque":
        unsupported.append(f"a controller other than {controller} over computed_torque")
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
    disturbance = Disturbance(
        bias=tuple(map(float, wheel.bias)),
        amplitude=tuple(map(float, wheel.amplitude)),
        frequency=float(wheel.frequency),
        phase=tuple(map(float, wheel.phase)),
    )
    trajectory = scenario.trajectory
    pose = scenario.initial.pose
    if pose is None:  # start on the reference
        ref0 = line_reference(Line(tuple(trajectory.start), trajectory.heading, trajectory.speed), 0.0)
        pose = ref0[:3]
    sim = scenario.simulation
    return {
        "plant": _robot(scenario.plant_params()),
        "nominal": _robot(scenario.robot.params()),
        "disturbance": disturbance,
        "line": Line(start=tuple(trajectory.start), heading=float(trajectory.heading), speed=float(trajectory.speed)),
        "x0": (*map(float, pose), *map(float, scenario.initial.velocity)),
        "n_steps": sim.n_steps,
        "control_period": sim.control_period,
        "substeps": sim.substeps,
    }


# --- the whole process: a plain script of the case ------------------------------------------------


def params_from_toml(path: str | Path) -> dict[str, Any]:
    """:func:`params_from_scenario` for a backstepping line scenario read by ``tomllib`` alone (no ddtrack, no
    NumPy), as a plain script would; its left-out plant keys take the [robot] values and friction defaults to 0."""
    with open(path, "rb") as file:
        doc = tomllib.load(file)
    robot_keys = ("mass", "inertia", "com_offset", "wheel_radius", "half_axle")
    defaults = {"viscous_friction": 0.0, "coulomb_friction": 0.0, "friction_smoothing": 0.01, "max_torque": 10.0}
    nominal = {**defaults, **{k: float(v) for k, v in doc["robot"].items() if k in Robot.__dataclass_fields__}}
    missing = [f"robot.{k}" for k in robot_keys if k not in nominal]
    control, trajectory, disturbance = doc["controller"], doc["trajectory"], doc.get("disturbance", {"kind": "none"})
    unsupported = [
        f"{name} = {value!r}"
        for name, value, wanted in (
            ("controller.kind", control.get("kind"), "backstepping"),
            ("controller.inner", control.get("inner"), "computed_torque"),
            ("trajectory.kind", trajectory.get("kind"), "line"),
            ("disturbance.kind", disturbance.get("kind"), "sinusoid"),
        )
        if value != wanted
    ] + [f"[{section}]" for section in ("noise", "randomize") if doc.get(section)]
    missing += [f"controller.{k}" for k in ("gains", "kc", "max_velocity", "max_yaw_rate") if k not in control]
    if missing or unsupported or doc.get("initial", {}).get("pose") is None:
        raise ValueError(
            f"bench/python_loop.py reads only the paper's line case; missing {missing}, "
            f"unsupported {unsupported} (and initial.pose must be given)"
        )
    plant = {**nominal, **{k: float(v) for k, v in doc.get("plant", {}).items() if k in Robot.__dataclass_fields__}}
    sim = doc["simulation"]
    kx, ky, ktheta = map(float, control["gains"])
    pair = lambda values: (float(values[0]), float(values[1]))  # noqa: E731
    return {
        "plant": Robot(**plant),
        "nominal": Robot(**nominal),
        "disturbance": Disturbance(
            bias=pair(disturbance.get("bias", (0, 0))),
            amplitude=pair(disturbance["amplitude"]),
            frequency=float(disturbance["frequency"]),
            phase=pair(disturbance.get("phase", (0, 0))),
        ),
        "line": Line(
            start=pair(trajectory["start"]), heading=float(trajectory["heading"]), speed=float(trajectory["speed"])
        ),
        "x0": (*map(float, doc["initial"]["pose"]), *map(float, doc["initial"].get("velocity", (0, 0)))),
        "gains": BacksteppingGains(
            kx=kx,
            ky=ky,
            ktheta=ktheta,
            kc=pair(control["kc"]),
            max_velocity=float(control["max_velocity"]),
            max_yaw_rate=float(control["max_yaw_rate"]),
        ),
        "n_steps": round(float(sim["duration"]) / float(sim["control_period"])),
        "control_period": float(sim["control_period"]),
        "substeps": int(sim.get("substeps", 1)),
    }


def main(argv: list[str] | None = None) -> int:
    """``python bench/python_loop.py [SCENARIO] [--out states.csv]``: the case as a whole plain-Python process
    (read the TOML, simulate, write the states, print the final tracking error): bench/speed.py's baseline for
    the ``ddtrack run`` command."""
    parser = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    parser.add_argument(
        "scenario", nargs="?", default=Path(__file__).resolve().parent.parent / "scenarios" / "paper_line.toml"
    )
    parser.add_argument("--out", help="CSV file of the states: t, x, y, theta, v, omega")
    args = parser.parse_args(argv)
    params = params_from_toml(args.scenario)
    states = run_backstepping(**params)
    if args.out:
        with open(args.out, "w", newline="") as file:
            writer = csv.writer(file)
            writer.writerow(("t", "x", "y", "theta", "v", "omega"))
            writer.writerows((k * params["control_period"], *state) for k, state in enumerate(states))
    t_end = (len(states) - 1) * params["control_period"]
    x_r, y_r, *_ = line_reference(params["line"], t_end)
    print(f"e_tr at t = {t_end:g} s: {math.hypot(states[-1][0] - x_r, states[-1][1] - y_r):.4f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
