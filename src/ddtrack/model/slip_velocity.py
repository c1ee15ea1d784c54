"""A velocity-commanded robot on a floor of finite grip: the slip plant's wheels under a PI wheel-speed loop
(model.md §1.10, the velocity-driven variant; the loop is model.md §1.7's ``VelocityDriver``).

The controller commands (v*, omega*) as ROS's ``cmd_vel`` does; each wheel's PI loop compares the set-point W nu*
with the wheel's own spin phi_dot_i, which is what its encoder measures. On a gripping floor that spin is the
body's speed; on a slippery one it is not, and the loop holds the wheels' spin while the body lags behind.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import ClassVar

import jax.numpy as jnp
from jax import Array

from .._pytree import pytree_dataclass, static_field
from ..integrators import Solver, rosenbrock2
from ..layout import VELOCITY_COMMAND, Layout, velocity
from ..parameters import TIMING
from .dynamics import wheel_speeds
from .motor_plants import armature_voltage, cruise_integral
from .motors import VelocityDriver
from .params import RobotParams
from .slip import SLIP_LOGS, SLIP_STATE, SlipPlant, broadcast_like, check_drawn, slip_integration, wheel_spins

#: the state of :class:`SlipVelocityPlant`: the slip plant's, then the integral of each wheel's speed error
SLIP_VELOCITY_STATE = Layout((*SLIP_STATE.names, "pi_r", "pi_l"), (*SLIP_STATE.units, "rad", "rad"))
#: what it logs: the slip plant's channels with the motors' currents and armature voltages after the torques
SLIP_VELOCITY_LOGS = Layout(
    (*SLIP_LOGS.names[:2], "i_r", "i_l", "u_r", "u_l", *SLIP_LOGS.names[2:]),
    (*SLIP_LOGS.units[:2], "A", "A", "V", "V", *SLIP_LOGS.units[2:]),
)
#: the slip plant's states
_SLIP = len(SLIP_STATE)


@pytree_dataclass
class SlipVelocityPlant:
    """The slip plant (model.md §1.10) whose wheels a PI speed loop drives: input (v* [m/s], omega* [rad/s]).

    The set-points are W nu*; each wheel's torque is ``driver.output(integral, set-point, phi_dot_i)``, the loop
    measuring the wheel's spin, and the integrals ``pi_r``, ``pi_l`` [rad] grow at ``driver.integral_rate`` (they
    freeze on a limit). State :data:`SLIP_VELOCITY_STATE`; the controller sees [x, y, theta, u, r].

    Attributes
    ----------
    slip : SlipPlant
        The robot on its floor, with no motor of its own (its torque input is the loop's applied torque).
    driver : VelocityDriver
        The PI loop of each wheel and the motor it drives.
    scheme : str
        ``"rk4"`` or ``"rosenbrock"`` (static); the Rosenbrock step is implicit in the velocities and spins.
    substeps : int or Array
        Sub-steps per control period at least (a number, traced, as :class:`~ddtrack.model.slip.SlipPlant`'s).
    """

    slip: SlipPlant
    driver: VelocityDriver
    scheme: str = static_field(default="rk4", why="the integrator, a different program")
    substeps: Array | int = 1
    state_layout: ClassVar[Layout] = SLIP_VELOCITY_STATE
    input_layout: ClassVar[Layout] = VELOCITY_COMMAND
    logged_layout: ClassVar[Layout] = SLIP_VELOCITY_LOGS

    @property
    def input_kind(self) -> str:
        return "velocity"

    @property
    def params(self) -> RobotParams:
        return self.slip.params

    def init(self, body: Array) -> Array:
        """BODY rolling without slip, and the integrals that hold its speeds (a base that has been cruising)."""
        return jnp.concatenate([self.slip.init(body), cruise_integral(self.params, self.driver, velocity(body))])

    def observe(self, x: Array) -> Array:
        """BODY [x, y, theta, u, r]."""
        return self.slip.observe(x[:_SLIP])

    def saturate(self, u: Array) -> Array:
        """The command as given: the driver's voltage and current limits act in the ODE."""
        return u

    def applied(self, x: Array, u: Array) -> tuple[Array, Array]:
        """(torques [N m], currents [A]) the loop gives at state ``x`` under the command ``u``, each (2,)."""
        setpoint = wheel_speeds(self.params, u)
        tau, current, _, _ = self.driver.output(x[_SLIP:], setpoint, wheel_spins(x))
        return tau, current

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        """[slip plant's rates, integrals' rates] under the loop's torques."""
        tau, _ = self.applied(x, u)
        integral_rate = self.driver.integral_rate(x[_SLIP:], wheel_speeds(self.params, u), wheel_spins(x))
        return jnp.concatenate([self.slip.derivative(x[:_SLIP], tau, tau_dist), integral_rate])

    def advance(self, x: Array, u: Array, tau_dist: Array, period: Array | float, solver: Solver) -> Array:
        """The state one ``period`` [s] later in max(``solver.substeps``, its own) steps (traced): by the solver's
        method where the plant's scheme is explicit, by ROS2 where it is ``"rosenbrock"`` (stiff)."""
        steps = jnp.maximum(solver.substeps, self.substeps)

        def rate(z: Array) -> Array:
            return self.derivative(z, u, tau_dist)

        if self.scheme == "rosenbrock":  # the integrals' own mode is slow (k_i / (k_p + k_e)): stepped explicitly
            return rosenbrock2(rate, x, period, steps, stiff=(3, _SLIP))
        return replace(solver, substeps=steps).integrate(rate, x, period)

    def logged(self, x: Array, u: Array) -> dict[str, Array]:
        """Applied torques, currents, slip speeds and the floor's forces at the start of the period."""
        tau, current = self.applied(x, u)
        floor = self.slip.logged(x[:_SLIP], tau)
        voltage = armature_voltage(self.driver.motor, current, wheel_spins(x))
        return floor | {"i_r": current[0], "i_l": current[1], "u_r": voltage[0], "u_l": voltage[1]}


def slip_velocity_model(
    nominal: RobotParams,
    driver: VelocityDriver,
    *,
    friction: float = 0.8,
    slip_speed: float = 1e-2,
    caster: float | None = None,
    period: float = TIMING.control_period,
    substeps: int = TIMING.substeps,
    scheme: str | None = None,
    com_height: float = 0.0,
) -> Callable[[RobotParams], SlipVelocityPlant]:
    """A ``Setup.plant_model`` giving the :class:`SlipVelocityPlant` of a drawn robot, alone or as a batch; the
    scheme and sub-steps chosen from the ``nominal`` robot as ``slip_plant_model`` does, the loop's proportional
    gain counted in the stiffness. Raises ValueError for J_w <= 0 or a caster not beyond the centre of mass."""
    gain = float(driver.kp)
    l_c, chosen, steps = slip_integration(
        nominal, friction, slip_speed, caster, driver.motor, period, substeps, scheme, gain, com_height
    )

    def plant_model(params: RobotParams) -> SlipVelocityPlant:
        check_drawn(params, l_c)
        mu, eps, held_caster, height = broadcast_like(params, (friction, slip_speed, l_c, com_height))
        count = jnp.broadcast_to(steps, jnp.shape(params.mass))  # an integer per robot, traced
        # no motor: its torque input is the loop's applied torque
        slip = SlipPlant(params, mu, eps, held_caster, com_height=height, substeps=count)  # batched like the rest
        return SlipVelocityPlant(slip, broadcast_like(params, driver), chosen, count)

    return plant_model
