"""Latency, wheel encoders and odometry as pure JAX functions (model.md §1.9).

Each function has static shapes and no Python branching on traced values, so a ``lax.scan`` body can call it once
per control period and carry its state:

* a **delay line** (:class:`DelayLine`, :func:`delay_line`, :func:`delay_push`) is a ring buffer of the last k
  vectors: pushing the vector of period j returns the one of period j - k. It delays measurements by k periods;
* an **actuation delay** of tau_a = (k + f) T_c (:func:`split_delay`, :func:`actuation_delay`,
  :func:`actuation_push`) holds commands in a line of k + 1: during period j the command of period j - k - 1 acts
  for the first f T_c and the command of period j - k for the rest;
* an **encoder** with n counts per revolution reads floor(phi n / 2 pi) 2 pi / n (:func:`encoder_counts`,
  :func:`encoder_angle`);
* **odometry** integrates the increments of the two wheel angles over a period as the exact arc they imply with
  the nominal wheel radius and half axle (:func:`odometry_step`), or with a gyro's turn in place of the wheels'
  difference, and estimates the speeds as increment / T_c.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax.numpy as jnp
from jax import Array

from ..layout import Layout, pose_vector

SERIES_BELOW = 1e-4  #: |a| [rad] under which sin(a) / a is its Taylor series (error below 1e-22)
COUNT_SLACK = 8.0 * 2.0**-52  #: relative slack under which a count boundary counts as reached (a few ulps)


# --- delays ---------------------------------------------------------------------------------------------------------


class DelayLine(NamedTuple):
    """A ring buffer of the last k vectors pushed (a pytree: a scan can carry it).

    Attributes
    ----------
    buffer
        (k, m) the k most recent vectors, the oldest at ``head`` and the rest after it, cyclically
    head
        () int32, the slot of the oldest vector (the one the next push returns)
    """

    buffer: Array
    head: Array


def delay_line(periods: int, initial: Array) -> DelayLine:
    """A line that delays by ``periods`` pushes (static, >= 0), full of ``initial`` (m,): the first ``periods``
    pushes return ``initial`` (the command before the run, or the first measurement)."""
    if periods < 0:
        raise ValueError(f"a delay line needs periods >= 0, not {periods}")
    initial = jnp.asarray(initial, dtype=float)
    return DelayLine(jnp.broadcast_to(initial, (periods, *initial.shape)), jnp.zeros((), dtype=jnp.int32))


def delay_push(line: DelayLine, value: Array) -> tuple[DelayLine, Array]:
    """Push this period's ``value`` (m,); return the line and the value pushed k periods ago (``value`` itself for
    k = 0).

    Pushed once per period, the measurement of period j comes out at period j + k: the controller at t_j sees the
    measurement taken at t_j - k T_c.
    """
    periods = line.buffer.shape[0]
    if periods == 0:
        return line, jnp.asarray(value, dtype=float)
    oldest = line.buffer[line.head]
    buffer = line.buffer.at[line.head].set(value)
    return DelayLine(buffer, (line.head + 1) % periods), oldest


def delay_contents(line: DelayLine) -> Array:
    """(k, m) the line's vectors, oldest first (``delay_push`` returns them in this order)."""
    return jnp.roll(line.buffer, -line.head, axis=0)


def queue_layout(prefix: str, layout: Layout, length: int) -> Layout:
    """The names of a queue of ``length`` vectors of ``layout``, oldest first (``queued_0_tau_r``, ...)."""
    names = tuple(f"{prefix}_{i}_{name}" for i in range(length) for name in layout.names)
    return Layout(names, layout.units * length)


QUEUE_BUCKET = 16  #: the least capacity of a command queue or a measurement line: delays up to 16 periods share one


def queue_capacity(whole: int, fraction: float) -> int:
    """The commands a queue for a delay of ``whole`` periods and ``fraction`` of one holds: none without a delay,
    else the next power of two, at least :data:`QUEUE_BUCKET` (the older commands in it are never read)."""
    needed = whole + (1 if fraction > 0.0 else 0)
    return 0 if needed == 0 else max(QUEUE_BUCKET, 1 << (needed - 1).bit_length())


def split_delay(delay: float, period: float) -> tuple[int, float]:
    """(k, f): the whole periods and the fraction of a period in ``delay`` [s] = (k + f) ``period`` [s], f in [0, 1).

    A ratio within 1e-9 of a whole number counts as whole (0.03 / 0.01 is 2.9999999999999996 in floating point).
    Plain Python, for the static shape of a line.
    """
    if delay < 0.0 or period <= 0.0:
        raise ValueError(f"a delay needs delay >= 0 and period > 0, not {delay} and {period}")
    ratio = delay / period
    whole = round(ratio)
    if abs(ratio - whole) < 1e-9:
        return whole, 0.0
    return math.floor(ratio), ratio - math.floor(ratio)


class ActuationDelay(NamedTuple):
    """The commands on their way to the motors: a :class:`DelayLine` of k + 1 and the fraction f of a period."""

    line: DelayLine
    fraction: Array


