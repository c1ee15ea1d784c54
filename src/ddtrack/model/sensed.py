"""Any plant seen through latency, wheel encoders and odometry (model.md §1.9): :class:`SensedPlant`.

The wrapper is itself a plant (``init``/``saturate``/``advance``/``observe``/``logged``), so the simulator, a batch
and the Gymnasium environment step it like any other. Its state is the inner plant's, then what the sensing chain
carries from one period to the next::

    [inner state | phi_r, phi_l, odom_x .. odom_omega (odometry) | queued commands | delayed readings | sensing_clock]

(each part only when its feature is on; the wheel angles also not when the inner plant has its own ``phi_r``,
``phi_l``).

``observe(x)`` stays the inner plant's, the **true** body, which the simulator records and the metrics read.
``measure(x)`` is what the controller's sensors report: the odometry estimate (or the true body without odometry),
as it was ``measurement_periods`` periods ago. The queues are internal: ``recorded_layout`` names the states a run
records (the inner plant's, the wheel angles and the estimate), so a long delay does not flood the time series.
An optional absolute fix blends a noisy true pose into the estimate every ``fix_periods`` periods; optionally the
estimate's heading comes from a gyro (the true turn of each period with white rate noise and a constant bias added)
instead of the wheels' difference, as a TurtleBot3 does with ``use_imu``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from pydantic import Field

from .._pytree import pytree_dataclass, static_field
from ..integrators import Solver
from ..layout import BODY, Layout, pose_vector, velocity
from ..parameters import NonNegative, Parameters, Structure, Timing, declared, declared_fields
from .plants import ODEPlant
from .sensing import encoder_angle, odometry_step, queue_capacity, queue_layout, split_delay

#: the wheel angles a plant with encoders integrates [rad]
WHEEL_ANGLES = Layout(("phi_r", "phi_l"), ("rad", "rad"))
#: the odometry estimate, a BODY vector
ODOMETRY = Layout(tuple(f"odom_{name}" for name in BODY.names), BODY.units)
#: periods since the start: when the absolute fix is due, and which draws the fix and the gyro take
CLOCK = Layout(("sensing_clock",), ("",))
GYRO_STREAM = 1  #: the gyro's draws: the period's key folded once more (the fix's draws use the period's key itself)
#: estimated minus true pose, logged each period
ODOMETRY_ERROR = Layout(("odom_ex", "odom_ey", "odom_etheta"), ("m", "m", "rad"))


def _join(*layouts: Layout) -> Layout:
    return Layout(sum((lay.names for lay in layouts), ()), sum((lay.units for lay in layouts), ()))


@pytree_dataclass
class SensedPlant:
    """``inner`` with an actuation delay, a measurement delay, encoders, odometry and an absolute fix (model.md §1.9).

    Attributes
    ----------
    inner
        the true robot, any :class:`~ddtrack.model.Plant`
    nominal_radius, nominal_half_axle
        the controller's R-hat, L-hat [m], with which odometry turns encoder increments into motion
    true_radius, true_half_axle
        the true R, L [m], with which the wheels turn as the body moves (unless ``inner`` has ``wheel_rates(x)``,
        e.g. a plant whose wheels slip)
    command_periods
        the actuation delay's whole periods k (a number, traced: delays of different lengths share a program)
    command_fraction
        its fraction of a period f in [0, 1), tau_a = (k + f) T_c (static: it splits the period's integration)
    queue_capacity
        the commands the queue holds, at least k + (1 if f > 0), padded (:func:`queue_capacity`; static)
    measurement_periods
        the measurement delay in whole periods (a number, traced, as the actuation delay's)
    reading_capacity
        the readings the measurement line holds, at least ``measurement_periods``, padded (:func:`queue_capacity`;
        static)
    encoder_counts
        counts per wheel revolution; 0: the encoders read the exact angle
    odometry
        the controller sees the odometry estimate instead of the true body (static)
    fix_gain, fix_position_std, fix_heading_std
        the absolute fix's blend weight in (0, 1], its noise on x and y [m] and on theta [rad]
    gyro_noise_density, gyro_bias
        with ``gyro``: the gyro's white rate noise [rad/s/sqrt(Hz)] (a turn over T_c has the standard deviation
        density sqrt(T_c)) and its constant bias [rad/s]
    noise_key
        the PRNG key the fix's and the gyro's noise are drawn from (per period, folded in by the period's index)
    fix_periods
        an absolute fix every this many periods; 0: none (a number, traced)
    fixes
        whether the chain has an absolute fix (static: the fix's clock and draws exist or not; set from
        ``fix_periods`` when it is given as a number)
    gyro
        odometry takes each period's turn from the gyro instead of the encoders (static)
    """

    inner: Any
    nominal_radius: Array | float
    nominal_half_axle: Array | float
    true_radius: Array | float
    true_half_axle: Array | float
    encoder_counts: Array | float = 0.0
    fix_gain: Array | float = 0.0
    fix_position_std: Array | float = 0.0
    fix_heading_std: Array | float = 0.0
    gyro_noise_density: Array | float = 0.0
    gyro_bias: Array | float = 0.0
    noise_key: Array | None = None
    command_periods: Array | np.ndarray | int = 0
    measurement_periods: Array | np.ndarray | int = 0
    fix_periods: Array | np.ndarray | int = 0
    command_fraction: float = static_field(
        default=0.0, why="a split period integrates in two pieces, its substeps shared in proportion"
    )
    queue_capacity: int = static_field(default=0, why="the command queue's length, an array shape")
    reading_capacity: int = static_field(default=0, why="the measurement line's length, an array shape")
    odometry: bool = static_field(default=False, why="odometry states exist or not")
    fixes: bool = static_field(default=False, why="a fix's clock and draws exist or not")
    gyro: bool = static_field(default=False, why="a gyro-bias state exists or not")

    def __post_init__(self) -> None:
        """A plant built with a delay and no line for it gets the least line that holds it (a capacity of 0: not
        given); a line given too short for the delay is refused; a fix period given as a number turns the fix on. A
        traced delay has no value to size a line by: give its capacity (a traced actuation delay without one, split
        by a fraction of a period, is refused)."""
        if isinstance(self.command_periods, jax.core.Tracer):
            if self.queue_capacity == 0 and self.command_fraction > 0.0:
                raise ValueError("a traced actuation delay needs its queue_capacity (see queue_capacity())")
        else:
            longest = int(np.max(np.asarray(self.command_periods, dtype=int)))
            needed = longest + (1 if self.command_fraction > 0.0 else 0)
            self._hold("queue_capacity", queue_capacity(longest, self.command_fraction), needed, "commands")
        if not isinstance(self.measurement_periods, jax.core.Tracer):
            longest = int(np.max(np.asarray(self.measurement_periods, dtype=int)))
            self._hold("reading_capacity", queue_capacity(longest, 0.0), longest, "readings")
        if not isinstance(self.fix_periods, jax.core.Tracer) and np.any(np.asarray(self.fix_periods) > 0):
            object.__setattr__(self, "fixes", True)  # frozen

    def _hold(self, capacity: str, least: int, needed: int, what: str) -> None:
        """Give the line ``capacity`` its ``least`` length where it was not given; refuse one too short."""
        if getattr(self, capacity) == 0:
            object.__setattr__(self, capacity, least)  # frozen
        elif getattr(self, capacity) < needed:
            raise ValueError(f"a line of {getattr(self, capacity)} {what} cannot hold a delay of {needed} periods")

    # --- layouts ------------------------------------------------------------------------------------------------

    @property
    def queue_length(self) -> int:
        """The commands the state holds, the latest last: the last k (and one more when a fraction of a period splits
        it, the command that acts first), padded to :attr:`queue_capacity` with older ones."""
        return self.queue_capacity

    @property
    def clocked(self) -> bool:
        """The state counts periods (:data:`CLOCK`): the fix's schedule and the fix's and the gyro's draws need it."""
        return self.fixes or (self.odometry and self.gyro)

    @property
    def own_angles(self) -> bool:
        """The inner plant integrates its wheel angles itself (states ``phi_r``, ``phi_l``): odometry reads those."""
        return set(WHEEL_ANGLES.names) <= set(self.inner.state_layout.names)

    @property
    def _parts(self) -> tuple[Layout, ...]:
        none = Layout((), ())
        odometry = (none if self.own_angles else WHEEL_ANGLES, ODOMETRY) if self.odometry else (none, none)
        return (
            self.inner.state_layout,
            *odometry,
            queue_layout("queued", self.inner.input_layout, self.queue_length),
            queue_layout("delayed", BODY, self.reading_capacity),
            CLOCK if self.clocked else none,
        )

    @property
    def state_layout(self) -> Layout:
        return _join(*self._parts)

    @property
    def recorded_layout(self) -> Layout:
        """The states a run records: the inner plant's, the wheel angles and the odometry estimate (not the queues)."""
        return _join(*self._parts[:3])

    @property
    def input_layout(self) -> Layout:
        return self.inner.input_layout

    @property
    def logged_layout(self) -> Layout:
        return _join(self.inner.logged_layout, ODOMETRY_ERROR) if self.odometry else self.inner.logged_layout

    @property
    def input_kind(self) -> str:
        return self.inner.input_kind

    @property
    def description(self) -> str:
        """The wrapped plant's name, for messages (``SensedPlant`` alone would not say which robot it is)."""
        return f"{getattr(self.inner, 'description', type(self.inner).__name__)} behind its [sensing] chain"

    def split(self, x: Array) -> tuple[Array, Array, Array, Array, Array]:
        """(inner state, wheel angles (2,), estimate (5,), command queue (q, m), measurement queue (d, 5)) of x."""
        sizes = [len(layout) for layout in self._parts]
        bounds = [sum(sizes[:i]) for i in range(len(sizes) + 1)]
        inner, phi, estimate, queued, delayed = (x[bounds[i] : bounds[i + 1]] for i in range(5))
        if self.odometry and self.own_angles:
            phi = self._inner_angles(inner)
        return (
            inner,
            phi,
            estimate,
            queued.reshape(self.queue_length, len(self.input_layout)),
            delayed.reshape(self.reading_capacity, len(BODY)),
        )

    # --- the plant ----------------------------------------------------------------------------------------------

    def init(self, body: Array) -> Array:
        """The inner state; wheel angles 0 and the estimate at the true start (the robot is told where it starts);
        the queue full of the command held before the run (no torque, or the initial velocity for a velocity-
        commanded robot: it was cruising); the measurement line full of the first measurement."""
        inner = self.inner.init(body)
        held = velocity(body) if self.input_kind == "velocity" else jnp.zeros(len(self.input_layout))
        odometry = ([] if self.own_angles else [jnp.zeros(2)]) + [body] if self.odometry else []
        first = body if self.odometry else self.inner.observe(inner)
        queued = jnp.tile(held, self.queue_length)
        delayed = jnp.tile(first, self.reading_capacity)
        clock = jnp.zeros(1 if self.clocked else 0)  # periods since the start, for the fix's schedule and the draws
        return jnp.concatenate([inner, *odometry, queued, delayed, clock])

    def saturate(self, u: Array) -> Array:
        return self.inner.saturate(u)

    def observe(self, x: Array) -> Array:
        """The true body (what the run records and its metrics read)."""
        return self.inner.observe(self.split(x)[0])

    def reading(self, x: Array) -> Array:
        """What the sensors read at x before any delay: the odometry estimate, or the true body without it."""
        inner, _, estimate, _, _ = self.split(x)
        return estimate if self.odometry else self.inner.observe(inner)

    def measure(self, x: Array) -> Array:
        """What the controller's sensors report at x (a BODY vector): the reading of ``measurement_periods`` ago."""
        if self.reading_capacity == 0:
            return self.reading(x)
        line = jnp.concatenate([self.split(x)[4], self.reading(x)[None]])  # the oldest first, this period's last
        return line[self.reading_capacity - jnp.asarray(self.measurement_periods)]

    def stretches(self, x: Array, u: Array) -> tuple[Array, list[tuple[Array, float]]]:
        """Queue the command ``u`` of this period: (the queue after it, [(command, share of the period), ...]), the
        commands acting over the period in order (one, or two when a fraction of a period splits it)."""
        queued = self.split(x)[3]
        if self.queue_length == 0:
            return queued, [(u, 1.0)]
        line = jnp.concatenate([queued, u[None]])
        latest = self.queue_length - jnp.asarray(self.command_periods)  # row of the command sent k periods ago
        if self.command_fraction > 0.0:  # the older command acts first, for the fraction f of the period
            return line[1:], [(line[latest - 1], self.command_fraction), (line[latest], 1.0 - self.command_fraction)]
        return line[1:], [(line[latest], 1.0)]

    def advance(self, x: Array, u: Array, tau_dist: Array, period: Array | float, solver: Solver) -> Array:
        """One control period: the queued commands drive the inner plant (the wheels turning with it), then the
        odometry adds the period's encoder increments, and the measurement line takes this period's reading."""
        inner, phi, estimate, _, delayed = self.split(x)
        queued, acting = self.stretches(x, u)
        inner_next, phi_next = inner, phi
        done = 0
        for i, (command, share) in enumerate(acting):
            n = solver.substeps  # shared by the stretches in proportion, at least one each
            steps = max(1, n - done if i == len(acting) - 1 else round(n * share))
            done += steps
            piece = replace(solver, substeps=steps)
            inner_next, phi_next = self._drive(inner_next, phi_next, command, tau_dist, share * period, piece)
        parts = [inner_next]
        if self.odometry:
            if self.own_angles:
                phi_next = self._inner_angles(inner_next)
            increments = self._encoder(phi_next) - self._encoder(phi)
            turn = None
            if self.gyro:  # the true turn of the period, as the gyro integrates it, with its noise and bias
                true_turn = self.inner.observe(inner_next)[2] - self.inner.observe(inner)[2]
                true_turn = jnp.arctan2(jnp.sin(true_turn), jnp.cos(true_turn))  # a period turns less than pi
                turn = self.gyro_turn(true_turn, period, x[-1] + 1.0)
            estimate = odometry_step(
                estimate,
                increments,
                wheel_radius=self.nominal_radius,
                half_axle=self.nominal_half_axle,
                period=period,
                turn=turn,
            )
            if self.fixes:
                estimate = self.fixed(estimate, self.inner.observe(inner_next), x[-1] + 1.0)
            parts += [estimate] if self.own_angles else [phi_next, estimate]
        if self.reading_capacity:
            delayed = jnp.concatenate([delayed[1:], self.reading(x)[None]])
        tail = [x[-1:] + 1.0] if self.clocked else []
        return jnp.concatenate([*parts, queued.reshape(-1), delayed.reshape(-1), *tail])

    def fixed(self, estimate: Array, body: Array, clock: Array) -> Array:
        """The estimate after the absolute fix of period ``clock`` (a localisation of the true ``body``, noise
        added), blended in with ``fix_gain`` when the period is due: pose + g (fix - pose), the heading gap wrapped."""
        assert self.noise_key is not None, "a fix needs its key (Sensing.wrap gives it)"
        xi = jax.random.normal(jax.random.fold_in(self.noise_key, clock.astype(jnp.int32)), (3,))
        noise = jnp.stack([self.fix_position_std * xi[0], self.fix_position_std * xi[1], self.fix_heading_std * xi[2]])
        gap = pose_vector(body) + noise - pose_vector(estimate)
        gap = gap.at[2].set(jnp.arctan2(jnp.sin(gap[2]), jnp.cos(gap[2])))  # the short way round
        due = jnp.mod(clock, jnp.asarray(self.fix_periods)) == 0
        return estimate.at[:3].add(jnp.where(due, self.fix_gain, 0.0) * gap)

    def gyro_turn(self, true_turn: Array, period: Array | float, clock: Array) -> Array:
        """The turn [rad] the gyro reports over period ``clock`` of length T_c: the true turn, plus bias T_c, plus
        white rate noise integrated over the period, density sqrt(T_c) xi with xi standard normal."""
        assert self.noise_key is not None, "a gyro needs its key (Sensing.wrap gives it)"
        key = jax.random.fold_in(jax.random.fold_in(self.noise_key, clock.astype(jnp.int32)), GYRO_STREAM)
        noise = self.gyro_noise_density * jnp.sqrt(period) * jax.random.normal(key, ())
        return true_turn + self.gyro_bias * period + noise

    def logged(self, x: Array, u: Array) -> dict[str, Array]:
        """The inner plant's channels under the command acting at the period's start, and, with odometry, the
        estimate's error (estimated minus true pose) ``odom_ex``, ``odom_ey`` [m], ``odom_etheta`` [rad]."""
        inner, _, estimate, _, _ = self.split(x)
        logs = self.inner.logged(inner, self.stretches(x, u)[1][0][0])
        if self.odometry:
            error = pose_vector(estimate) - pose_vector(self.inner.observe(inner))
            logs = logs | ODOMETRY_ERROR.columns(error)
        return logs

    # --- wheels -------------------------------------------------------------------------------------------------

    def _inner_angles(self, inner: Array) -> Array:
        """(phi_R, phi_L) [rad] of an inner plant that integrates them itself (:attr:`own_angles`)."""
        return jnp.stack([inner[self.inner.state_layout.index(name)] for name in WHEEL_ANGLES.names])

    def _encoder(self, phi: Array) -> Array:
        """The angles [rad] the encoders report (a leaf, so runs with other counts share one compilation)."""
        counts = jnp.asarray(self.encoder_counts, dtype=float)
        return jnp.where(counts > 0, encoder_angle(phi, jnp.where(counts > 0, counts, 1.0)), phi)

    def wheel_rates(self, inner: Array) -> Array:
        """(phi_dot_R, phi_dot_L) [rad/s] at the inner state: the inner plant's own ``wheel_rates(x)`` if it has
        them, else its states ``phidot_r``, ``phidot_l`` if it has those (a plant whose wheels slip), else W nu of its
        body with the true R and L (wheels that roll without slipping)."""
        own = getattr(self.inner, "wheel_rates", None)
        if own is not None:
            return own(inner)
        names = self.inner.state_layout.names
        if "phidot_r" in names and "phidot_l" in names:
            return jnp.stack([inner[names.index("phidot_r")], inner[names.index("phidot_l")]])
        v, omega = velocity(self.inner.observe(inner))
        return jnp.stack([v + self.true_half_axle * omega, v - self.true_half_axle * omega]) / self.true_radius

    def _drive(
        self, inner: Array, phi: Array, u: Array, tau_dist: Array, duration: Array | float, solver: Solver
    ) -> tuple[Array, Array]:
        """The inner state and the wheel angles ``duration`` [s] later under the held command ``u``."""
        if not self.odometry or self.own_angles:  # no angles to integrate, or the plant integrates its own
            return self.inner.advance(inner, u, tau_dist, duration, solver), phi
        plant = self.inner
        if isinstance(plant, ODEPlant) and type(plant).advance is ODEPlant.advance:
            # an ODE plant: the wheel angles integrate with its state, in the same solver steps
            size = len(inner)

            def rates(z: Array) -> Array:
                return jnp.concatenate([plant.derivative(z[:size], u, tau_dist), self.wheel_rates(z[:size])])

            z = solver.integrate(rates, jnp.concatenate([plant.hold(inner, u), phi]), duration)
            return z[:size], z[size:]

        # a plant with its own integrator: its steps one at a time, the angles by the trapezoid rule over each
        steps, single = solver.substeps, replace(solver, substeps=1)

        def step(_: Any, carry: tuple[Array, Array]) -> tuple[Array, Array]:
            state, angles = carry
            after = plant.advance(state, u, tau_dist, duration / steps, single)
            return after, angles + 0.5 * duration / steps * (self.wheel_rates(state) + self.wheel_rates(after))

        return jax.lax.fori_loop(0, steps, step, (inner, phi))


class SensingParameters(Parameters):
    """The sensing chain's parameters, as a scenario's ``[sensing]`` section declares them (the gyro's, which default
    to the robot preset's, are the section's own)."""

    actuation_delay: NonNegative = Field(
        0.0,
        le=10.0,
        description=(
            "tau_a [s]: the command computed at t_k acts from t_k + tau_a until the next one acts; a fraction of a "
            "control period splits the period between two commands."
        ),
    )
    measurement_delay: NonNegative = Field(
        0.0,
        le=10.0,
        description=(
            "tau_m [s], a whole number of control periods: the controller at t_k sees what its sensors read at "
            "t_k - tau_m."
        ),
    )
    encoder_counts: int = Field(
        0,
        ge=0,
        le=10_000_000,
        description=(
            "Counts per wheel revolution of the encoders odometry reads, e.g. 4096 for a TurtleBot3's XL430; "
            "0: exact wheel angles. Needs odometry = true."
        ),
    )
    odometry: Structure[bool] = Field(
        False,
        description=(
            "The controller sees the odometry estimate (encoder increments integrated with the [robot] wheel_radius "
            "and half_axle, whatever [plant] says) instead of the true pose and velocity."
        ),
    )

    fix_period: NonNegative = Field(
        0.0,
        le=3600.0,
        description=(
            "An absolute fix (localisation) every fix_period [s], a whole number of control periods, corrects the "
            "odometry estimate; 0: none. Needs odometry = true."
        ),
    )
    fix_gain: float = Field(
        0.5, gt=0.0, le=1.0, description="Weight g of the fix in the blend pose + g (fix - pose); 1: reset to it."
    )
    fix_position_std: NonNegative = Field(0.0, description="Noise of the fix on x and y [m].")
    fix_heading_std: NonNegative = Field(0.0, description="Noise of the fix on theta [rad].")


@dataclass(frozen=True)
@declared_fields
class Sensing:
    """The sensing chain of a scenario (``[sensing]``), before it knows its plant: the fields of
    :class:`SensingParameters` (documented there), the control period T_c [s], and whether odometry's heading comes
    from a gyro of this white rate noise ``gyro_noise_density`` [rad/s/sqrt(Hz)] and constant ``gyro_bias`` [rad/s].
    """

    actuation_delay: float = declared(SensingParameters)
    measurement_delay: float = declared(SensingParameters)
    encoder_counts: int = declared(SensingParameters)
    odometry: bool = declared(SensingParameters)
    control_period: float = declared(Timing)
    fix_period: float = declared(SensingParameters)
    fix_gain: float = declared(SensingParameters)
    fix_position_std: float = declared(SensingParameters)
    fix_heading_std: float = declared(SensingParameters)
    gyro: bool = False
    gyro_noise_density: float = 0.0
    gyro_bias: float = 0.0

    def wrap(self, plant: Any, nominal: Any, true: Any, key: Array | None = None) -> SensedPlant:
        """``plant`` behind this chain; ``nominal`` and ``true`` are the controller's and the plant's
        :class:`~ddtrack.model.RobotParams` (``true`` may carry a batch axis, which the nominal values take);
        ``key``, the PRNG key of the absolute fix's and the gyro's noise (default a fixed one), with that batch axis
        too."""
        whole, fraction = split_delay(self.actuation_delay, self.control_period)
        measured, _ = split_delay(self.measurement_delay, self.control_period)
        fixes, _ = split_delay(self.fix_period, self.control_period)
        if (fixes or self.gyro) and not self.odometry:
            raise ValueError("an absolute fix and a gyro heading feed the odometry estimate: they need odometry")
        batch = jnp.shape(true.wheel_radius)
        drawn = bool(fixes) or self.gyro
        if drawn and key is None:
            key = jnp.broadcast_to(jax.random.PRNGKey(0), (*batch, 2))

        def like_batch(value: float) -> Array:
            return jnp.broadcast_to(jnp.asarray(value, dtype=float), batch)

        return SensedPlant(
            plant,
            like_batch(nominal.wheel_radius),
            like_batch(nominal.half_axle),
            true.wheel_radius,
            true.half_axle,
            like_batch(self.encoder_counts),
            like_batch(self.fix_gain),
            like_batch(self.fix_position_std),
            like_batch(self.fix_heading_std),
            like_batch(self.gyro_noise_density),
            like_batch(self.gyro_bias),
            key if drawn else None,
            # numpy: concrete even where the plant is built traced
            command_periods=np.broadcast_to(whole, batch),
            measurement_periods=np.broadcast_to(measured, batch),
            fix_periods=np.broadcast_to(fixes, batch),
            command_fraction=fraction,
            queue_capacity=queue_capacity(whole, fraction),  # from the config: a plant built in a trace has no values
            reading_capacity=queue_capacity(measured, 0.0),
            odometry=self.odometry,
            fixes=bool(fixes),
            gyro=self.gyro,
        )
