"""The controller protocol and the cascade of an outer velocity law over an inner torque law.

One calling convention for every controller (docs/architecture.md)::

    memory = controller.init(x0, ref0, key)
    u, memory, logs = controller.step(t, y, ref, memory)

``y`` is the measured state [x, y, theta, v, omega]; ``u`` is what the plant takes (wheel torques
[N m], or (v, omega) for a kinematic plant); ``logs`` is a flat dict of float64 scalars that is
recorded and never fed back. Everything that evolves lives in ``memory``.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple, Protocol

import jax.numpy as jnp
from jax import Array

from .._pytree import pytree_dataclass
from ..layout import VELOCITY_COMMAND
from ..trajectories import Reference

Logs = dict[str, Array]


def commanded(nu_c: Array) -> Logs:
    """The logs of a velocity command (v_c, omega_c) [m/s, rad/s]: ``v_cmd`` and ``omega_cmd``, read by name."""
    return {f"{name}_cmd": VELOCITY_COMMAND.read(nu_c, name) for name in VELOCITY_COMMAND.names}


class Controller(Protocol):
    """What the simulator needs of a controller: ``init`` once, then ``step`` every control period. A controller
    may declare ``output_kind`` (``"torque"`` or ``"velocity"``), which the simulator checks against the plant's
    ``input_kind``."""

    def init(self, x0: Array, ref0: Reference, key: Array) -> Any:
        """The initial memory, from the initial state ``x0`` (5,), the reference at t = 0 and a PRNG ``key``
        (the run's controller stream, for whatever the controller draws)."""
        ...

    def step(self, t: Array, y: Array, ref: Reference, memory: Any) -> tuple[Array, Any, Logs]:
        """One control period at time ``t`` [s] from the measured state ``y`` (5,) and the reference: the plant
        input (wheel torques [N m], or (v [m/s], omega [rad/s]) for a kinematic plant), the next memory and
        the logs."""
        ...


class VelocityCommand(NamedTuple):
    """What an outer law hands the inner loop."""

    nu_c: Array  #: commanded (v_c [m/s], omega_c [rad/s])
    nu_c_dot: Array  #: its time derivative (analytic, model.md §2.5)
    feedback: Array  #: extra term added to u of eq. 11 (strict backstepping cross term; zero otherwise)
    saturated: Array  #: 1.0 when a velocity clamp was active, else 0.0


class VelocityLaw(Protocol):
    """An outer (kinematic) law of a :class:`Cascade`: state and reference in, velocity command out."""

    def init(self, x0: Array, ref0: Reference, key: Array) -> Any:
        """The initial memory (see :meth:`Controller.init`)."""
        ...

    def command(self, t: Array, y: Array, ref: Reference, memory: Any) -> tuple[VelocityCommand, Any, Logs]:
        """The velocity command for time ``t`` [s] and measured state ``y`` (5,), the next memory, the logs."""
        ...

    def observe(self, memory: Any, saturated: Array) -> Any:
        """Told after the inner loop whether this period saturated (1.0) or not; returns the memory."""


class TorqueLaw(Protocol):
    """An inner (dynamic) loop of a :class:`Cascade`: velocity command in, wheel torques out (model.md §2.5, 2.6)."""

    def init(self, x0: Array, ref0: Reference, key: Array) -> Any:
        """The initial memory (see :meth:`Controller.init`)."""
        ...

    def torque(self, y: Array, command: VelocityCommand, memory: Any) -> tuple[Array, Array, Any]:
        """Wheel torques (tau_R, tau_L) [N m] for the measured state ``y`` (5,), saturated at the nominal
        ``max_torque``; 1.0 if the limit acted (else 0.0); the next memory."""
        ...


@pytree_dataclass
class Cascade:
    """An outer velocity law over an inner torque law, so baselines share inner loops (docs/architecture.md).

    Logs: ``v_cmd`` [m/s], ``omega_cmd`` [rad/s], ``saturated`` (1.0 when a velocity clamp or the
    torque limit was active), plus the outer law's logs, plus ``inner.logs(memory)`` of an inner law
    that has memory worth recording (e.g. adapted parameters), for the memory this period's torque used.
    """

    outer: Any
    inner: Any
    output_kind: ClassVar[str] = "torque"  #: what the inner loop hands the plant

    def init(self, x0: Array, ref0: Reference, key: Array) -> tuple[Any, Any]:
        return self.outer.init(x0, ref0, key), self.inner.init(x0, ref0, key)

    def step(self, t: Array, y: Array, ref: Reference, memory: tuple[Any, Any]) -> tuple[Array, Any, Logs]:
        outer_memory, inner_memory = memory
        command, outer_memory, outer_logs = self.outer.command(t, y, ref, outer_memory)
        inner_logs = self.inner.logs(inner_memory) if hasattr(self.inner, "logs") else {}
        tau, torque_saturated, inner_memory = self.inner.torque(y, command, inner_memory)
        saturated = jnp.maximum(command.saturated, torque_saturated)
        outer_memory = self.outer.observe(outer_memory, saturated)
        logs = {
            **commanded(command.nu_c),
            "saturated": saturated,
            **outer_logs,
            **inner_logs,
        }
        return tau, (outer_memory, inner_memory), logs


@pytree_dataclass
class VelocityOutput:
    """An outer velocity law alone, its (v_c, omega_c) handed to the robot as its velocity command (ROS's cmd_vel):
    ``[controller] inner = "none"`` (model.md §2.7). The strict cross term and nu_c's derivative have no inner loop
    to enter, so they are dropped.

    Logs: as :class:`Cascade`'s, ``v_cmd`` [m/s], ``omega_cmd`` [rad/s], ``saturated`` (1.0 when a velocity clamp
    was active), plus the outer law's logs.
    """

    outer: Any
    output_kind: ClassVar[str] = "velocity"  #: what the law hands the plant

    def init(self, x0: Array, ref0: Reference, key: Array) -> Any:
        return self.outer.init(x0, ref0, key)

    def step(self, t: Array, y: Array, ref: Reference, memory: Any) -> tuple[Array, Any, Logs]:
        command, memory, outer_logs = self.outer.command(t, y, ref, memory)
        memory = self.outer.observe(memory, command.saturated)
        logs = {**commanded(command.nu_c), "saturated": command.saturated, **outer_logs}
        return command.nu_c, memory, logs
