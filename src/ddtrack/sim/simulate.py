"""The closed-loop simulator: one ``jax.lax.scan`` over control periods (docs/architecture.md, model.md §2.7)."""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from ..geometry import posture_error
from ..model import MeasurementNoise, Plant, WheelDisturbance
from ..precision import require_float64
from ..trajectories import Trajectory
from .integrators import rk4
from .result import SimResult

SCAN_UNROLL = 4


class Draws(NamedTuple):
    """The run's randomness, drawn before it from one seed (so the run itself is deterministic).

    Attributes
    ----------
    disturbance
        (N, 2) standard-normal draws for the Gaussian wheel-torque disturbance, one per period
    noise
        (N, 5) standard-normal draws for the measurement noise, one per period
    controller_key
        the PRNG key handed to ``controller.init`` (e.g. an MPPI sampler, dither)
    """

    disturbance: Array  #: (N, 2) standard-normal draws for the Gaussian disturbance, one per period
    noise: Array  #: (N, 5) standard-normal draws for the measurement noise
    controller_key: Array  #: PRNG key handed to ``controller.init``

    @staticmethod
    def zeros(n_steps: int) -> Draws:
        """No randomness: for deterministic studies and tests."""
        return Draws(jnp.zeros((n_steps, 2)), jnp.zeros((n_steps, 5)), jax.random.PRNGKey(0))


DIVERGENCE_SPEED = 50.0  #: |v| [m/s] or |omega| [rad/s] beyond which a run has diverged, unless a caller says otherwise


def plant_period(
    plant: Plant,
    x: Array,
    u: Array,
    t: Array,
    xi_disturbance: Array,
    *,
    disturbance: WheelDisturbance,
    control_period: Array | float,
    substeps: int,
) -> tuple[Array, Array]:
    """Advance the plant over one control period under the held input: the simulator's own step.

    ``u = plant.saturate(u)``; ``d = disturbance.torque(t, xi_disturbance)``; then ``substeps`` RK4 steps of
    ``plant.derivative(., u, d)`` from ``plant.hold(x, u)`` over ``control_period``, both held (zero-order hold).
    :func:`simulate` and the Gymnasium environment (``ddtrack.envs``) both call it, so they step alike.

    Parameters
    ----------
    plant
        a ``ddtrack.model.Plant``
    x
        (5,) state x_k = [x, y, theta, v, omega] at t_k [m, m, rad, m/s, rad/s]
    u
        (2,) plant input before saturation: wheel torques [N m], or (v, omega) for a kinematic plant
    t
        t_k [s]
    xi_disturbance
        (2,) this period's standard-normal disturbance draw
    disturbance
        the wheel-torque disturbance
    control_period
        T_c [s]
    substeps
        RK4 steps per period (static under ``jit``)

    Returns
    -------
    tuple of Array
        ``(u, x_next)``: the saturated input actually held [N m or m/s, rad/s], and x_{k+1}
    """
    u = plant.saturate(u)
    tau_d = disturbance.torque(t, xi_disturbance)
    x_next = rk4(lambda z: plant.derivative(z, u, tau_d), plant.hold(x, u), control_period, substeps)
    return u, x_next


def period_status(
    x: Array,
    x_next: Array,
    u: Array,
    error: Array,
    *,
    divergence_error: Array | float = 50.0,
    divergence_speed: Array | float = DIVERGENCE_SPEED,
) -> Array:
    """The status of one control period (``STATUS_NAMES``): 2 (``non_finite``) when x_{k+1} or the held input
    is not finite, else 1 (``diverged``) when the tracking error |(e_x, e_y)| of x_k exceeds
    ``divergence_error`` [m] or |v| [m/s] or |omega| [rad/s] of x_k exceeds ``divergence_speed``, else 0 (``ok``).

    ``error`` is the posture error of x_k (model.md §2.2); ``u`` the saturated input (:func:`plant_period`).
    """
    finite = jnp.all(jnp.isfinite(x_next)) & jnp.all(jnp.isfinite(u))
    too_far = (jnp.hypot(error[0], error[1]) > divergence_error) | jnp.any(jnp.abs(x[3:5]) > divergence_speed)
    return jnp.where(finite, jnp.where(too_far, 1, 0), 2)


