"""The closed-loop simulator: one ``jax.lax.scan`` over control periods (docs/architecture.md, model.md §2.7)."""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from .._pytree import pytree_dataclass, static_field
from ..geometry import posture_error
from ..integrators import RK4, Solver
from ..layout import BODY, POSTURE_ERROR, VELOCITY_COMMAND, WHEEL_TORQUES, Layout, pose, velocity
from ..model import MeasurementNoise, Plant, WheelDisturbance
from ..parameters import Timing, declared
from ..precision import require_float64
from .result import SimResult

SCAN_UNROLL = 2


class Draws(NamedTuple):
    """The run's randomness, drawn before it from one seed (so the run itself is deterministic).

    Attributes
    ----------
    disturbance
        (N, 2) standard-normal draws for the Gaussian wheel-torque disturbance, one per period (its channels are
        :data:`~ddtrack.layout.WHEEL_TORQUES`, whatever the plant)
    noise
        (N, 5) standard-normal draws for the measurement noise, one per period, on what every plant reports
        (:data:`~ddtrack.layout.BODY`), so a plant with more states draws the same numbers
    controller_key
        the PRNG key handed to ``controller.init`` (e.g. an MPPI sampler, dither)
    """

    disturbance: Array  #: (N, 2) standard-normal draws for the Gaussian disturbance, one per period
    noise: Array  #: (N, 5) standard-normal draws for the measurement noise
    controller_key: Array  #: PRNG key handed to ``controller.init``

    @staticmethod
    def zeros(n_steps: int) -> Draws:
        """No randomness: for deterministic studies and tests."""
        return Draws(jnp.zeros((n_steps, len(WHEEL_TORQUES))), jnp.zeros((n_steps, len(BODY))), jax.random.PRNGKey(0))


DIVERGENCE_SPEED = 50.0  #: |v| [m/s] or |omega| [rad/s] beyond which a run has diverged, unless a caller says otherwise
DIVERGENCE_ERROR = 50.0  #: the tracking error [m] beyond which a run has diverged, unless a caller says otherwise


def plant_period(
    plant: Plant,
    x: Array,
    u: Array,
    t: Array,
    xi_disturbance: Array,
    *,
    disturbance: WheelDisturbance,
    control_period: Array | float,
    solver: Solver,
) -> tuple[Array, Array]:
    """Advance the plant over one control period under the held input: the simulator's own step.

    ``u = plant.saturate(u)``; ``d = disturbance.torque(t, xi_disturbance)``; then ``plant.advance(x, u, d,
    control_period, solver)``, both held (zero-order hold; an ODE plant takes ``solver.substeps`` of its steps).
    :func:`simulate` and the Gymnasium environment (``ddtrack.envs``) both call it, so they step alike.

    Parameters
    ----------
    plant
        a ``ddtrack.model.Plant``
    x
        the plant's state x_k at t_k (its ``state_layout``)
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
    solver
        the :class:`~ddtrack.integrators.Solver` the plant is integrated with, e.g. ``RK4(10)`` (static under ``jit``)

    Returns
    -------
    tuple of Array
        ``(u, x_next)``: the saturated input actually held [N m or m/s, rad/s], and x_{k+1}
    """
    u = plant.saturate(u)
    tau_d = disturbance.torque(t, xi_disturbance)
    return u, plant.advance(x, u, tau_d, control_period, solver)


def period_status(
    body: Array,
    x_next: Array,
    u: Array,
    error: Array,
    *,
    divergence_error: Array | float = DIVERGENCE_ERROR,
    divergence_speed: Array | float = DIVERGENCE_SPEED,
) -> Array:
    """The status of one control period (``STATUS_NAMES``): 2 (``non_finite``) when x_{k+1} or the held input
    is not finite, else 1 (``diverged``) when the tracking error |(e_x, e_y)| of x_k exceeds
    ``divergence_error`` [m] or |v| [m/s] or |omega| [rad/s] of x_k exceeds ``divergence_speed``, else 0 (``ok``).

    ``body`` is x_k as the plant observes it (a :data:`~ddtrack.layout.BODY` vector, no noise), ``error`` its posture
    error (model.md §2.2); ``u`` the saturated input (:func:`plant_period`).
    """
    finite = jnp.all(jnp.isfinite(x_next)) & jnp.all(jnp.isfinite(u))
    e_x, e_y = POSTURE_ERROR.read(error, "e_x"), POSTURE_ERROR.read(error, "e_y")
    too_far = (jnp.hypot(e_x, e_y) > divergence_error) | jnp.any(jnp.abs(velocity(body)) > divergence_speed)
    return jnp.where(finite, jnp.where(too_far, 1, 0), 2)


