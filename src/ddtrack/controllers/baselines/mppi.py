"""MPPI: Model Predictive Path Integral control on the nominal dynamic model, wheel torques as the control.

Williams, Wagener, Goldfain, Drews, Rehg, Boots & Theodorou (2017), "Information theoretic MPC for
model-based reinforcement learning", ICRA 2017, Algorithm 2 (MPPI), with the costs below; the
structure (warm-started sequence, shift, softmin weights over sampled rollouts) is also that of
Nav2's MPPI controller. One control period, from the measured state y and the
sequence U = (tau_0 .. tau_{H-1}) kept in memory, each tau_i held for ``model_step`` dt::

    key, sub  = split(key)
    eps_k     ~ N(0, diag(sigma^2)) per step,  k = 0 .. K-1 (eps_0 = 0: the previous plan is a candidate)
    V_k       = clip(U + eps_k, +-tau_max)                     what the saturated plant would get
    S_k       = sum_i c(x_{k,i+1}, tau_{k,i}) + phi(x_{k,H})   rollout on the nominal model (vmap over k)
    w_k       = exp(-(S_k - min S) / lambda) / sum             softmin (information-theoretic) weights
    U         = sum_k w_k V_k;  apply tau = U_0
    U         <- U shifted by T_c (linear interpolation between elements; the last one is held)

Model: the nominal reduced dynamics (model.md §1.3, ``body_acceleration`` with zero disturbance, the
nominal friction) integrated by semi-implicit Euler at dt. Cost, against the reference trajectory
itself at t + dt, .. t + H dt (a tracking MPC previews the reference, as Nav2's MPPI previews its
path), with e_p the position error, e_th the wrapped heading error and e_nu = nu - nu_r::

    c   = q_p |e_p|^2 + q_th e_th^2 + q_nu |e_nu|^2 + r |tau|^2 + q_lim (relu(|v| - v_max)^2 + relu(|w| - w_max)^2)
    phi = q_T (q_p |e_p|^2 + q_th e_th^2)

The q_lim term is a soft version of the velocity clamps of the other controllers (Nav2's constraint
critic): torques alone would otherwise race the robot at 10 m/s towards a reference 7 m away.

We leave out the lambda u^T Sigma^-1 eps term of Williams et al.'s cost: the effort weight r already
penalises large torques, and without it a zero-noise sample's cost is that of the previous plan.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array
from pydantic import Field

from ..._ordered import total
from ..._pytree import FloatVector, pytree_dataclass
from ...geometry import wrap_angle
from ...integrators import semi_implicit_euler_step
from ...layout import pose_vector, velocity
from ...model import RobotParams, body_acceleration, pose_rate
from ...parameters import NonNegative, Parameters, Positive, Structure, Timing, declared
from ...trajectories import Reference, Trajectory
from ..base import Logs


class MPPIMemory(NamedTuple):
    """What MPPI carries from one control period to the next: its plan and its sampling key."""

    sequence: Array  #: (H, 2) planned wheel torques [N m], element i held over [i dt, (i + 1) dt)
    key: Array  #: PRNG key of the sampling noise, split every control period


def preview(trajectory: Trajectory, t: Array, horizon: int, dt: float) -> Array:
    """(H, 5) reference [x, y, theta, v, omega] at t + dt, t + 2 dt, .. t + H dt."""
    ref = jax.vmap(trajectory)(t + dt * jnp.arange(1, horizon + 1))
    return jnp.stack([ref.x, ref.y, ref.theta, ref.v, ref.omega], axis=1)


def rollout(nominal: RobotParams, state: Array, sequence: Array, dt: float) -> Array:
    """(H, 5) states after each held torque of ``sequence`` (H, 2), semi-implicit Euler on the nominal model."""

    def advance(x, tau):
        # the heading moves with the updated yaw rate, the position with the updated speed and the old heading
        pose, nu = semi_implicit_euler_step(
            lambda q, nu: body_acceleration(nominal, nu, tau, jnp.zeros(2)),
            lambda q, nu, h: pose_rate(q[2], h * nu[0], h * nu[1]),
            pose_vector(x),
            velocity(x),
            dt,
        )
        x = jnp.concatenate([pose, nu])
        return x, x

    return jax.lax.scan(advance, state, sequence)[1]


class MPPIParameters(Parameters):
    """MPPI's parameters (Williams et al. 2017): the sampling and the cost."""

    samples: Structure[int] = Field(64, ge=1, le=10_000, description="K: torque sequences sampled per control period.")
    horizon: Structure[int] = Field(20, ge=1, le=500, description="H: steps per sequence.")
    model_step: Positive = Field(
        0.05,
        le=10.0,
        description=("dt: how long each step of a sequence holds its torque, and the rollout's Euler step [s]."),
    )
    temperature: Positive = Field(
        1.0,
        description=(
            "lambda of the weights exp(-(S - min S) / lambda), in cost units: lower trusts the best samples more."
        ),
    )
    noise_std: tuple[Positive, Positive] = Field(
        (0.2, 0.2), description=("sigma of the sampled torque perturbations, [right, left] wheel [N m].")
    )
    position_weight: NonNegative = Field(100.0, description="q_p of the squared position error, per step [1/m^2].")
    heading_weight: NonNegative = Field(1.0, description="q_th of the squared heading error, per step [1/rad^2].")
    velocity_weight: NonNegative = Field(1.0, description=("q_nu of |nu - nu_r|^2, per step [s^2/m^2 and s^2/rad^2]."))
    effort_weight: NonNegative = Field(0.01, description="r of the squared wheel torques, per step [1/(N m)^2].")
    terminal_weight: NonNegative = Field(
        10.0, description=("q_T: the last step's position and heading terms count again, times this.")
    )
    limit_weight: NonNegative = Field(
        1000.0,
        description=("q_lim of the squared excess of |v| over max_velocity and |omega| over max_yaw_rate, per step."),
    )
    max_velocity: Positive = Field(2.0, description="Soft limit on |v| of the rollouts [m/s].")
    max_yaw_rate: Positive = Field(4.0, description="Soft limit on |omega| of the rollouts [rad/s].")


