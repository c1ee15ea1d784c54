"""Smooth references: line, circle, figure-eight, sinusoid (model.md §4.2)."""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array

from .._pytree import FloatVector, pytree_dataclass, static_field
from .base import ParametricCurve


@pytree_dataclass
class Line(ParametricCurve):
    """Straight line at constant speed; the paper's Case 1 is ``heading = pi/4`` (y = x) from the origin.

    Attributes: ``start`` (2,) [m], position at t = 0; ``heading`` [rad]; ``speed`` v_r > 0 [m/s].
    """

    start: FloatVector = (0.0, 0.0)
    heading: float = 0.0
    speed: float = 0.5

    def position(self, t: Array) -> Array:
        direction = jnp.stack([jnp.cos(self.heading), jnp.sin(self.heading)])
        return jnp.asarray(self.start) + self.speed * t * direction


@pytree_dataclass
class Circle(ParametricCurve):
    """Circle of ``radius`` [m] about ``center`` (2,) [m] at ``speed`` [m/s], starting at polar angle
    ``start_angle`` [rad], counter-clockwise unless ``clockwise``."""

    center: FloatVector = (0.0, 0.0)
    radius: float = 2.0
    speed: float = 0.5
    start_angle: float = -jnp.pi / 2
    clockwise: bool = static_field(default=False)

    def position(self, t: Array) -> Array:
        direction = -1.0 if self.clockwise else 1.0
        phi = self.start_angle + direction * self.speed * t / self.radius
        return jnp.asarray(self.center) + self.radius * jnp.stack([jnp.cos(phi), jnp.sin(phi)])


@pytree_dataclass
class FigureEight(ParametricCurve):
    """Lemniscate of Gerono, p = center + size [sin(2 pi t / period), sin(4 pi t / period) / 2].

    ``size`` is the half-width [m]; both lobes take ``period`` [s]. With w = 2 pi / period the speed
    varies between sqrt(7)/4*size*w (where cos^2(wt) = 3/8) and sqrt(2)*size*w (at the crossing): it never stops.
    """

    center: FloatVector = (0.0, 0.0)
    size: float = 3.0
    period: float = 60.0

    def position(self, t: Array) -> Array:
        phase = 2.0 * jnp.pi * t / self.period
        return jnp.asarray(self.center) + self.size * jnp.stack([jnp.sin(phase), jnp.sin(2.0 * phase) / 2.0])


@pytree_dataclass
class Sinusoid(ParametricCurve):
    """A sine wave about a straight axis: the axis is run at ``speed`` [m/s] from ``start`` along
    ``heading`` [rad], with lateral ``amplitude`` [m] and ``wavelength`` [m] along the axis."""

    start: FloatVector = (0.0, 0.0)
    heading: float = 0.0
    speed: float = 0.5
    amplitude: float = 1.0
    wavelength: float = 10.0

    def position(self, t: Array) -> Array:
        along = self.speed * t
        across = self.amplitude * jnp.sin(2.0 * jnp.pi * along / self.wavelength)
        c, s = jnp.cos(self.heading), jnp.sin(self.heading)
        return jnp.asarray(self.start) + jnp.stack([c * along - s * across, s * along + c * across])
