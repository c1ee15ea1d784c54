"""Plants whose wheels are driven by geared DC motors through a driver (model.md §1.7).

The body is the Lagrangian robot of model.md §1.3 with its wheels' spin inertia (§1.6), as in
:class:`~ddtrack.model.DynamicPlant`; what differs is where its wheel torques come from. Each wheel has the same
:class:`~ddtrack.model.motors.DCMotor` (constants referred to the wheel), and the board in front of it decides
what a controller's command means:

* :class:`TorqueDrivenPlant`: a current-controlled board (:func:`~ddtrack.model.motors.torque_driver`), or a
  PWM-only one turning torque into voltage through its model of the motor. The
  controller commands wheel torques; the motor applies them inside the torque-speed curve at the wheels' speed of
  the moment, so a wheel that speeds up within a period loses torque as it goes and never passes its no-load speed.
* :class:`VelocityDrivenPlant`: a board with a PI loop on each wheel's speed
  (:class:`~ddtrack.model.motors.VelocityDriver`), as ROS bases take ``cmd_vel``. The controller commands
  (v*, omega*); the set-points are the wheel speeds W nu*, and the two PI integrators are states of the plant.

Both are advanced by RK4 like ``DynamicPlant`` (the driver evaluated continuously, inside every RK4 stage) and log
the torques the motors applied and the currents they drew, not the commands: the torques are what effort and the
grip a run needed are computed from. :func:`torque_driven_model` and :func:`velocity_driven_model` give the
``Setup.plant_model`` of either for a drawn robot, alone or as a batch; :func:`motor_from_datasheet` the motor of a
preset's datasheet (``ddtrack.robots``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar, Protocol, TypeVar

import jax
import jax.numpy as jnp
from jax import Array

from .._pytree import pytree_dataclass
from ..layout import BODY, VELOCITY_COMMAND, Layout, velocity
from .dynamics import reduced_coriolis, reduced_input_inverse, wheel_friction, wheel_speeds
from .motors import DCMotor, VelocityDriver, drive_torque
from .params import RobotParams
from .plants import DynamicPlant, ODEPlant

#: what a motor-driven plant logs each period: the applied wheel torques (named as DynamicPlant's), the currents and
#: the armature voltages
MOTOR_LOGS = Layout(("tau_r", "tau_l", "i_r", "i_l", "u_r", "u_l"), ("N m", "N m", "A", "A", "V", "V"))
#: the state of :class:`VelocityDrivenPlant`: BODY, then the integral of each wheel's speed error
VELOCITY_DRIVEN_STATE = Layout((*BODY.names, "pi_r", "pi_l"), (*BODY.units, "rad", "rad"))


def armature_voltage(motor: DCMotor, current: Array, wheel_speed: Array) -> Array:
    """R_a i + k_e phi_dot [V]: the voltage across each armature that drives ``current`` at ``wheel_speed`` (what a
    PWM board applies once its own current limit has acted), model.md §1.7 with L_a = 0."""
    return motor.resistance * current + motor.back_emf * wheel_speed


def _motor_logs(motor: DCMotor, tau: Array, current: Array, wheel_speed: Array) -> dict[str, Array]:
    voltage = armature_voltage(motor, current, wheel_speed)
    return {
        "tau_r": tau[0],
        "tau_l": tau[1],
        "i_r": current[0],
        "i_l": current[1],
        "u_r": voltage[0],
        "u_l": voltage[1],
    }


@pytree_dataclass
class TorqueDrivenPlant(ODEPlant):
    """The robot of model.md §1.3 with current-controlled DC motors at its wheels (model.md §1.7).

    Input: the commanded wheel torques [N m], held over a period. Inside the ODE each wheel gets
    ``torque_driver(motor, command, wheel speed)``: the command where the motor can give it, else the nearest end
    of the torque-speed envelope at the wheel's current speed. State: :data:`~ddtrack.layout.BODY`.

    Attributes
    ----------
    params : RobotParams
        The robot, its wheels' spin inertia ``wheel_inertia`` included (which should hold the motors' reflected
        rotor inertia).
    motor : DCMotor
        The motor of each wheel, constants referred to the wheel.
    pwm_model : DCMotor or None
        None: the board controls current. Else it offers PWM only, and turns the torque command into a voltage
        through this model of its motor (:func:`~ddtrack.model.motors.drive_torque`).
    """

    params: RobotParams
    motor: DCMotor
    pwm_model: DCMotor | None = None
    logged_layout: ClassVar[Layout] = MOTOR_LOGS

    def applied(self, x: Array, u: Array) -> tuple[Array, Array]:
        """(torques [N m], currents [A]) the motors give at state ``x`` under the command ``u``, each (2,)."""
        return drive_torque(self.motor, u, wheel_speeds(self.params, velocity(x)), self.pwm_model)

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        """[x_dot, y_dot, theta_dot, v_dot, omega_dot] under the applied, not the commanded, torques."""
        tau, _ = self.applied(x, u)
        return DynamicPlant(self.params).derivative(x, tau, tau_dist)

    def saturate(self, u: Array) -> Array:
        """The command clipped to +- the motor's stall torque [N m] (the speed-dependent limit acts in the ODE)."""
        stall = self.motor.stall_torque
        return jnp.clip(u, -stall, stall)

    def logged(self, x: Array, u: Array) -> dict[str, Array]:
        """``tau_r``, ``tau_l`` [N m] applied, ``i_r``, ``i_l`` [A] drawn and ``u_r``, ``u_l`` [V] across the armatures
        at the start of the period."""
        return _motor_logs(self.motor, *self.applied(x, u), wheel_speeds(self.params, velocity(x)))