@pytree_dataclass
class ClosedLoop:
    """One run's loop without its randomness: the one description every simulation takes (:func:`simulate`, its
    batched forms, the Gymnasium environment's episode). Its :meth:`period` is the one control period that
    :func:`simulate`'s scan and the environment both step; nothing in it changes during a run.

    ``ClosedLoop(plant, controller, trajectory)`` is a run with no disturbance, no noise, the declared timing (RK4 in
    10 steps a period) and the default divergence bounds; ``dataclasses.replace(loop, controller=...)`` changes one
    part. For a batch (:func:`~ddtrack.sim.simulate_batch`) every leaf carries a leading run axis, numbers included
    (each run may have its own control period or bound): :func:`ddtrack.sim.stack` stacks single loops, and
    :func:`ddtrack.sim.repeated` repeats one loop's numbers over an already stacked batch.

    Attributes
    ----------
    plant
        a ``ddtrack.model.Plant``
    controller
        a ``ddtrack.controllers.Controller``
    trajectory
        a ``ddtrack.trajectories.Trajectory``
    disturbance
        the wheel-torque disturbance (default: none)
    noise
        the pose-measurement noise (default: none)
    control_period
        T_c [s]
    divergence_error
        the tracking error [m] beyond which the run has diverged
    divergence_speed
        the |v| [m/s] or |omega| [rad/s] beyond which the run has diverged
    solver
        how the plant is integrated over a period (:class:`~ddtrack.integrators.Solver`; default
        ``RK4(simulation.substeps)``, 10 steps): its class and step count are part of the compiled program
    """

    plant: Any  #: a ``ddtrack.model.Plant``
    controller: Any  #: a ``ddtrack.controllers.Controller``
    trajectory: Any  #: a ``ddtrack.trajectories.Trajectory``
    disturbance: WheelDisturbance = WheelDisturbance()
    noise: MeasurementNoise = MeasurementNoise()
    control_period: Array | float = declared(Timing)  #: T_c [s]
    divergence_error: Array | float = DIVERGENCE_ERROR  #: [m]
    divergence_speed: Array | float = DIVERGENCE_SPEED  #: [m/s] or [rad/s]
    solver: Solver = RK4()  #: how the plant is integrated over a period (its step count: structure)

    def period(
        self, x: Array, memory: Any, status: Array, k: Array, xi_disturbance: Array, xi_noise: Array
    ) -> tuple[Array, Any, Array, tuple[Array, Any, Array, Array, dict]]:
        """Period k from plant state x_k, the controller's memory and the run's ``status`` so far (0 while it
        runs): x_{k+1}, the next memory and status (both frozen once it failed), and what the period records:
        the observed BODY state b_k, the reference, the posture error e_p(b_k, ref_k), the held input u_k and the
        controller's logs (:func:`simulate`'s docstring)."""
        t = k * self.control_period
        ref = self.trajectory(t)
        body = self.plant.observe(x)
        y = self.noise.measure(measured(self.plant, x), xi_noise)
        u, next_memory, logs = self.controller.step(t, y, ref, memory)
        u, x_next = plant_period(
            self.plant,
            x,
            u,
            t,
            xi_disturbance,
            disturbance=self.disturbance,
            control_period=self.control_period,
            solver=self.solver,
        )
        error = posture_error(*pose(body), ref.x, ref.y, ref.theta)
        new_status = jnp.where(
            status == 0,
            period_status(
                body, x_next, u, error, divergence_error=self.divergence_error, divergence_speed=self.divergence_speed
            ),
            status,
        )
        keep = new_status == 0
        x_next = jnp.where(keep, x_next, x)
        next_memory = jax.tree_util.tree_map(lambda new, old: jnp.where(keep, new, old), next_memory, memory)
        return x_next, next_memory, new_status, (body, ref, error, u, logs)


@pytree_dataclass
class HeldInput:
    """A controller that holds a given plant input over the period: the environment's action, a live robot's
    ``/cmd_vel``; so that stepping them is :meth:`ClosedLoop.period` too. ``output_kind`` (None: unchecked) is what
    :func:`require_matching_input` compares with the plant's input."""

    u: Array  #: (2,) wheel torques [N m] or (v [m/s], omega [rad/s])
    output_kind: str | None = static_field(default=None, why="the plant input it is checked against")

    def init(self, x0: Array, ref0: Any, key: Array) -> tuple[()]:
        return ()

    def step(self, t: Array, y: Array, ref: Any, memory: tuple[()]) -> tuple[Array, tuple[()], dict]:
        return self.u, memory, {}


def period_record(plant: Plant, x: Array, u: Array, logs: dict) -> tuple[dict[str, Array], dict[str, Array]]:
    """What a period records beside BODY, the reference, the error and the input (:func:`simulate`'s scan, a live
    robot's periods): the logged channels (the held velocity command, the controller's ``logs``, the plant's own,
    e.g. the torques a torque-driven plant applied) and the plant's recorded states beyond BODY, by name."""
    channels = commanded(plant, u) | logs | plant.logged(x, u)
    extra = {name: x[plant.state_layout.index(name)] for name in recorded(plant).names if name not in BODY.names}
    return {name: jnp.asarray(value, float) for name, value in channels.items()}, extra


