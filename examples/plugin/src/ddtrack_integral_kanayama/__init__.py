"""A ddtrack controller plugin: Kanayama's law with integral action on the along-track error.

Unmodelled wheel friction makes plain backstepping lag its reference by a few centimetres (model.md §4.5); the
integral removes that lag. The law is an outer velocity loop over ddtrack's shared inner loop
(:class:`ddtrack.scenario.InnerLoopConfig`), and its integral lives in ``memory``, which ``command`` returns
instead of mutating. ``register`` is the ``ddtrack.controllers`` entry point (pyproject.toml): ddtrack calls it
the first time it looks a controller kind up, and from then on ``kind = "integral_kanayama"`` works in scenario
files and every command.
"""

from __future__ import annotations

from typing import Any, Literal

import jax
import jax.numpy as jnp
from pydantic import Field

import ddtrack
from ddtrack.controllers import Cascade, VelocityCommand
from ddtrack.geometry import posture_error
from ddtrack.model import RobotParams
from ddtrack.parameters import NonNegative, Parameters, Positive, declared
from ddtrack.scenario import InnerLoopConfig


class IntegralParameters(Parameters):
    """The integral action's parameters, declared once: the scenario's keys and the controller's defaults."""

    ki: NonNegative = Field(0.5, description="Integral gain on the along-track error e_x [1/s^2].")
    gate: Positive = Field(0.2, description="Integrate only while the tracking error is below this [m].")


@ddtrack.pytree_dataclass  # the simulator is jitted: a controller is a frozen dataclass and a pytree of its parameters
class IntegralKanayama:
    """Kanayama's law with v_c += ki * integral of e_x. In: y = [x, y, theta, v, omega] and the reference;
    out: (v_c [m/s], omega_c [rad/s]) and its feed-forward derivative (the inner loop's K_c absorbs the rest)."""

    kx: Any = 1.0  # [1/s]; Any: tune and the environment's gains mode put arrays here
    ky: Any = 55.0  # [1/m^2]
    ktheta: Any = 15.0  # [1/m]
    ki: float = declared(IntegralParameters)
    control_period: float = 0.01  # [s]
    gate: float = declared(IntegralParameters)  # no wind-up

    def init(self, x0: jax.Array, ref0: Any, key: jax.Array) -> jax.Array:
        """The memory: the integral of e_x [m s], zero."""
        return jnp.asarray(0.0)

    def command(self, t: Any, y: jax.Array, ref: Any, memory: jax.Array) -> tuple[Any, jax.Array, dict]:
        """The velocity command, the new integral and the logs (recorded, never fed back)."""
        e_x, e_y, e_th = posture_error(y[0], y[1], y[2], ref.x, ref.y, ref.theta)  # model.md §2.2
        integral = memory + jnp.where(jnp.hypot(e_x, e_y) < self.gate, e_x * self.control_period, 0.0)
        v_c = ref.v * jnp.cos(e_th) + self.kx * e_x + self.ki * integral
        omega_c = ref.omega + ref.v * (self.ky * e_y + self.ktheta * jnp.sin(e_th))
        command = VelocityCommand(
            jnp.stack([v_c, omega_c]), jnp.stack([ref.v_dot, ref.omega_dot]), jnp.zeros(2), jnp.asarray(0.0)
        )  # no strict cross term, no velocity clamp
        return command, integral, {"integral_e_x": integral}

    def observe(self, memory: jax.Array, saturated: Any) -> jax.Array:
        """Told whether the torque limit acted; this law ignores it."""
        return memory


class IntegralKanayamaConfig(IntegralParameters, InnerLoopConfig):
    """Kanayama backstepping with integral action on the along-track error, over the shared inner loop."""

    kind: Literal["integral_kanayama"]
    gains: tuple[Positive, Positive, Positive] = Field((1.0, 55.0, 15.0), description="[Kx, Ky, Ktheta].")

    def build(self, nominal: RobotParams, control_period: float, key: jax.Array) -> Cascade:
        """The controller; ``key`` is unused (nothing is drawn)."""
        kx, ky, ktheta = self.gains
        law = IntegralKanayama(kx, ky, ktheta, self.ki, control_period, self.gate)
        return Cascade(law, self.build_inner(nominal, control_period))


def register() -> None:
    """The entry point: register the kind with what it can do (Kanayama gains, so the gains mode takes it; a
    rollout is differentiable in them, so ``ddtrack tune`` takes it)."""
    ddtrack.register_controller(IntegralKanayamaConfig, has_kanayama_gains=True, differentiable=True)
