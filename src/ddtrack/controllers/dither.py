"""A small random dither on an outer law's command, for identification experiments (model.md §3.7)."""

from __future__ import annotations

from typing import Any

import jax
from jax import Array

from .._pytree import FloatVector, pytree_dataclass
from ..trajectories import Reference
from .base import Logs, VelocityCommand


@pytree_dataclass
class Dithered:
    """``law``'s command plus Gaussian noise of ``std`` = (sigma_v [m/s], sigma_omega [rad/s]), drawn
    from the controller's key each period. It decorrelates the command from the measured velocity,
    which makes the command's effect identifiable (their closed-loop correlation is about 0.97)."""

    law: Any
    std: FloatVector = (0.05, 0.1)

    def init(self, x0: Array, ref0: Reference, key: Array) -> tuple[Any, Array]:
        law_key, dither_key = jax.random.split(key)
        return self.law.init(x0, ref0, law_key), dither_key

    def command(
        self, t: Array, y: Array, ref: Reference, memory: tuple[Any, Array]
    ) -> tuple[VelocityCommand, tuple[Any, Array], Logs]:
        law_memory, key = memory
        command, law_memory, logs = self.law.command(t, y, ref, law_memory)
        key, draw = jax.random.split(key)
        nu_c = command.nu_c + jax.numpy.asarray(self.std) * jax.random.normal(draw, (2,))
        return command._replace(nu_c=nu_c), (law_memory, key), logs

    def observe(self, memory: tuple[Any, Array], saturated: Array) -> tuple[Any, Array]:
        return self.law.observe(memory[0], saturated), memory[1]