@partial(jax.jit, static_argnames=("n_steps",))
def simulate(loop: ClosedLoop, x0: Array, draws: Draws, *, n_steps: int) -> SimResult:
    """Simulate ``n_steps`` control periods of ``loop``: its controller on its plant tracking its trajectory.

    One control period, exactly (:meth:`ClosedLoop.period`)::

        x_0 = plant.init(x0)
        for k in 0 .. N-1:                      t_k = k * T_c
            ref_k      = trajectory(t_k)
            b_k        = plant.observe(x_k)              the true BODY vector [x, y, theta, v, omega]
            y_k        = plant.measure(x_k) + noise_std * xi_k    what the controller sees (b_k without ``measure``)
            u_k, m     = controller.step(t_k, y_k, ref_k, m)
            u_k, x_{k+1} = plant_period(plant, x_k, u_k, t_k, draw_k):
                u_k      = plant.saturate(u_k)
                d_k      = disturbance(t_k, draw_k)
                x_{k+1}  = plant.advance(x_k, u_k, d_k, T_c, solver)
            status_k   = period_status(b_k, x_{k+1}, u_k, e_p(b_k, ref_k))
            record b_k, ref_k, e_p(b_k, ref_k), u_k, logs_k | plant.logged(x_k, u_k), the other recorded states of x_k

    Failure is a status, never an exception: the first k with a non-finite control or next state
    sets ``non_finite``; the first k whose tracking error exceeds the loop's ``divergence_error`` [m], or whose
    |v| [m/s] or |omega| [rad/s] exceeds its ``divergence_speed``, sets ``diverged``. From then on the
    state and the controller's memory are frozen.

    Parameters
    ----------
    loop
        plant, controller, trajectory, disturbance, noise, timing and bounds (:class:`ClosedLoop`); a controller
        that declares an ``output_kind`` must match the plant's ``input_kind`` (a ValueError names both otherwise)
    x0
        (5,) initial BODY state [x, y, theta, v, omega], from which ``plant.init`` builds the plant's state
    draws
        the run's random draws (:class:`Draws`), shapes (n_steps, 2) and (n_steps, 5)
    n_steps
        number of control periods N (static)

    Returns
    -------
    SimResult
        the recorded series (states, references, errors, controls, logs; N rows each), the status and the
        index of the failing period (-1 when none)
    """
    require_float64()
    plant = loop.plant
    require_matching_input(plant, loop.controller)
    x0 = plant.init(jnp.asarray(x0, dtype=float))
    memory0 = loop.controller.init(measured(plant, x0), loop.trajectory(0.0), draws.controller_key)

    def period(carry, inputs):
        x, memory, status, failure_index = carry
        k, xi_disturbance, xi_noise = inputs
        x_next, next_memory, new_status, (body, ref, error, u, logs) = loop.period(
            x, memory, status, k, xi_disturbance, xi_noise
        )
        failure_index = jnp.where((status == 0) & (new_status != 0), k, failure_index)
        record = (body, ref, error, u, *period_record(plant, x, u, logs))
        return (x_next, next_memory, new_status, failure_index), record

    steps = jnp.arange(n_steps)
    carry0 = (x0, memory0, jnp.asarray(0), jnp.asarray(-1))
    # unroll=2: a third less loop overhead on CPU; 4 ran no faster and compiled slower (docs/benchmarks.md)
    (_, _, status, failure_index), (states, refs, errors, controls, logs, extra) = jax.lax.scan(
        period, carry0, (steps, draws.disturbance, draws.noise), unroll=SCAN_UNROLL
    )
    return SimResult(steps * loop.control_period, states, refs, errors, controls, logs, status, failure_index, extra)


def measured(plant: Plant, x: Array) -> Array:
    """What the controller's sensors report at x, a BODY vector before noise: ``plant.measure(x)`` where the plant
    has one (odometry, a delayed measurement: ``ddtrack.model.SensedPlant``), else the true ``plant.observe(x)``."""
    return getattr(plant, "measure", plant.observe)(x)


def commanded(plant: Plant, u: Array) -> dict[str, Array]:
    """The held command of a velocity-driven plant as ``v_cmd`` [m/s], ``omega_cmd`` [rad/s] (a controller's own
    logs of them take precedence); nothing for other inputs: a torque plant logs the torques it applied itself."""
    commanded = {"v_cmd": VELOCITY_COMMAND.read(u, "v"), "omega_cmd": VELOCITY_COMMAND.read(u, "omega")}
    return commanded if plant.input_kind == "velocity" else {}


def recorded(plant: Plant) -> Layout:
    """The states a run records: ``plant.recorded_layout`` where the plant declares one (leaving out internal buffers
    such as a command queue), else its whole ``state_layout``."""
    return getattr(plant, "recorded_layout", plant.state_layout)


def require_matching_input(plant: Plant, controller: Any) -> None:
    """A ValueError naming both sides when ``controller`` declares an ``output_kind`` that ``plant`` does not take."""
    output = getattr(controller, "output_kind", None)
    if output is not None and output != plant.input_kind:
        raise ValueError(
            f"{type(controller).__name__} outputs {output} commands but {_name(plant)} takes "
            f"{plant.input_kind} ({', '.join(plant.input_layout.names)}): pair a {output}-driven plant with it"
        )


def _name(plant: Plant) -> str:
    """The plant's class, or the wrapped plant's for a wrapper (e.g. the sensing chain) that says what it wraps."""
    return getattr(plant, "description", type(plant).__name__)
