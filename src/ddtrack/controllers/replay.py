"""Open loop: a plan of timed velocity commands replayed as it is (``[controller] kind = "replay"``), so that a
simulated robot can be driven by the plan ``ddtrack excite`` writes, as a real one is, and its log identified."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jax import Array

from .._pytree import pytree_dataclass
from ..trajectories import Reference
from .base import Logs, commanded

#: [s] relative slack (at least 1 ns) under which a row's time counts as reached: t = k T_c picks row k even when
#: k T_c rounds a few ulps below the row's time
TIME_SLACK = 1e-9


@pytree_dataclass
class Replay:
    """A plan of velocity commands, each held from its time until the next row's (``ddtrack excite`` writes one).

    It is open loop: it ignores the measured state and the reference, so the run's tracking metrics measure nothing
    about a controller, only where the plan took the robot against whatever reference the scenario names.

    ``times`` (n,) [s], strictly increasing; ``commands`` (n, 2) of (v [m/s], omega [rad/s]); ``end`` [s], after
    ``times[-1]``, when the plan is over. At time t it outputs the row with the largest ``times[i] <= t`` (within
    :data:`TIME_SLACK`), (0, 0) before ``times[0]`` and from ``end`` on: a plan that has run out stops the robot
    rather than leaving it driving. Logs ``v_cmd`` [m/s], ``omega_cmd`` [rad/s] and ``saturated`` (always 0: there
    is no clamp; the plant's own limits still act).
    """

    times: Array
    commands: Array
    end: Array | float
    output_kind: ClassVar[str] = "velocity"  #: (v, omega) for a velocity-commanded plant

    def init(self, x0: Array, ref0: Reference, key: Array) -> tuple[()]:
        return ()

    def command_at(self, t: Array) -> Array:
        """(v [m/s], omega [rad/s]) of the plan at time ``t`` [s]."""
        reached = t + TIME_SLACK * jnp.maximum(1.0, jnp.abs(t))
        row = jnp.searchsorted(self.times, reached, side="right") - 1
        running = (row >= 0) & (reached < self.end)
        return jnp.where(running, self.commands[jnp.maximum(row, 0)], jnp.zeros(2))

    def step(self, t: Array, y: Array, ref: Reference, memory: tuple[()]) -> tuple[Array, tuple[()], Logs]:
        nu_c = self.command_at(t)
        return nu_c, memory, {**commanded(nu_c), "saturated": jnp.zeros((), nu_c.dtype)}
