"""Piecewise paths of straight segments and circular arcs at constant speed: the square (model.md §4.3)
and waypoint lists with rounded corners.

Sharp corners (radius 0) give a heading jump with omega_r = 0 there: the jump is not represented
as an impulse, which is how tracking of "non-continuous gradient" references is usually posed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np
from jax import Array

from .._pytree import pytree_dataclass, static_field
from ..geometry import wrap_angle
from .base import Reference


@pytree_dataclass
class PiecewisePath:
    """Segments i = 0..n-1 start at ``starts[i]`` with heading ``headings[i]`` and curvature
    ``curvatures[i]`` (0 for a straight segment) at arc length ``offsets[i]``; the path ends at
    ``length``. Traversed at ``speed`` [m/s]; ``loop`` repeats it, otherwise the reference stops at
    the end (v_r = 0 from then on)."""

    starts: Array
    headings: Array
    curvatures: Array
    offsets: Array
    length: float
    speed: float
    loop: bool = static_field(default=False, why="a closed path wraps its arc length")

    def __call__(self, t: Array | float) -> Reference:
        travelled = self.speed * jnp.asarray(t, dtype=float)
        moving: Array | bool
        if self.loop:
            s, moving = jnp.mod(travelled, self.length), True
        else:
            s, moving = jnp.minimum(travelled, self.length), travelled < self.length
        i = jnp.clip(jnp.searchsorted(self.offsets, s, side="right") - 1, 0, self.offsets.shape[0] - 1)
        sigma, heading, kappa = s - self.offsets[i], self.headings[i], self.curvatures[i]
        straight = kappa == 0.0
        safe_kappa = jnp.where(straight, 1.0, kappa)  # keeps the unused arc branch finite
        turned = heading + kappa * sigma
        arc = jnp.stack([jnp.sin(turned) - jnp.sin(heading), jnp.cos(heading) - jnp.cos(turned)]) / safe_kappa
        line = sigma * jnp.stack([jnp.cos(heading), jnp.sin(heading)])
        p = self.starts[i] + jnp.where(straight, line, arc)
        v = jnp.where(moving, jnp.asarray(self.speed, float), 0.0)
        zero = jnp.zeros_like(v)
        return Reference(p[0], p[1], wrap_angle(turned), v, kappa * v, zero, zero)


def polyline_path(
    points: Sequence[Sequence[float]], *, speed: float, corner_radius: float = 0.0, loop: bool = False
) -> PiecewisePath:
    """Path through ``points`` (n >= 2, [m]) with every interior corner rounded by a circular fillet.

    Raises
    ------
    ValueError
        On fewer than two points, NaN, a repeated point, a non-positive speed, a fillet that does
        not fit between its neighbours, or a rounded U-turn (direction reversed).
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
        raise ValueError(f"need at least two [x, y] points, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points must be finite numbers (found NaN or inf)")
    if not (math.isfinite(speed) and speed > 0.0):
        raise ValueError(f"speed must be > 0, got {speed}")
    if not (math.isfinite(corner_radius) and corner_radius >= 0.0):
        raise ValueError(f"corner radius must be >= 0, got {corner_radius}")
    legs = np.diff(pts, axis=0)
    leg_lengths = np.hypot(legs[:, 0], legs[:, 1])
    repeated = np.flatnonzero(leg_lengths == 0.0)
    if repeated.size:
        raise ValueError(f"point {repeated[0] + 1} repeats point {repeated[0]}; remove the duplicate")
    directions = np.arctan2(legs[:, 1], legs[:, 0])
    turns = np.angle(np.exp(1j * np.diff(directions)))  # signed turn at each interior point, (-pi, pi]
    if corner_radius > 0.0 and np.any(np.abs(turns) >= np.pi - 1e-9):
        k = int(np.flatnonzero(np.abs(turns) >= np.pi - 1e-9)[0]) + 1
        raise ValueError(f"the path reverses direction at point {k}; a reversal cannot be rounded")
    tangents = corner_radius * np.tan(np.abs(turns) / 2.0)  # fillet tangent length at each corner
    trim = np.zeros((len(legs), 2))  # length cut from the start and the end of each leg
    trim[1:, 0] = tangents
    trim[:-1, 1] = tangents
    if np.any(trim.sum(axis=1) > leg_lengths + 1e-12):
        k = int(np.flatnonzero(trim.sum(axis=1) > leg_lengths + 1e-12)[0])
        raise ValueError(
            f"corner radius {corner_radius} m does not fit on leg {k} "
            f"({leg_lengths[k]:.3g} m long); use a smaller radius"
        )
    starts, headings, curvatures, lengths = [], [], [], []
    for k, (direction, leg_length) in enumerate(zip(directions, leg_lengths, strict=True)):
        unit = np.array([math.cos(direction), math.sin(direction)])
        straight = leg_length - trim[k].sum()
        if straight > 0.0:
            starts.append(pts[k] + trim[k, 0] * unit)
            headings.append(direction)
            curvatures.append(0.0)
            lengths.append(straight)
        if k < len(turns) and tangents[k] > 0.0:
            starts.append(pts[k + 1] - tangents[k] * unit)
            headings.append(direction)
            curvatures.append(math.copysign(1.0 / corner_radius, turns[k]))
            lengths.append(corner_radius * abs(turns[k]))
    offsets = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    return PiecewisePath(
        starts=jnp.asarray(np.array(starts)),
        headings=jnp.asarray(headings),
        curvatures=jnp.asarray(curvatures),
        offsets=jnp.asarray(offsets),
        length=float(np.sum(lengths)),
        speed=float(speed),
        loop=loop,
    )


def square(
    *, corner: Sequence[float] = (10.0, 0.0), side: float = 10.0, speed: float = 0.5, corner_radius: float = 0.0
) -> PiecewisePath:
    """The paper's square (model.md §4.3): corners C0 = corner, C0 + (S, 0), C0 + (S, S), C0 + (0, S),
    counter-clockwise from C0 with heading 0, repeating every lap of 4S/v_r (sharp corners).

    With ``corner_radius`` r_c > 0 the corners C1, C2, C3 are filleted (lap length 4S - 6 r_c + 3 pi r_c / 2).
    """
    x0, y0 = corner
    points = [(x0, y0), (x0 + side, y0), (x0 + side, y0 + side), (x0, y0 + side), (x0, y0)]
    return polyline_path(points, speed=speed, corner_radius=corner_radius, loop=True)