def cruise_integral(params: RobotParams, driver: VelocityDriver, nu: Array) -> Array:
    """The PI integrals z_R, z_L [rad] of a base that has been cruising at nu = (v, omega) (model.md §1.7).

    A constant velocity nu needs the wheel torques tau = tau_f(W nu) + B_bar^{-1} V_bar(nu) nu (friction and the
    centre-of-mass offset's term, model.md §1.3), so the currents tau / (eta k_t) and the voltages R_a i + k_e W nu;
    with no speed error all of it comes from the integral, z = u / k_i. At rest this is 0. Zeros instead would make
    a robot that starts moving brake until its integrators wind up, an artefact of the start, not of the
    controller. A speed the motors cannot hold (beyond the no-load speed) gets the integral it would need all the
    same; with k_i = 0 (a P loop) the integrals stay 0.
    """
    speeds = wheel_speeds(params, nu)
    torque = wheel_friction(params, speeds) + reduced_input_inverse(params) @ reduced_coriolis(params, nu)
    motor = driver.motor
    voltage = motor.resistance * torque / (motor.efficiency * motor.torque_constant) + motor.back_emf * speeds
    ki = jnp.asarray(driver.ki, dtype=float)
    return jnp.where(ki != 0.0, voltage / jnp.where(ki != 0.0, ki, 1.0), 0.0)


@pytree_dataclass
class VelocityDrivenPlant(ODEPlant):
    """The robot of model.md §1.3 whose motors a PI wheel-speed loop drives (model.md §1.7), as ``cmd_vel`` does.

    Input: (v* [m/s], omega* [rad/s]), held over a period; the wheel-speed set-points are W nu* (``wheel_speeds``).
    State: :data:`~ddtrack.layout.BODY`, then ``pi_r``, ``pi_l`` [rad], the integrals of the wheels' speed errors
    (:data:`VELOCITY_DRIVEN_STATE`). The driver's continuous-time output gives the torques and its
    ``integral_rate`` (with anti-windup) the integrals' rates. The controller sees BODY.

    Attributes
    ----------
    params : RobotParams
        The robot, its wheels' spin inertia included.
    driver : VelocityDriver
        The PI loop of each wheel and the motor it drives.
    """

    params: RobotParams
    driver: VelocityDriver
    state_layout: ClassVar[Layout] = VELOCITY_DRIVEN_STATE
    input_layout: ClassVar[Layout] = VELOCITY_COMMAND
    logged_layout: ClassVar[Layout] = MOTOR_LOGS

    def init(self, body: Array) -> Array:
        """BODY and the integrals that hold its speeds (:func:`cruise_integral`): the integrators of a base that
        has been cruising at them."""
        return jnp.concatenate([body, cruise_integral(self.params, self.driver, velocity(body))])

    def observe(self, x: Array) -> Array:
        return x[: len(BODY)]

    def setpoints(self, u: Array) -> Array:
        """The wheel-speed set-points W nu* [rad/s] of the command ``u`` = (v*, omega*)."""
        return wheel_speeds(self.params, u)

    def applied(self, x: Array, u: Array) -> tuple[Array, Array]:
        """(torques [N m], currents [A]) the driver gives at state ``x`` under the command ``u``, each (2,)."""
        tau, current, _, _ = self.driver.output(
            x[len(BODY) :], self.setpoints(u), wheel_speeds(self.params, velocity(x))
        )
        return tau, current

    def derivative(self, x: Array, u: Array, tau_dist: Array) -> Array:
        """[BODY rates, integral rates] under the driver's torques; the integrals freeze on a limit (anti-windup)."""
        body, integral = x[: len(BODY)], x[len(BODY) :]
        setpoint, speeds = self.setpoints(u), wheel_speeds(self.params, velocity(body))
        tau, _ = self.applied(x, u)
        body_rate = DynamicPlant(self.params).derivative(body, tau, tau_dist)
        return jnp.concatenate([body_rate, self.driver.integral_rate(integral, setpoint, speeds)])

    def saturate(self, u: Array) -> Array:
        """The command as given: the driver's voltage and current limits act on the motors, in the ODE."""
        return u

    def logged(self, x: Array, u: Array) -> dict[str, Array]:
        """``tau_r``, ``tau_l`` [N m] applied, ``i_r``, ``i_l`` [A] drawn and ``u_r``, ``u_l`` [V] across the armatures
        at the start of the period."""
        return _motor_logs(self.driver.motor, *self.applied(x, u), wheel_speeds(self.params, velocity(x)))