@pytree_dataclass
class MPPICost:
    """Weights of the MPPI cost (module docstring): q_p [1/m^2], q_th [1/rad^2], q_nu [per (m/s)^2 and
    (rad/s)^2], r [1/(N m)^2], q_T (multiplies the final position and heading terms), q_lim [per (m/s)^2
    and (rad/s)^2] beyond the soft limits v_max [m/s] and w_max [rad/s]."""

    position: float = declared(MPPIParameters, "position_weight")
    heading: float = declared(MPPIParameters, "heading_weight")
    velocity: float = declared(MPPIParameters, "velocity_weight")
    effort: float = declared(MPPIParameters, "effort_weight")
    terminal: float = declared(MPPIParameters, "terminal_weight")
    limit: float = declared(MPPIParameters, "limit_weight")
    max_velocity: float = declared(MPPIParameters)
    max_yaw_rate: float = declared(MPPIParameters)

    def __call__(self, states: Array, torques: Array, reference: Array) -> Array:
        # written out, not jnp.sum: XLA rounded that reduce differently by batch size (ddtrack._ordered)
        squared_norm = lambda pairs: pairs[:, 0] ** 2 + pairs[:, 1] ** 2  # noqa: E731
        position = squared_norm(states[:, 0:2] - reference[:, 0:2])
        heading = wrap_angle(reference[:, 2] - states[:, 2]) ** 2
        velocity = squared_norm(states[:, 3:5] - reference[:, 3:5])
        tracking = self.position * position + self.heading * heading
        excess = jax.nn.relu(jnp.abs(states[:, 3:5]) - jnp.stack([self.max_velocity, self.max_yaw_rate]))
        stage = (
            tracking
            + self.velocity * velocity
            + self.effort * squared_norm(torques)
            + self.limit * squared_norm(excess)
        )
        return total(stage) + self.terminal * tracking[-1]