def actuation_delay(delay: float, period: float, initial: Array) -> ActuationDelay:
    """The FIFO of an actuation delay of ``delay`` [s] at control period ``period`` [s] (:func:`split_delay`),
    full of ``initial`` (m,), the command held before the run."""
    whole, fraction = split_delay(delay, period)
    return ActuationDelay(delay_line(whole + 1, initial), jnp.asarray(fraction, dtype=float))


def actuation_push(delay: ActuationDelay, command: Array) -> tuple[ActuationDelay, Array, Array, Array]:
    """Queue the command computed at t_j; return the FIFO and what acts over [t_j, t_j + T_c).

    Returns
    -------
    tuple of Array
        ``(delay, earlier, later, fraction)``: ``earlier`` (the command of period j - k - 1) acts for the first
        ``fraction`` T_c of the period, ``later`` (the command of period j - k) for the remaining (1 - fraction)
        T_c. A plant period under the delay is two held stretches, e.g.::

            x = plant.advance(x, earlier, d, fraction * T_c, solver)
            x = plant.advance(x, later, d, (1 - fraction) * T_c, solver)

        (with fraction = 0 the first stretch is empty and ``later`` is the command of period j - k).
    """
    line, earlier = delay_push(delay.line, command)
    later = line.buffer[line.head]
    return ActuationDelay(line, delay.fraction), earlier, later, delay.fraction


# --- encoders -------------------------------------------------------------------------------------------------------


def encoder_counts(angle: Array, counts_per_revolution: int | Array) -> Array:
    """The count an incremental encoder shows at wheel angle ``angle`` [rad] (as a float): floor(phi n / 2 pi).

    A boundary within a few ulps counts as reached, so an angle that is a whole number of counts, as rounded in
    floating point, reads as that count.
    """
    scaled = jnp.asarray(angle) * counts_per_revolution / (2.0 * jnp.pi)
    return jnp.floor(scaled + COUNT_SLACK * jnp.maximum(1.0, jnp.abs(scaled)))


def encoder_angle(angle: Array, counts_per_revolution: int | Array) -> Array:
    """The wheel angle [rad] the encoder reports, floor(phi n / 2 pi) 2 pi / n: at most one count below ``angle``."""
    return encoder_counts(angle, counts_per_revolution) * (2.0 * jnp.pi / counts_per_revolution)


# --- odometry -------------------------------------------------------------------------------------------------------


def _sin_over(a: Array) -> Array:
    """sin(a) / a, its series 1 - a^2/6 + a^4/120 near 0 (finite, with finite derivatives, at a = 0)."""
    small = jnp.abs(a) < SERIES_BELOW
    safe = jnp.where(small, 1.0, a)
    return jnp.where(small, 1.0 - a**2 / 6.0 + a**4 / 120.0, jnp.sin(safe) / safe)


def body_increments(increments: Any, wheel_radius: Array | float, half_axle: Array | float) -> tuple[Any, Any]:
    """(distance [m], turn [rad]) of the axle midpoint from the wheel-angle increments (dphi_R, dphi_L) [rad]:
    R (dphi_R + dphi_L) / 2 and R (dphi_R - dphi_L) / (2 L) (model.md §1.1). Plain arithmetic: JAX or NumPy
    arrays in (rates give the midpoint's speeds), the same kind out."""
    right, left = increments[0], increments[1]
    return wheel_radius * (right + left) / 2.0, wheel_radius * (right - left) / (2.0 * half_axle)


def arc_pose(pose: Array, distance: Array, turn: Array) -> Array:
    """The pose (x, y, theta) after driving ``distance`` [m] along a circular arc that turns by ``turn`` [rad]:
    x + s cos(theta + dtheta/2) sinc(dtheta/2), likewise y with sin, theta + dtheta (a straight line for turn = 0)."""
    chord = distance * _sin_over(turn / 2.0)
    middle = pose[2] + turn / 2.0
    return jnp.stack([pose[0] + chord * jnp.cos(middle), pose[1] + chord * jnp.sin(middle), pose[2] + turn])


def odometry_step(
    estimate: Array,
    increments: Array,
    *,
    wheel_radius: Array | float,
    half_axle: Array | float,
    period: Array | float,
    turn: Array | None = None,
) -> Array:
    """The odometry estimate one control period later, as a BODY vector [x, y, theta, v, omega].

    Parameters
    ----------
    estimate
        (5,) the estimate at the period's start (its speeds are not used)
    increments
        (2,) how far the right and left wheels turned over the period, as the encoders count it [rad]
    wheel_radius, half_axle
        the controller's nominal R-hat, L-hat [m]
    period
        T_c [s]
    turn
        the period's turn [rad] from another sensor (a gyro), used instead of the encoders' R (dphi_R - dphi_L) / 2L;
        None: the encoders'

    Returns
    -------
    Array
        (5,) the pose at the end of the arc the increments imply (exact for constant speeds), and the speeds
        estimated as increment / T_c: (distance / T_c, turn / T_c)
    """
    distance, wheel_turn = body_increments(increments, wheel_radius, half_axle)
    turn = wheel_turn if turn is None else turn
    pose = arc_pose(pose_vector(estimate), distance, turn)
    return jnp.concatenate([pose, jnp.stack([distance / period, turn / period])])
