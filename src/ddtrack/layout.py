"""Named layouts of the vectors that flow between plant, controller and simulator (docs/architecture.md).

A plant's state, its input and the channels it logs are declared as a :class:`Layout` (names and units), so that
every layer reads a vector by name, and a plant with more states (wheel angles, motor currents, slip) cannot be
read silently as one with five. Every plant shows its controller the same :data:`BODY` vector, the measured pose
and body velocity; controllers read it through :func:`pose` and :func:`velocity`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import jax.numpy as jnp
from jax import Array


@dataclass(frozen=True)
class Layout:
    """The names and units of a vector's entries, in order (hashable: static under ``jit``)."""

    names: tuple[str, ...]
    units: tuple[str, ...]

    def __post_init__(self) -> None:
        if len(self.names) != len(self.units) or len(set(self.names)) != len(self.names):
            raise ValueError(f"a layout needs one unit per name and distinct names: {self.names} {self.units}")

    def __len__(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Where ``name`` sits; a ValueError naming the layout's channels if it is not one."""
        if name not in self.names:
            raise ValueError(f"no channel '{name}' in the layout {self.names}")
        return self.names.index(name)

    def unit(self, name: str) -> str:
        """The unit of ``name``."""
        return self.units[self.index(name)]

    def read(self, vector: Any, name: str) -> Any:
        """The entry ``name`` of ``vector`` (a JAX or NumPy array whose last axis is the layout's)."""
        return vector[..., self.index(name)]

    def take(self, vector: Any, *names: str) -> Array:
        """The entries ``names`` of ``vector``, stacked in that order along its last axis."""
        return jnp.stack([self.read(vector, name) for name in names], axis=-1)

    def span(self, vector: Any, first: str, last: str) -> Any:
        """The entries from ``first`` to ``last``, both included, of ``vector`` (the last axis), as one slice."""
        return vector[..., self.index(first) : self.index(last) + 1]

    def columns(self, vectors: Any) -> dict[str, Any]:
        """Each channel of ``vectors`` (..., len(self); a JAX or NumPy array) by name."""
        return {name: vectors[..., i] for i, name in enumerate(self.names)}


#: what every plant shows its controller (measured, noise added) and what the errors and metrics read (true)
BODY = Layout(("x", "y", "theta", "v", "omega"), ("m", "m", "rad", "m/s", "rad/s"))
#: the posture error e_p = R(theta)^T (q_r - q) of the reference in the robot's frame (model.md §2.2)
POSTURE_ERROR = Layout(("e_x", "e_y", "e_theta"), ("m", "m", "rad"))
#: wheel torques, the input of a torque-driven plant
WHEEL_TORQUES = Layout(("tau_r", "tau_l"), ("N m", "N m"))
#: body velocity, the input of a velocity-driven plant
VELOCITY_COMMAND = Layout(("v", "omega"), ("m/s", "rad/s"))
#: no channels (a plant that logs nothing of its own)
NOTHING = Layout((), ())


def pose(y: Array) -> tuple[Array, Array, Array]:
    """(x [m], y [m], theta [rad]) of a :data:`BODY` vector."""
    return y[0], y[1], y[2]


def position(y: Array) -> Array:
    """(x [m], y [m]) of a :data:`BODY` vector, as one (2,) array."""
    return y[0:2]


def pose_vector(y: Array) -> Array:
    """(x [m], y [m], theta [rad]) of a :data:`BODY` vector, as one (3,) array."""
    return y[0:3]


def velocity(y: Array) -> Array:
    """(v [m/s], omega [rad/s]) of a :data:`BODY` vector, as one (2,) array."""
    return y[3:5]
