"""Two time bases in one simulation: inputs held from their own stamps, speeds read at the odometry's
(docs/identification.md, "Timing").

A robot's log has a stream of inputs (``/cmd_vel``, wheel torques, voltages), each sent at its own stamp s_j, and a
stream of measured speeds at the stamps t_k, on another rate. The input s_j acts from s_j + d (d the delay, any real
number of seconds) until the next one does: a zero-order hold on the inputs' own time base. Between two measurements
t_k and t_{k+1} the input may therefore change once, several times, or not at all; each interval is cut into
``slots`` segments at the switches that fall inside it (zero-length segments pad the rest), and the speeds are
integrated segment by segment. Which input acts where depends on d only through the segments' boundaries s_j + d,
so the simulated speeds are differentiable in d between the switches' crossings of a measurement stamp, and
continuous across them: the fit moves d like any other parameter.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache, cached_property
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..integrators import rk4_step

#: [s] the delay is nudged by this before a Jacobian: at a switch exactly on a measurement stamp (equal rates, a
#: delay of whole samples) the simulation has a corner in d, and its right derivative is the one that moves it
CORNER = 1e-9
#: XLA's YNN fusions hand each small matrix product (the body model's 2x2 input map) to a library, and inside the
#: simulation's innermost loop the call costs more than the product: the fit's programs leave them off (results
#: bit-identical; the windows' residuals took less than half the time on 2026-11-29).
NO_YNN = {"xla_cpu_experimental_ynn_fusion_type": ""}


@cache
def compiler_options() -> dict[str, str]:
    """:data:`NO_YNN` where this jax and XLA know the option (a trivial program compiled to ask), else none."""
    try:
        jax.jit(lambda x: x, compiler_options=NO_YNN)(0.0)
    except (TypeError, RuntimeError):  # an older jax or XLA: no such option, and no YNN fusions to turn off
        return {}
    return NO_YNN


class Program:
    """``fn`` jitted with :func:`compiler_options`, at its first call (so that importing asks XLA nothing)."""

    def __init__(self, fn: Callable, static_argnums: tuple[int, ...]) -> None:
        self.fn, self.static_argnums = fn, static_argnums
        self.__doc__ = fn.__doc__

    @cached_property
    def jitted(self) -> Any:
        options: dict[str, Any] = {"compiler_options": compiler_options()} if compiler_options() else {}
        return jax.jit(self.fn, static_argnums=self.static_argnums, **options)

    def __call__(self, *args: Any) -> Any:
        return self.jitted(*args)


def program(*static_argnums: int) -> Callable[[Callable], Program]:
    """Decorate a function as a :class:`Program` with these static arguments."""
    return lambda fn: Program(fn, static_argnums)


class Schedule(NamedTuple):
    """What acts over each measurement interval k (from t_k to t_{k+1}), for one delay."""

    start: np.ndarray  #: (n - 1,) t_k [s]
    step: np.ndarray  #: (n - 1,) t_{k+1} - t_k [s]
    switch: np.ndarray  #: (n - 1, slots - 1) stamps s_j [s] (before the delay) of the inputs that take over inside
    valid: np.ndarray  #: (n - 1, slots - 1) True where ``switch`` is one (else a zero-length pad)
    inputs: np.ndarray  #: (n - 1, slots, 2) the input over each segment: the one in force at t_k, then each switch's


def slots_for(t: np.ndarray, sent_t: np.ndarray) -> int:
    """Segments per measurement interval that hold every switch at any delay: one plus the most input stamps in a
    span as long as the longest interval."""
    longest = float(np.max(np.diff(t)))
    within = np.searchsorted(sent_t, sent_t + longest, side="left") - np.arange(sent_t.size)
    return 1 + int(within.max())


def in_force(t: np.ndarray, sent_t: np.ndarray, delay: float) -> np.ndarray:
    """Index of the input in force at each time ``t``: the last one with s_j + delay <= t (the first before any
    acts: what the robot did before the log began is not known, and the first input is the best guess)."""
    return np.clip(np.searchsorted(sent_t + delay, t, side="right") - 1, 0, None)


def held_at(t: np.ndarray, sent_t: np.ndarray, sent: np.ndarray, delay: float) -> np.ndarray:
    """The input in force at each time ``t`` [s] when each of ``sent`` acts ``delay`` [s] after its stamp."""
    return sent[in_force(t, sent_t, delay)]


def nearest_corner(t: np.ndarray, sent_t: np.ndarray, sent: np.ndarray, delay: float) -> float:
    """The delay nearest ``delay`` [s] at which an input that changes what is in force takes over exactly on a
    measurement stamp (NaN if none changes): the simulated speeds have a corner in the delay there, and where the
    two streams' stamps are aligned every switch has its corner at the same delay, often the fit's minimum."""
    changes = sent_t[1:][np.any(sent[1:] != sent[:-1], axis=1)]
    if changes.size == 0:
        return float("nan")
    acting = changes + delay
    k = np.clip(np.searchsorted(t, acting), 1, t.size - 1)
    gaps = np.concatenate([t[k] - acting, t[k - 1] - acting])
    return float(delay + gaps[np.argmin(np.abs(gaps))])


def schedule(t: np.ndarray, sent_t: np.ndarray, sent: np.ndarray, delay: float, slots: int) -> Schedule:
    """The segments of every interval between the measurement stamps ``t`` for inputs ``sent`` stamped ``sent_t``,
    each acting ``delay`` [s] after its stamp. An input that acts exactly at t_k is in force at t_k (no
    zero-length segment before it)."""
    acting = sent_t + delay
    first = in_force(t[:-1], sent_t, delay)
    count = np.clip(np.searchsorted(acting, t[1:], side="left") - 1 - first, 0, None)  # switches inside
    if count.max(initial=0) > slots - 1:
        raise ValueError(f"{count.max()} switches in one interval, {slots - 1} slots")
    inside = np.arange(slots - 1)[None, :]
    valid = inside < count[:, None]
    index = np.where(valid, first[:, None] + 1 + inside, first[:, None] + count[:, None])
    index = np.minimum(index, sent_t.size - 1)
    segments = np.concatenate([first[:, None], index], axis=1)
    return Schedule(t[:-1], np.diff(t), np.where(valid, sent_t[index], 0.0), valid, sent[segments])


def used_segments(valid: jax.Array) -> jax.Array:
    """How many of each interval's segments are integrated: 1 + its switches inside (``valid``, (..., n - 1,
    slots - 1)), the most over the leading axes (windows simulated side by side take one loop). The others have
    zero length: an RK4 step of h = 0 leaves the state, its tangents and the area as they are, bit for bit."""
    count = jnp.sum(valid, axis=-1)
    return 1 + count.reshape(-1, count.shape[-1]).max(axis=0)


def _intervals(rate, params, delay, start, scheduled, interval_mean, substeps, used):
    """The state after every interval of ``scheduled`` from ``start``, and each interval's sample (its end's state,
    or with ``interval_mean`` the mean over it); ``used``: :func:`used_segments`."""

    def interval(speed, segments):
        (t0, h_all, switch, valid, inputs), n = segments
        t1 = t0 + h_all
        bounds = jnp.clip(jnp.where(valid, switch + delay, t1), t0, t1)
        lengths = jnp.diff(jnp.concatenate([t0[None], bounds, t1[None]]))

        def segment(i, carry):
            s, areas = carry
            h = lengths[i]
            f = lambda x: rate(params, x, inputs[i])  # noqa: E731

            def substep(x, _):
                after = rk4_step(f, x, h / substeps)
                return after, after

            after, path = jax.lax.scan(substep, s, None, length=substeps)
            area = h * (0.5 * s + path[:-1].sum(axis=0) + 0.5 * after) / substeps  # trapezoid over the substeps
            return after, areas + area

        # the used segments only: a schedule that holds the most switches any delay could put in an interval (3
        # slots where the streams share their stamps) mostly pads with zero-length ones, which cost as much
        after, areas = jax.lax.fori_loop(0, n, segment, (speed, jnp.zeros_like(speed)))
        mean = jnp.where(h_all > 0, areas / jnp.where(h_all > 0, h_all, 1.0), after)
        return after, jnp.where(interval_mean, mean, after)  # a select, not a branch: one program serves both readings

    return jax.lax.scan(interval, start, (scheduled, used))


def simulate_schedule(rate, params, delay, start, scheduled, interval_mean, substeps, used):
    """(v, omega) at t_0 (``start``) and at the end of each interval of ``scheduled`` (JAX arrays of a
    :class:`Schedule`, any leading shape the caller vmaps away), ``substeps`` RK4 steps per segment; with
    ``interval_mean``, each sample after the first is the mean over the interval ending at it. ``used``:
    :func:`used_segments` of the schedule, or of every one vmapped beside it."""
    _, speeds = _intervals(rate, params, delay, start, scheduled, interval_mean, substeps, used)
    return jnp.concatenate([start[None], speeds])


@program(0, 6)
def simulate_jit(rate, params, delay, start, scheduled, interval_mean, substeps):
    """The state at the end of ``scheduled`` and the samples at each interval's end (:func:`simulate_schedule`
    without ``start``), compiled once per model, substep count and number of intervals (the reading is traced)."""
    return _intervals(rate, params, delay, start, scheduled, interval_mean, substeps, used_segments(scheduled[3]))