@pytree_dataclass
class MPPI:
    """MPPI over wheel torques on the nominal model (module docstring; Williams et al. 2017).

    In: time t [s] and measured state y = [x, y, theta, v, omega]; the reference comes from
    ``trajectory`` over the horizon. Out: wheel torques [N m] within the nominal ``max_torque``.
    ``samples`` K, ``horizon`` H (static: they fix array shapes); ``model_step`` dt [s];
    ``control_period`` T_c [s]; ``temperature`` lambda (cost units); ``noise_std`` sigma per wheel
    [N m]; ``cost`` the weights. Memory: the plan and a PRNG key (the one handed to ``init``), so a
    run is deterministic per seed. Logs: ``v_cmd``, ``omega_cmd`` (the plan's velocity one model step
    ahead [m/s, rad/s]), ``mppi_cost`` (the new plan's cost), ``saturated`` (1.0 when at least half the
    samples' first torques were clipped at the limit).
    """

    nominal: RobotParams
    trajectory: Trajectory
    cost: MPPICost = MPPICost()
    model_step: float = declared(MPPIParameters)
    control_period: float = declared(Timing)
    temperature: float = declared(MPPIParameters)
    noise_std: FloatVector = declared(MPPIParameters)
    samples: int = declared(MPPIParameters)
    horizon: int = declared(MPPIParameters)
    output_kind: ClassVar[str] = "torque"  #: what it hands the plant

    def init(self, x0: Array, ref0: Reference, key: Array) -> MPPIMemory:
        return MPPIMemory(jnp.zeros((self.horizon, 2)), key)

    def plan(self, t: Array, y: Array, sequence: Array, key: Array) -> tuple[Array, Array, Array]:
        """One MPPI update of ``sequence`` from state ``y`` at time ``t``: the new plan, the sampled costs (K,)
        and the fraction of samples whose first torque was clipped at the limit."""
        limit = self.nominal.max_torque
        noise = jax.random.normal(key, (self.samples, self.horizon, 2)) * jnp.asarray(self.noise_std)
        unclipped = sequence + noise.at[0].set(0.0)
        candidates = jnp.clip(unclipped, -limit, limit)
        clipped = jnp.mean(jnp.any(jnp.abs(unclipped[:, 0]) > limit, axis=-1))
        reference = preview(self.trajectory, t, self.horizon, self.model_step)
        costs = jax.vmap(lambda u: self.cost(rollout(self.nominal, y, u, self.model_step), u, reference))(candidates)
        weights = jnp.exp(-(costs - jnp.min(costs)) / self.temperature)
        weights = weights / total(weights)  # softmax, its sum in a fixed order
        return jnp.tensordot(weights, candidates, axes=1), costs, clipped

    def sequence_cost(self, t: Array, y: Array, sequence: Array) -> Array:
        """The cost S of one torque sequence (H, 2) from state ``y`` at time ``t``."""
        states = rollout(self.nominal, y, sequence, self.model_step)
        return self.cost(states, sequence, preview(self.trajectory, t, self.horizon, self.model_step))

    def step(self, t: Array, y: Array, ref: Reference, memory: MPPIMemory) -> tuple[Array, MPPIMemory, Logs]:
        key, sub = jax.random.split(memory.key)
        sequence, _, clipped = self.plan(t, y, memory.sequence, sub)
        states = rollout(self.nominal, y, sequence, self.model_step)
        cost = self.cost(states, sequence, preview(self.trajectory, t, self.horizon, self.model_step))
        tau = sequence[0]
        # the plan T_c later: element i now starts at i dt + T_c (linear in between, the last one held)
        index = jnp.arange(self.horizon, dtype=float)
        shifted = jax.vmap(
            lambda u: jnp.interp(index + self.control_period / self.model_step, index, u), in_axes=1, out_axes=1
        )(sequence)
        saturated = (clipped >= 0.5).astype(tau.dtype)  # the plan presses against the limit
        logs = {"v_cmd": states[0, 3], "omega_cmd": states[0, 4], "mppi_cost": cost, "saturated": saturated}
        return tau, MPPIMemory(shifted, key), logs
