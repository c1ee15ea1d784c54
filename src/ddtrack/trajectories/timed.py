"""A timed path: the reference is at (x_i, y_i) at t_i, between rows a C2 cubic spline in time, and stops where
consecutive rows share a point (a recorded or planned path replayed as it was driven).

The spline is split at every stop: each stretch of rows with distinct consecutive points gets its own C2 cubic
spline in t, clamped at both ends, and a stretch between two equal rows is the constant point, so a stop is
exactly stationary (one spline through a repeated point would overshoot around it). The clamped end velocity of a
stretch is v_i (cos h_i, sin h_i) where a ``speeds`` row is given (h_i: its ``yaws`` row, else the direction of its
leg), else zero: without speeds the reference starts from rest, comes to rest at every stop and at the end, and
its speed is continuous. Interior speeds only set the time stamps (:func:`trapezoid_times`); the spline's
interior slopes come from the positions. Where the reference stands still (a stop, before t_0, after t_last, or a
speed below ``STILL_SPEED``) v_r = omega_r = v_dot = omega_dot = 0 and the heading is held: the row's ``yaws``
value where given, else the last heading of motion (the first one before the reference first moves).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np
from jax import Array

from .._pytree import pytree_dataclass
from ..geometry import wrap_angle
from .base import Reference

STILL_SPEED = 1e-9  #: [m/s] below this the heading of the zero velocity vector is noise: the reference is held


@pytree_dataclass
class TimedPath:
    """Cubic pieces in time between the rows ``points`` (n, 2) [m] at ``times`` (n,) [s]: ``coefficients[k, axis]``
    holds (c3, c2, c1, c0) of x or y = c3 tau^3 + c2 tau^2 + c1 tau + c0, tau = t - times[k]. ``still[k]`` marks a
    stop (a constant piece); ``held[k]`` (2,) is the heading [rad] held where piece k stands still near its start
    and near its end; ``before`` and ``after`` are the headings held before t_0 and after t_last. Build it with
    :func:`timed_path`."""

    points: Array
    times: Array
    coefficients: Array
    still: Array
    held: Array
    before: Array
    after: Array

    def __call__(self, t: Array | float) -> Reference:
        t = jnp.asarray(t, dtype=float)
        first, last = self.times[0], self.times[-1]
        k = jnp.clip(jnp.searchsorted(self.times, t, side="right") - 1, 0, self.times.shape[0] - 2)
        tau = jnp.clip(t, first, last) - self.times[k]
        c3, c2, c1, c0 = (self.coefficients[k, :, j] for j in range(4))
        p = ((c3 * tau + c2) * tau + c1) * tau + c0
        p1 = (3.0 * c3 * tau + 2.0 * c2) * tau + c1
        p2 = 6.0 * c3 * tau + 2.0 * c2
        p3 = 6.0 * c3
        p = jnp.where(t >= last, self.points[-1], jnp.where(t <= first, self.points[0], p))  # the rows exactly
        speed = jnp.hypot(p1[0], p1[1])
        moving = (t >= first) & (t < last) & ~self.still[k] & (speed > STILL_SPEED)
        safe = jnp.where(moving, speed, 1.0)  # keeps the unused branch finite where the reference stands still
        cross = p1[0] * p2[1] - p1[1] * p2[0]
        v_dot = (p1[0] * p2[0] + p1[1] * p2[1]) / safe
        omega = cross / safe**2
        omega_dot = (p1[0] * p3[1] - p1[1] * p3[0]) / safe**2 - 2.0 * cross * v_dot / safe**3
        near_end = (tau > 0.5 * (self.times[k + 1] - self.times[k])).astype(int)
        held = jnp.where(t < first, self.before, jnp.where(t > last, self.after, self.held[k, near_end]))
        theta = jnp.where(moving, jnp.arctan2(p1[1], jnp.where(moving, p1[0], 1.0)), held)
        zero = jnp.zeros_like(t)
        return Reference(
            p[0],
            p[1],
            wrap_angle(theta),
            jnp.where(moving, speed, zero),
            jnp.where(moving, omega, zero),
            jnp.where(moving, v_dot, zero),
            jnp.where(moving, omega_dot, zero),
        )


def timed_path(
    times: Sequence[float],
    points: Sequence[Sequence[float]],
    *,
    yaws: Sequence[float] | None = None,
    speeds: Sequence[float] | None = None,
    labels: Sequence[str] | None = None,
) -> TimedPath:
    """The reference through ``points`` (n, 2) [m] at ``times`` (n,) [s], strictly increasing; ``yaws`` [rad] are the
    headings held where it stands still, ``speeds`` [m/s] the end velocities of each stretch between stops (see the
    module's docstring). ``labels`` name the rows in errors (``"line 7"``; default ``"point i"``, from 0).

    Raises
    ------
    ValueError
        On fewer than two rows, columns of different lengths, NaN or inf, a time not after the one before, a
        negative speed, or a path that never moves.
    """
    t = np.asarray(times, dtype=float)
    p = np.asarray(points, dtype=float)
    n = len(t)
    names = list(labels) if labels is not None else [f"point {i}" for i in range(n)]
    if p.shape != (n, 2) or n < 2 or len(names) != n:
        raise ValueError(f"need at least two rows of t and [x, y] of one length, got {n} times and {len(p)} points")
    columns = {"t": t, "x, y": p, "yaw": yaws, "v": speeds}
    for name, column in columns.items():
        if column is not None and (len(column) != n or not np.all(np.isfinite(np.asarray(column, dtype=float)))):
            raise ValueError(f"{name} must hold {n} finite numbers, one per row (found NaN, inf or another length)")
    late = np.flatnonzero(np.diff(t) <= 0.0)
    if late.size:
        k = int(late[0]) + 1
        raise ValueError(f"{names[k]}: t = {t[k]:g} s is not after {t[k - 1]:g} s; times must increase row by row")
    v = None if speeds is None else np.asarray(speeds, dtype=float)
    if v is not None and np.any(v < 0.0):
        raise ValueError(f"{names[int(np.flatnonzero(v < 0.0)[0])]}: a speed is >= 0 m/s (the path sets the heading)")
    still = np.all(np.diff(p, axis=0) == 0.0, axis=1)
    if np.all(still):
        raise ValueError("the path never moves: give at least two different points")
    yaw = None if yaws is None else np.asarray(yaws, dtype=float)
    coefficients = np.zeros((n - 1, 2, 4))
    coefficients[:, :, 3] = p[:-1]  # a stop is its point; a stretch overwrites its pieces below
    held = np.zeros((n - 1, 2))
    from scipy.interpolate import CubicSpline  # here, not at the top: 0.2 s that every ddtrack command would pay

    for a, b in _stretches(still):
        ends = [_end_velocity(p, v, yaw, row, leg) for row, leg in ((a, a), (b, b - 1))]
        spline = CubicSpline(t[a : b + 1], p[a : b + 1], bc_type=((1, ends[0]), (1, ends[1])))
        coefficients[a:b] = np.moveaxis(spline.c, 0, -1)
        for k in range(a, b):
            held[k] = [
                _limit_heading(coefficients[k], 0.0, 1.0),
                _limit_heading(coefficients[k], t[k + 1] - t[k], -1.0),
            ]
    moving_pieces = np.flatnonzero(~still)
    start_heading, end_heading = held[moving_pieces[0], 0], held[moving_pieces[-1], 1]
    last = start_heading
    for k in range(n - 1):  # a stop holds the last heading of motion, the first one before any motion
        if still[k]:
            held[k] = yaw[k] if yaw is not None else last
        else:
            last = held[k, 1]
    return TimedPath(
        points=jnp.asarray(p),
        times=jnp.asarray(t),
        coefficients=jnp.asarray(coefficients),
        still=jnp.asarray(still),
        held=jnp.asarray(held),
        before=jnp.asarray(yaw[0] if yaw is not None else start_heading),
        after=jnp.asarray(yaw[-1] if yaw is not None else end_heading),
    )


def _stretches(still: np.ndarray) -> list[tuple[int, int]]:
    """(first row, last row) of each run of moving pieces between stops."""
    runs, a = [], None
    for k, stopped in enumerate([*still, True]):
        if not stopped and a is None:
            a = k
        elif stopped and a is not None:
            runs.append((a, k))
            a = None
    return runs


def _end_velocity(p: np.ndarray, v: np.ndarray | None, yaw: np.ndarray | None, row: int, leg: int) -> np.ndarray:
    """The clamped velocity [m/s] at a stretch's end ``row``: v (cos, sin) of its yaw or of its ``leg``'s direction."""
    if v is None:
        return np.zeros(2)
    chord = p[leg + 1] - p[leg]
    heading = yaw[row] if yaw is not None else np.arctan2(chord[1], chord[0])
    return v[row] * np.array([np.cos(heading), np.sin(heading)])


def _limit_heading(c: np.ndarray, tau: float, sign: float) -> float:
    """The heading of motion [rad] of the cubic piece ``c`` (2, 4) as tau -> ``tau`` from after (``sign`` 1) or
    from before (-1): the direction of its first derivative that is not zero (the velocity vanishes at a stop)."""
    derivatives = [
        (3.0 * c[:, 0] * tau + 2.0 * c[:, 1]) * tau + c[:, 2],
        6.0 * c[:, 0] * tau + 2.0 * c[:, 1],
        6.0 * c[:, 0],
    ]
    scale = max(float(np.max(np.abs(c[:, :3]))), 1e-300)
    for order, d in enumerate(derivatives):
        if np.hypot(d[0], d[1]) > 1e-12 * scale * max(1.0, abs(tau)) ** 2:
            d = d * sign**order
            return float(np.arctan2(d[1], d[0]))
    return 0.0  # not reached for a piece between two different points


def trapezoid_times(
    points: Sequence[Sequence[float]], speeds: Sequence[float], *, labels: Sequence[str] | None = None
) -> np.ndarray:
    """Times [s] from 0 at which a path through ``points`` [m] at ``speeds`` [m/s] (one per row, >= 0) reaches
    each row, the speed varying linearly along each leg: dt = 2 ds / (v_i + v_{i+1}). A leg of length 0 takes no
    time (and is dropped as a repeated row); ``labels`` name the rows in errors.

    Raises
    ------
    ValueError
        On a negative or non-finite speed, or a leg of positive length whose two speeds are both 0 (never driven).
    """
    p, v = np.asarray(points, dtype=float), np.asarray(speeds, dtype=float)
    names = list(labels) if labels is not None else [f"point {i}" for i in range(len(p))]
    bad = np.flatnonzero(~np.isfinite(v) | (v < 0.0))
    if bad.size:
        raise ValueError(f"{names[int(bad[0])]}: v = {v[bad[0]]:g} m/s; a speed is a finite number >= 0")
    lengths = np.hypot(*np.diff(p, axis=0).T)
    pair = v[:-1] + v[1:]
    stalled = np.flatnonzero((lengths > 0.0) & (pair == 0.0))
    if stalled.size:
        k = int(stalled[0]) + 1
        raise ValueError(
            f"{names[k]}: the leg from {names[k - 1]} has v = 0 at both ends, so it is never driven; give one "
            "end a speed > 0, or give a t column"
        )
    return np.concatenate([[0.0], np.cumsum(2.0 * lengths / np.where(pair > 0.0, pair, 1.0))])