T = TypeVar("T")


def _like_batch(tree: T, params: RobotParams) -> T:
    """``tree`` with every leaf broadcast to the leading batch shape of ``params`` (() for a single robot)."""
    batch = jnp.shape(params.mass)
    return jax.tree_util.tree_map(lambda leaf: jnp.broadcast_to(jnp.asarray(leaf, dtype=float), batch), tree)


def torque_driven_model(motor: DCMotor, pwm_model: DCMotor | None = None) -> Callable[[RobotParams], TorqueDrivenPlant]:
    """A ``Setup.plant_model`` that puts ``motor`` (a current-controlled board, or PWM through ``pwm_model``) at each
    wheel of the drawn robot.

    The motor's leaves take the parameters' leading batch axis, so the same model serves a single run and a batch
    (``dataclasses.replace(setup, plant_model=torque_driven_model(motor))``).
    """

    def plant_model(params: RobotParams) -> TorqueDrivenPlant:
        pwm = None if pwm_model is None else _like_batch(pwm_model, params)
        return TorqueDrivenPlant(params, _like_batch(motor, params), pwm)

    return plant_model


def velocity_driven_model(driver: VelocityDriver) -> Callable[[RobotParams], VelocityDrivenPlant]:
    """A ``Setup.plant_model`` that drives the drawn robot's wheels with ``driver``, for a velocity-output
    controller; alone or as a batch, like :func:`torque_driven_model`."""

    def plant_model(params: RobotParams) -> VelocityDrivenPlant:
        return VelocityDrivenPlant(params, _like_batch(driver, params))

    return plant_model


class MotorSheet(Protocol):
    """What :func:`motor_from_datasheet` reads of a datasheet (``ddtrack.robots.MotorDatasheet`` has it), all at
    the output shaft: voltage [V], stall torque [N m], stall current [A], no-load speed [rad/s] and current [A]."""

    @property
    def voltage(self) -> float:
        """The voltage the figures hold at [V]."""
        ...

    @property
    def stall_torque(self) -> float:
        """Output torque at stall [N m]."""
        ...

    @property
    def stall_current(self) -> float:
        """Current at stall [A]."""
        ...

    @property
    def no_load_speed(self) -> float:
        """Output speed with no load [rad/s]."""
        ...

    @property
    def no_load_current(self) -> float:
        """Current with no load [A]."""
        ...


def motor_from_datasheet(
    sheet: MotorSheet,
    efficiency: float = 1.0,
    current_limit: float | None = None,
    supply_voltage: float | None = None,
) -> DCMotor:
    """The :class:`~ddtrack.model.motors.DCMotor` of a datasheet, e.g. ``preset("turtlebot3_burger").motor``
    (model.md §1.7).

    Parameters
    ----------
    sheet : MotorSheet
        The datasheet's figures at the output shaft, so the motor's constants are the wheel's (gear ratio included).
    efficiency : float, optional
        Gearbox efficiency in (0, 1]; it only splits eta k_t (the stall torque is measured through the gearbox).
    current_limit : float, optional
        The driver's current limit [A]; default the stall current at the supply voltage.
    supply_voltage : float, optional
        The driver's supply [V]; default the datasheet's voltage.

    Returns
    -------
    DCMotor
        R_a = V / I_s, eta k_t = tau_s / I_s, k_e = (V - R_a I_0) / omega_0 (:meth:`DCMotor.from_datasheet`).
    """
    return DCMotor.from_datasheet(
        sheet.voltage,
        sheet.stall_torque,
        sheet.stall_current,
        sheet.no_load_speed,
        no_load_current=sheet.no_load_current,
        efficiency=efficiency,
        current_limit=current_limit,
        supply_voltage=supply_voltage,
    )
