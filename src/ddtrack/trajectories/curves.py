"""Smooth references: line, circle, figure-eight, sinusoid (model.md §4.2)."""

from __future__ import annotations

import math
from typing import Annotated

import jax.numpy as jnp
from jax import Array
from pydantic import Field

from .._pytree import FloatVector, pytree_dataclass
from ..parameters import MAX_COORDINATE, Length, Parameters, Position, Positive, declared
from .base import ParametricCurve


class LineParameters(Parameters):
    """A straight line's parameters."""

    speed: Positive = Field(0.5, description="v_r [m/s].")
    start: Position = Field((0.0, 0.0), description="Position at t = 0 [m].")
    heading: float = Field(0.0, description="Direction [rad].")


class CircleParameters(Parameters):
    """A circle's parameters."""

    center: Position = Field((0.0, 0.0), description="Centre [m].")
    radius: Length = Field(2.0, description="Radius [m].")
    speed: Positive = Field(0.5, description="v_r [m/s].")
    start_angle: float = Field(-math.pi / 2, description="Polar angle of the start point about the centre [rad].")
    clockwise: bool = Field(False, description="Direction of travel.")


class FigureEightParameters(Parameters):
    """A figure eight's parameters."""

    center: Position = Field((0.0, 0.0), description="Crossing point [m].")
    size: Length = Field(3.0, description="Half-width [m].")
    period: Positive = Field(60.0, description="Time for both lobes [s].")


class SinusoidParameters(Parameters):
    """A sinusoid's parameters."""

    start: Position = Field((0.0, 0.0), description="Position at t = 0 [m].")
    heading: float = Field(0.0, description="Direction of the axis [rad].")
    speed: Positive = Field(0.5, description="Speed along the axis [m/s].")
    amplitude: Annotated[float, Field(ge=0.0, le=MAX_COORDINATE)] = Field(1.0, description="Lateral amplitude [m].")
    wavelength: Length = Field(10.0, description="Wavelength along the axis [m].")


@pytree_dataclass
class Line(ParametricCurve):
    """Straight line at constant speed; the paper's Case 1 is ``heading = pi/4`` (y = x) from the origin.

    Attributes: ``start`` (2,) [m], position at t = 0; ``heading`` [rad]; ``speed`` v_r > 0 [m/s].
    """

    start: FloatVector = declared(LineParameters)
    heading: float = declared(LineParameters)
    speed: float = declared(LineParameters)

    def position(self, t: Array) -> Array:
        direction = jnp.stack([jnp.cos(self.heading), jnp.sin(self.heading)])
        return jnp.asarray(self.start) + self.speed * t * direction


@pytree_dataclass
class Circle(ParametricCurve):
    """Circle of ``radius`` [m] about ``center`` (2,) [m] at ``speed`` [m/s], starting at polar angle
    ``start_angle`` [rad], counter-clockwise unless ``clockwise``."""

    center: FloatVector = declared(CircleParameters)
    radius: float = declared(CircleParameters)
    speed: float = declared(CircleParameters)
    start_angle: float = declared(CircleParameters)
    clockwise: Array | bool = declared(CircleParameters)

    def position(self, t: Array) -> Array:
        direction = jnp.where(self.clockwise, -1.0, 1.0)
        phi = self.start_angle + direction * self.speed * t / self.radius
        return jnp.asarray(self.center) + self.radius * jnp.stack([jnp.cos(phi), jnp.sin(phi)])


@pytree_dataclass
class FigureEight(ParametricCurve):
    """Lemniscate of Gerono, p = center + size [sin(2 pi t / period), sin(4 pi t / period) / 2].

    ``size`` is the half-width [m]; both lobes take ``period`` [s]. With w = 2 pi / period the speed
    varies between sqrt(7)/4*size*w (where cos^2(wt) = 3/8) and sqrt(2)*size*w (at the crossing): it never stops.
    """

    center: FloatVector = declared(FigureEightParameters)
    size: float = declared(FigureEightParameters)
    period: float = declared(FigureEightParameters)

    def position(self, t: Array) -> Array:
        phase = 2.0 * jnp.pi * t / self.period
        return jnp.asarray(self.center) + self.size * jnp.stack([jnp.sin(phase), jnp.sin(2.0 * phase) / 2.0])


@pytree_dataclass
class Sinusoid(ParametricCurve):
    """A sine wave about a straight axis: the axis is run at ``speed`` [m/s] from ``start`` along
    ``heading`` [rad], with lateral ``amplitude`` [m] and ``wavelength`` [m] along the axis."""

    start: FloatVector = declared(SinusoidParameters)
    heading: float = declared(SinusoidParameters)
    speed: float = declared(SinusoidParameters)
    amplitude: float = declared(SinusoidParameters)
    wavelength: float = declared(SinusoidParameters)

    def position(self, t: Array) -> Array:
        along = self.speed * t
        across = self.amplitude * jnp.sin(2.0 * jnp.pi * along / self.wavelength)
        c, s = jnp.cos(self.heading), jnp.sin(self.heading)
        return jnp.asarray(self.start) + jnp.stack([c * along - s * across, s * along + c * across])