@partial(jax.jit, static_argnames=("n_steps", "substeps"))
def simulate(
    plant: Plant,
    controller: Any,
    trajectory: Trajectory,
    x0: Array,
    draws: Draws,
    *,
    n_steps: int,
    control_period: float = 0.01,
    substeps: int = 10,
    disturbance: WheelDisturbance = WheelDisturbance(),
    noise: MeasurementNoise = MeasurementNoise(),
    divergence_error: float = 50.0,
    divergence_speed: float = DIVERGENCE_SPEED,
) -> SimResult:
    """Simulate ``n_steps`` control periods of ``controller`` on ``plant`` tracking ``trajectory``.

    One control period, exactly::

        for k in 0 .. N-1:                      t_k = k * T_c
            ref_k      = trajectory(t_k)
            y_k        = x_k + noise_std * xi_k          what the controller sees
            u_k, m     = controller.step(t_k, y_k, ref_k, m)
            u_k, x_{k+1} = plant_period(plant, x_k, u_k, t_k, draw_k):
                u_k      = plant.saturate(u_k)
                d_k      = disturbance(t_k, draw_k)
                x_{k+1}  = substeps x rk4(plant.derivative(., u_k, d_k), plant.hold(x_k, u_k), T_c / substeps)
            status_k   = period_status(x_k, x_{k+1}, u_k, e_p(x_k, ref_k))
            record x_k, ref_k, e_p(x_k, ref_k), u_k, logs_k

    Failure is a status, never an exception: the first k with a non-finite control or next state
    sets ``non_finite``; the first k whose tracking error exceeds ``divergence_error`` [m], or whose
    |v| [m/s] or |omega| [rad/s] exceeds ``divergence_speed``, sets ``diverged``. From then on the
    state and the controller's memory are frozen.

    Parameters
    ----------
    plant, controller, trajectory
        pytrees following their protocols (``ddtrack.model.Plant``,
        ``ddtrack.controllers.Controller``, ``ddtrack.trajectories.Trajectory``)
    x0
        (5,) initial state [x, y, theta, v, omega]
    draws
        the run's random draws (:class:`Draws`), shapes (n_steps, 2) and (n_steps, 5)
    n_steps
        number of control periods N (static)
    control_period
        T_c [s]
    substeps
        RK4 steps per control period (static)
    disturbance, noise
        the wheel-torque disturbance and the pose-measurement noise
    divergence_error, divergence_speed
        thresholds of the ``diverged`` status [m], [m/s or rad/s]

    Returns
    -------
    SimResult
        the recorded series (states, references, errors, controls, logs; N rows each), the status and the
        index of the failing period (-1 when none)
    """
    require_float64()
    x0 = jnp.asarray(x0, dtype=float)
    memory0 = controller.init(x0, trajectory(0.0), draws.controller_key)

    def period(carry, inputs):
        x, memory, status, failure_index = carry
        k, xi_disturbance, xi_noise = inputs
        t = k * control_period
        ref = trajectory(t)
        y = noise.measure(x, xi_noise)
        u, next_memory, logs = controller.step(t, y, ref, memory)
        u, x_next = plant_period(
            plant, x, u, t, xi_disturbance, disturbance=disturbance, control_period=control_period, substeps=substeps
        )
        error = posture_error(x[0], x[1], x[2], ref.x, ref.y, ref.theta)

        running = status == 0
        new_status = jnp.where(
            running,
            period_status(x, x_next, u, error, divergence_error=divergence_error, divergence_speed=divergence_speed),
            status,
        )
        failure_index = jnp.where(running & (new_status != 0), k, failure_index)
        keep = new_status == 0
        x_next = jnp.where(keep, x_next, x)
        next_memory = jax.tree_util.tree_map(lambda new, old: jnp.where(keep, new, old), next_memory, memory)
        torques = {"tau_r": u[0], "tau_l": u[1]} if plant.input_kind == "torque" else {}
        record = (x, ref, error, u, {name: jnp.asarray(value, float) for name, value in (logs | torques).items()})
        return (x_next, next_memory, new_status, failure_index), record

    steps = jnp.arange(n_steps)
    carry0 = (x0, memory0, jnp.asarray(0), jnp.asarray(-1))
    # unroll=4: a third less per-step loop overhead on CPU at no compile cost (docs/benchmarks.md)
    (_, _, status, failure_index), (states, refs, errors, controls, logs) = jax.lax.scan(
        period, carry0, (steps, draws.disturbance, draws.noise), unroll=SCAN_UNROLL
    )
    return SimResult(steps * control_period, states, refs, errors, controls, logs, status, failure_index)
