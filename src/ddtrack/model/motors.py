"""Geared DC motors and the boards that drive them (model.md §1.7).

One motor per wheel, described by output-referred constants (the gear ratio and the gearbox folded in, so every
speed is the wheel's and every torque is at the wheel)::

    L_a di/dt = u - R_a i - k_e phi_dot,        tau = eta k_t i

with armature resistance R_a [ohm], torque constant k_t [N m/A], back-EMF constant k_e [V s/rad], gearbox
efficiency eta in (0, 1], supply voltage V_s [V], current limit i_max [A] and inductance L_a [H]. With L_a = 0
(the default: datasheets seldom give it, and L_a / R_a is well under a millisecond) the current is algebraic,
i = (u - k_e phi_dot) / R_a; with L_a > 0, :func:`current_rate` is the current's ODE for a plant to integrate.

Three drivers decide what a controller commands:

* :func:`torque_driver`: current control; the torque command is met inside the speed-dependent
  :func:`torque_envelope` (the torque-speed curve) and clipped to it outside;
* :func:`voltage_driver`: PWM; the voltage command is clipped to +-V_s and the current to +-i_max;
* :class:`VelocityDriver`: a PI loop on the wheel speed that sets the voltage, with anti-windup.

Everything here is a pure JAX function of pytrees, so it runs under ``jit``, ``vmap`` and ``grad``; the plants of
:mod:`ddtrack.model.motor_plants` put it behind the wheels. The gearbox efficiency multiplies the torque in both
directions of power flow (a back-driven gearbox would divide instead): a simplification that matters only while a
wheel brakes.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jax import Array

from .._pytree import pytree_dataclass, static_field

RPM = 2.0 * math.pi / 60.0  #: one revolution per minute in rad/s


@pytree_dataclass
class DCMotor:
    """A geared DC motor with its constants referred to the wheel (model.md §1.7). All SI units.

    Attributes
    ----------
    resistance : float
        Armature resistance R_a [ohm].
    torque_constant : float
        Torque constant k_t at the wheel, gear ratio included [N m/A].
    back_emf : float
        Back-EMF constant k_e at the wheel, gear ratio included [V s/rad].
    efficiency : float
        Gearbox efficiency eta in (0, 1]: the wheel torque is eta k_t i.
    supply_voltage : float
        The most voltage the driver can apply, V_s [V].
    current_limit : float
        The driver's current limit i_max [A].
    inductance : float
        Armature inductance L_a [H]; 0 makes the current algebraic (see :func:`current_rate`).
    """

    resistance: float
    torque_constant: float
    back_emf: float
    efficiency: float
    supply_voltage: float
    current_limit: float
    inductance: float = 0.0

    @classmethod
    def from_datasheet(
        cls,
        voltage: float,
        stall_torque: float,
        stall_current: float,
        no_load_speed: float,
        no_load_current: float = 0.0,
        efficiency: float = 1.0,
        current_limit: float | None = None,
        supply_voltage: float | None = None,
    ) -> DCMotor:
        """The motor of a datasheet measured at ``voltage`` (model.md §1.7; the recipe of WPILib's ``DCMotor``).

        R_a = V / I_s (at stall there is no back-EMF), eta k_t = tau_s / I_s, and k_e = (V - R_a I_0) / omega_0 (at
        no load the current I_0 only overcomes the motor's internal friction).

        Parameters
        ----------
        voltage : float
            The voltage the datasheet's figures were measured at [V].
        stall_torque : float
            Stall torque at the output shaft [N m].
        stall_current : float
            Stall current [A].
        no_load_speed : float
            No-load speed at the output shaft [rad/s] (multiply rpm by :data:`RPM`).
        no_load_current : float, optional
            Current drawn at no load [A]; 0 when the datasheet does not give it.
        efficiency : float, optional
            Gearbox efficiency in (0, 1]. The stall torque is measured through the gearbox, so it only splits
            eta k_t into its factors: k_t = tau_s / (eta I_s).
        current_limit : float, optional
            The driver's current limit [A]; default the stall current at the supply voltage, V_s / R_a.
        supply_voltage : float, optional
            The driver's supply [V]; default ``voltage``.

        Raises
        ------
        ValueError
            A value that is not a positive finite number (the no-load current may be 0), an efficiency outside
            (0, 1], or a no-load current not below the stall current; the message names the argument.
        """
        for name, value in (
            ("voltage", voltage),
            ("stall_torque", stall_torque),
            ("stall_current", stall_current),
            ("no_load_speed", no_load_speed),
            ("current_limit", current_limit),
            ("supply_voltage", supply_voltage),
        ):
            if value is not None and not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}: give the datasheet's value")
        if not (math.isfinite(no_load_current) and no_load_current >= 0.0):
            raise ValueError(f"no_load_current must be >= 0, got {no_load_current!r}: use 0 if the datasheet has none")
        if no_load_current >= stall_current:
            raise ValueError(
                f"no_load_current ({no_load_current:g} A) must be below stall_current ({stall_current:g} A): "
                "check the two datasheet values (no-load current is typically a few percent of the stall current)"
            )
        if not (math.isfinite(efficiency) and 0.0 < efficiency <= 1.0):
            raise ValueError(f"efficiency must be in (0, 1], got {efficiency!r}: use 1 if the datasheet has none")
        resistance = voltage / stall_current
        supply = voltage if supply_voltage is None else supply_voltage
        return cls(
            resistance=resistance,
            torque_constant=stall_torque / (stall_current * efficiency),
            back_emf=(voltage - resistance * no_load_current) / no_load_speed,
            efficiency=efficiency,
            supply_voltage=supply,
            current_limit=supply / resistance if current_limit is None else current_limit,
        )

    @property
    def no_load_speed(self) -> float:
        """V_s / k_e: the wheel speed at which the back-EMF cancels the full supply [rad/s] (no friction)."""
        return self.supply_voltage / self.back_emf

    @property
    def stall_current(self) -> Array:
        """min(V_s / R_a, i_max): the current at zero speed and full voltage [A]."""
        return jnp.minimum(self.supply_voltage / self.resistance, self.current_limit)

    @property
    def stall_torque(self) -> Array:
        """eta k_t min(V_s / R_a, i_max): the torque at zero speed and full voltage [N m]."""
        return self.efficiency * self.torque_constant * self.stall_current


def current_envelope(motor: DCMotor, wheel_speed: Array | float) -> tuple[Array, Array]:
    """(low, high): the currents the driver can hold at ``wheel_speed`` [rad/s], in amperes (model.md §1.7).

    The current limit [-i_max, i_max] intersected with what the supply can push against the back-EMF,
    [(-V_s - k_e phi_dot) / R_a, (V_s - k_e phi_dot) / R_a]. Where the two do not meet (a wheel driven far beyond
    its no-load speed) the supply wins: the envelope shrinks to the voltage range's end nearest the limit.
    """
    emf = motor.back_emf * jnp.asarray(wheel_speed)
    by_voltage_low = (-motor.supply_voltage - emf) / motor.resistance
    by_voltage_high = (motor.supply_voltage - emf) / motor.resistance
    low = jnp.clip(-motor.current_limit, by_voltage_low, by_voltage_high)
    high = jnp.clip(motor.current_limit, by_voltage_low, by_voltage_high)
    return low, high


def torque_envelope(motor: DCMotor, wheel_speed: Array | float) -> tuple[Array, Array]:
    """(low, high) [N m]: the torque-speed curve, eta k_t times :func:`current_envelope` (model.md §1.7).

    At rest it is +-stall torque; at the no-load speed its upper end is 0; beyond it the motor can only brake.
    """
    low, high = current_envelope(motor, wheel_speed)
    gain = motor.efficiency * motor.torque_constant
    return gain * low, gain * high


def torque_driver(motor: DCMotor, tau_command: Array, wheel_speed: Array) -> tuple[Array, Array]:
    """Current control (model.md §1.7): (applied torque [N m], current [A]) for a torque command [N m].

    The board sets the current i* = tau* / (eta k_t), clipped to the :func:`current_envelope` at ``wheel_speed``
    [rad/s]: a feasible command is met exactly, an infeasible one saturates on the torque-speed curve.
    """
    low, high = current_envelope(motor, wheel_speed)
    gain = motor.efficiency * motor.torque_constant
    current = jnp.clip(jnp.asarray(tau_command) / gain, low, high)
    return gain * current, current


def voltage_driver(motor: DCMotor, voltage_command: Array, wheel_speed: Array) -> tuple[Array, Array]:
    """PWM with L_a = 0 (model.md §1.7): (torque [N m], current [A]) for a voltage command [V].

    u = clip(u*, -V_s, V_s), i = clip((u - k_e phi_dot) / R_a, -i_max, i_max), tau = eta k_t i.
    """
    voltage = jnp.clip(jnp.asarray(voltage_command), -motor.supply_voltage, motor.supply_voltage)
    current = (voltage - motor.back_emf * jnp.asarray(wheel_speed)) / motor.resistance
    current = jnp.clip(current, -motor.current_limit, motor.current_limit)
    return motor.efficiency * motor.torque_constant * current, current


def torque_feedforward(motor: DCMotor, tau_command: Array, wheel_speed: Array) -> Array:
    """The voltage [V] a PWM board without a current sensor applies for a torque command [N m] (model.md §1.7):
    u* = R_a tau* / (eta k_t) + k_e phi_dot, the motor's own model inverted at the measured ``wheel_speed``.

    Through :func:`voltage_driver` it gives :func:`torque_driver`'s torque wherever the current and voltage ranges
    overlap (up to the no-load speed): the clips of the two drivers meet in another order, not another place.
    """
    gain = motor.efficiency * motor.torque_constant
    return motor.resistance * jnp.asarray(tau_command) / gain + motor.back_emf * jnp.asarray(wheel_speed)


def drive_torque(
    motor: DCMotor, tau_command: Array, wheel_speed: Array, pwm_model: DCMotor | None = None
) -> tuple[Array, Array]:
    """(torque [N m], current [A]) a board gives ``motor`` for a torque command: current control
    (:func:`torque_driver`) when ``pwm_model`` is None, else PWM, the command turned into a voltage through the
    board's own model of its motor (:func:`torque_feedforward` of ``pwm_model``, e.g. the datasheet's while the true
    motor differs) and applied by :func:`voltage_driver`: what a servo without a current mode offers a torque law."""
    if pwm_model is None:
        return torque_driver(motor, tau_command, wheel_speed)
    return voltage_driver(motor, torque_feedforward(pwm_model, tau_command, wheel_speed), wheel_speed)


def current_rate(motor: DCMotor, voltage: Array, current: Array, wheel_speed: Array) -> Array:
    """di/dt = (u - R_a i - k_e phi_dot) / L_a [A/s], the armature's ODE for a motor with inductance (model.md §1.7).

    For ``motor.inductance > 0`` only (with L_a = 0 the current is algebraic: use :func:`voltage_driver`). The
    voltage is clipped to +-V_s. The mode is stiff, with time constant L_a / R_a (0.1 to 1 ms for small motors):
    an explicit integrator needs steps well below it. The current limit is the caller's to enforce (a current-
    controlled board sets u from the current error).
    """
    voltage = jnp.clip(jnp.asarray(voltage), -motor.supply_voltage, motor.supply_voltage)
    return (voltage - motor.resistance * current - motor.back_emf * wheel_speed) / motor.inductance


@pytree_dataclass
class VelocityDriver:
    """A PI loop on the wheel speed that sets the motor's voltage, as ROS bases and servos in velocity mode do
    (model.md §1.7).

    u = kp e + ki z, e = phi_dot* - phi_dot, z the integral of e; u is clipped to +-V_s and the current to
    +-i_max (:func:`voltage_driver`). Anti-windup by conditional integration: z stops while a limit acts and e
    would drive u further into it, so z can unwind as soon as the error reverses.

    Attributes
    ----------
    motor : DCMotor
        The motor it drives.
    kp : float
        Proportional gain [V s/rad].
    ki : float
        Integral gain [V/rad].
    anti_windup : bool
        False integrates whatever the limits do (for comparison only; static).
    """

    motor: DCMotor
    kp: float
    ki: float
    anti_windup: bool = static_field(default=True, why="an integrator clamp exists or not")

    def output(self, integral: Array, speed_setpoint: Array, wheel_speed: Array) -> tuple[Array, Array, Array, Array]:
        """(torque [N m], current [A], voltage asked [V], integral frozen: 1.0 or 0.0) at one instant."""
        error = jnp.asarray(speed_setpoint) - wheel_speed
        voltage = self.kp * error + self.ki * integral
        tau, current = voltage_driver(self.motor, voltage, wheel_speed)
        if not self.anti_windup:
            return tau, current, voltage, jnp.zeros_like(tau)
        # a larger z raises u, and with it the unclipped current: freeze z where that pushes into a limit
        free_current = (voltage - self.motor.back_emf * wheel_speed) / self.motor.resistance
        voltage_pushed = (jnp.abs(voltage) > self.motor.supply_voltage) & (error * voltage > 0.0)
        current_pushed = (jnp.abs(free_current) > self.motor.current_limit) & (error * free_current > 0.0)
        return tau, current, voltage, (voltage_pushed | current_pushed).astype(tau.dtype)

    def integral_rate(self, integral: Array, speed_setpoint: Array, wheel_speed: Array) -> Array:
        """dz/dt [rad/s]: the speed error, or 0 while the integral is frozen; for a plant that integrates z."""
        *_, frozen = self.output(integral, speed_setpoint, wheel_speed)
        return (1.0 - frozen) * (jnp.asarray(speed_setpoint) - wheel_speed)

    def step(
        self, integral: Array, speed_setpoint: Array, wheel_speed: Array, dt: Array | float
    ) -> tuple[Array, Array, Array]:
        """(torque [N m], current [A], next integral) of a driver sampled every ``dt`` [s] (forward Euler on z)."""
        tau, current, _, frozen = self.output(integral, speed_setpoint, wheel_speed)
        error = jnp.asarray(speed_setpoint) - wheel_speed
        return tau, current, integral + dt * (1.0 - frozen) * error
