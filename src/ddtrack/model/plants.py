"""Plants the simulator advances, each with its layouts declared (docs/architecture.md).

A plant is a pytree with four pure steps::

    x  = plant.init(body0)                 its state from the initial pose and velocity, BODY [x, y, theta, v, omega]
    u  = plant.saturate(u)                 the actuator limits
    x' = plant.advance(x, u, d, T, solver) one control period under the held input u and wheel disturbance d
    y  = plant.observe(x)                  what its sensors report, as a BODY vector (before noise)

and its layouts: ``state_layout``, ``input_layout`` (whose kind a controller's output must match) and
``logged_layout`` with :meth:`Plant.logged`, the channels it records each period. The plant is the term, the
``solver`` (:class:`~ddtrack.integrators.Solver`, e.g. ``RK4(10)``) the method and step count it is integrated
with. :class:`ODEPlant` is the implementation for a plant given as an ODE (``hold`` and ``derivative``), advanced by
``solver.integrate``; a plant with stiff parts brings its own ``advance``.
"""

from __future__ import annotations

from typing import ClassVar, Protocol

import jax.numpy as jnp
from jax import Array

from .._pytree import pytree_dataclass
from ..integrators import Solver
from ..layout import BODY, NOTHING, VELOCITY_COMMAND, WHEEL_TORQUES, Layout, pose, velocity
from .dynamics import body_acceleration, pose_rate
from .params import RobotParams

INPUT_KINDS = {WHEEL_TORQUES: "torque", VELOCITY_COMMAND: "velocity"}


class Plant(Protocol):
    """What :func:`ddtrack.sim.simulate` needs of a plant."""

    state_layout: ClassVar[Layout]
    input_layout: ClassVar[Layout]
    logged_layout: ClassVar[Layout]

    @property
    def input_kind(self) -> str:
        """``"torque"`` (wheel torques [N m]) or ``"velocity"`` ((v [m/s], omega [rad/s])), from ``input_layout``."""
        ...

    def init(self, body: Array) -> Array:
        """The state at rest in the :data:`~ddtrack.layout.BODY` state ``body`` (the initial pose and velocity)."""
        ...

    def saturate(self, u: Array) -> Array:
        """``u`` within the actuator limits (e.g. |tau| <= max_torque [N m])."""
        ...

    def advance(self, x: Array, u: Array, tau_dist: Array, period: Array | float, solver: Solver) -> Array:
        """The state one ``period`` [s] later under the held input ``u`` and wheel disturbance torques ``tau_dist``
        (2,) [N m] (model.md §1.3), integrated by ``solver`` (its method in its ``substeps`` steps, static)."""
        ...

    def observe(self, x: Array) -> Array:
        """What the plant's sensors report, as a :data:`~ddtrack.layout.BODY` vector."""
        ...

    def logged(self, x: Array, u: Array) -> dict[str, Array]:
        """The ``logged_layout`` channels of a period from its state ``x`` and held input ``u``."""
        ...


class ODEPlant:
    """A plant given as x_dot = ``derivative(x, u, d)`` from ``hold(x, u)``, advanced by the solver (model.md §2.7).

    The default state is :data:`~ddtrack.layout.BODY` itself; a subclass with more states overrides ``init`` and
    ``observe`` with its ``state_layout``.
    """

    state_layout: ClassVar[Layout] = BODY
    input_layout: ClassVar[Layout] = WHEEL_TORQUES
    logged_layout: ClassVar[Layout] = NOTHING

    @property
    def input_kind(self) -> str:
        return INPUT_KINDS[self.input_layout]

    def hold(self, x: Array, u: Array) -> Array:
        """The state at the start of a period once the held input applies (unchanged, for torques)."""
        return x

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        raise NotImplementedError

    def init(self, body: Array) -> Array:
        return body

    def advance(self, x: Array, u: Array, tau_dist: Array, period: Array | float, solver: Solver) -> Array:
        return solver.integrate(lambda z: self.derivative(z, u, tau_dist), self.hold(x, u), period)

    def observe(self, x: Array) -> Array:
        return x

    def logged(self, x: Array, u: Array) -> dict[str, Array]:
        return {}


@pytree_dataclass
class DynamicPlant(ODEPlant):
    """The Lagrangian robot (model.md §1.3): input wheel torques [N m], saturated at ``params.max_torque``; logs
    the torques it applied (``tau_r``, ``tau_l``)."""

    params: RobotParams
    logged_layout: ClassVar[Layout] = WHEEL_TORQUES

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        _, _, theta = pose(x)
        nu = velocity(x)
        return jnp.concatenate([pose_rate(theta, nu[0], nu[1]), body_acceleration(self.params, nu, u, tau_dist)])

    def saturate(self, u: Array) -> Array:
        return jnp.clip(u, -self.params.max_torque, self.params.max_torque)

    def logged(self, x: Array, u: Array) -> dict[str, Array]:
        return WHEEL_TORQUES.columns(u)


@pytree_dataclass
class KinematicPlant(ODEPlant):
    """The unicycle with ideal velocity tracking: input nu = (v, omega), applied at once and held.

    Disturbances have no effect (there are no torques); for tests and the kinematic baseline.
    """

    input_layout: ClassVar[Layout] = VELOCITY_COMMAND

    def hold(self, x: Array, u: Array) -> Array:
        return x.at[3:5].set(u)  # the velocities of BODY

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        _, _, theta = pose(x)
        nu = velocity(x)
        return jnp.concatenate([pose_rate(theta, nu[0], nu[1]), jnp.zeros(2)])

    def saturate(self, u: Array) -> Array:
        return u
