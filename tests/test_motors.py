"""Geared DC motors and their drivers (model.md §1.7) against their analytic facts.

The motor of most tests is the Dynamixel XL430-W250 of the TurtleBot3 (ROBOTIS e-Manual): 1.4 N m stall torque at
11.1 V and 1.3 A, 57 rpm at no load. The tests take its no-load current as 0 (an assumption) unless they say.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ddtrack  # noqa: F401  (turns on float64)
from ddtrack.integrators import rk4
from ddtrack.model import (
    DCMotor,
    VelocityDriver,
    current_envelope,
    current_rate,
    torque_driver,
    torque_envelope,
    torque_feedforward,
    voltage_driver,
)
from ddtrack.model.motors import RPM

XL430 = {"voltage": 11.1, "stall_torque": 1.4, "stall_current": 1.3, "no_load_speed": 57 * RPM}


def xl430(**changes: float) -> DCMotor:
    return DCMotor.from_datasheet(**(XL430 | changes))


# --- the datasheet recipe ----------------------------------------------------------------------------


def test_from_datasheet_recovers_the_datasheet_at_its_voltage():
    motor = xl430()
    assert motor.resistance == pytest.approx(11.1 / 1.3, rel=1e-15)
    assert motor.back_emf == pytest.approx(11.1 / (57 * RPM), rel=1e-15)
    assert float(motor.stall_torque) == pytest.approx(1.4, rel=1e-14)
    assert motor.no_load_speed == pytest.approx(57 * 2 * math.pi / 60, rel=1e-14)  # 5.97 rad/s
    assert motor.supply_voltage == 11.1 and motor.current_limit == pytest.approx(1.3, rel=1e-15)
    # the efficiency splits eta k_t only: what the datasheet measured through the gearbox stays
    geared = xl430(efficiency=0.8)
    assert geared.torque_constant == pytest.approx(1.4 / (1.3 * 0.8), rel=1e-15)
    assert float(geared.stall_torque) == pytest.approx(1.4, rel=1e-14)
    assert geared.back_emf == motor.back_emf


def test_a_no_load_current_is_the_motors_internal_friction():
    """With I_0 > 0, k_e = (V - R_a I_0) / omega_0: at the datasheet's no-load speed the motor still gives
    eta k_t I_0, the torque its own friction took, and its frictionless no-load speed lies above omega_0."""
    motor = xl430(no_load_current=0.1)
    omega_0 = 57 * RPM
    _, high = torque_envelope(motor, omega_0)
    assert float(high) == pytest.approx(motor.efficiency * motor.torque_constant * 0.1, rel=1e-12)
    assert motor.no_load_speed == pytest.approx(omega_0 * 11.1 / (11.1 - 0.1 * 11.1 / 1.3), rel=1e-14)
    assert motor.no_load_speed > omega_0


def test_supply_voltage_and_current_limit_scale_the_stall_torque():
    # a 12 V supply without a limit of its own: the stall current, and torque, grow with the voltage
    assert float(xl430(supply_voltage=12.0).stall_torque) == pytest.approx(1.4 * 12.0 / 11.1, rel=1e-14)
    # the driver's limit caps it: eta k_t i_max
    assert float(xl430(supply_voltage=12.0, current_limit=1.3).stall_torque) == pytest.approx(1.4, rel=1e-14)
    assert float(xl430(current_limit=0.65).stall_torque) == pytest.approx(0.7, rel=1e-14)
    assert xl430(supply_voltage=12.0).no_load_speed == pytest.approx(57 * RPM * 12.0 / 11.1, rel=1e-14)


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ({"voltage": 0.0}, "voltage"),
        ({"stall_torque": -1.4}, "stall_torque"),
        ({"stall_current": 0.0}, "stall_current"),
        ({"no_load_speed": float("nan")}, "no_load_speed"),
        ({"no_load_current": -0.1}, "no_load_current"),
        ({"no_load_current": 1.3}, "no_load_current"),
        ({"efficiency": 0.0}, "efficiency"),
        ({"efficiency": 1.2}, "efficiency"),
        ({"current_limit": 0.0}, "current_limit"),
        ({"supply_voltage": float("inf")}, "supply_voltage"),
    ],
)
def test_from_datasheet_names_the_bad_argument_and_the_fix(change, named):
    with pytest.raises(ValueError, match=rf"^{named} .*: (give|use|check)"):
        xl430(**change)


def test_motors_are_pytrees_that_batch():
    motors = jax.tree_util.tree_map(lambda *leaves: jnp.array(leaves), xl430(), xl430(current_limit=0.65))
    assert len(jax.tree_util.tree_leaves(motors)) == 7
    stall = jax.vmap(lambda m: m.stall_torque)(motors)
    np.testing.assert_allclose(stall, [1.4, 0.7], rtol=1e-14)
    driver = VelocityDriver(xl430(), kp=1.0, ki=1.0, anti_windup=False)
    assert len(jax.tree_util.tree_leaves(driver)) == 9  # the flag is static, not a leaf


# --- the torque-speed envelope and the torque driver -------------------------------------------------


def test_the_envelope_is_the_stall_torque_at_rest_and_closes_at_no_load():
    motor = xl430()
    low, high = torque_envelope(motor, 0.0)
    assert float(low) == pytest.approx(-1.4, rel=1e-14) and float(high) == pytest.approx(1.4, rel=1e-14)
    _, high = torque_envelope(motor, motor.no_load_speed)
    assert abs(float(high)) < 1e-14
    low, _ = torque_envelope(motor, -motor.no_load_speed)
    assert abs(float(low)) < 1e-14
    # in between, the straight torque-speed line from stall to no load
    speeds = np.linspace(0.0, motor.no_load_speed, 11)
    _, high = torque_envelope(motor, jnp.asarray(speeds))
    np.testing.assert_allclose(high, 1.4 * (1.0 - speeds / motor.no_load_speed), rtol=0, atol=1e-13)


def test_a_current_limit_flattens_the_envelope_up_to_its_knee():
    motor = xl430(current_limit=0.65)  # half the stall current
    knee = (motor.supply_voltage - motor.resistance * 0.65) / motor.back_emf
    speeds = jnp.asarray([0.0, 0.5 * knee, knee, 0.5 * (knee + motor.no_load_speed), motor.no_load_speed])
    _, high = torque_envelope(motor, speeds)
    line = 1.4 * (1.0 - np.asarray(speeds) / motor.no_load_speed)
    np.testing.assert_allclose(high, np.minimum(0.7, line), rtol=0, atol=1e-13)
    assert float(high[1]) == pytest.approx(0.7, rel=1e-14) and float(high[3]) < 0.7 - 0.1


def test_beyond_no_load_the_motor_only_brakes_and_the_supply_wins_over_the_limit():
    motor = xl430(current_limit=1.0)
    low, high = current_envelope(motor, 1.5 * motor.no_load_speed)
    assert float(high) < 0.0 and float(low) == pytest.approx(-1.0, rel=1e-14)
    # driven so fast that even full reverse voltage leaves more than i_max: the envelope is that one current
    speed = 3.0 * motor.no_load_speed
    low, high = current_envelope(motor, speed)
    full_reverse = (motor.supply_voltage - motor.back_emf * speed) / motor.resistance
    assert float(low) == float(high) == pytest.approx(full_reverse, rel=1e-14) and full_reverse < -1.0


def test_the_torque_driver_meets_a_feasible_command_and_saturates_an_infeasible_one():
    motor = xl430(current_limit=1.1)
    rng = np.random.default_rng(3)
    speeds = jnp.asarray(rng.uniform(-1.2, 1.2, 500) * motor.no_load_speed)
    low, high = torque_envelope(motor, speeds)
    fraction = jnp.asarray(rng.uniform(0.0, 1.0, 500))
    feasible = low + fraction * (high - low)
    tau, current = torque_driver(motor, feasible, speeds)
    np.testing.assert_allclose(tau, feasible, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(current, feasible / (motor.efficiency * motor.torque_constant), rtol=1e-14)
    # the voltage the driver needs for it is within the supply, the current within the limit
    voltage = motor.resistance * current + motor.back_emf * speeds
    assert float(jnp.max(jnp.abs(voltage))) <= motor.supply_voltage * (1 + 1e-12)
    assert float(jnp.max(jnp.abs(current))) <= 1.1 * (1 + 1e-12)
    # beyond the curve the torque stops on it
    excess = jnp.asarray(rng.uniform(0.01, 5.0, 500))
    tau, _ = torque_driver(motor, high + excess, speeds)
    np.testing.assert_array_equal(tau, high)
    tau, _ = torque_driver(motor, low - excess, speeds)
    np.testing.assert_array_equal(tau, low)


def test_a_torque_law_through_a_voltage_board_gets_the_current_drivers_torque():
    """Up to the no-load speed the feed-forward voltage through the PWM driver and the current driver give the same
    torque, feasible or not, with the current limit active or not (model.md §1.7, "Drivers")."""
    rng = np.random.default_rng(11)
    for motor in (xl430(), xl430(current_limit=0.5)):  # the supply binds first, then the current limit
        speeds = jnp.asarray(rng.uniform(-1.0, 1.0, 2000) * motor.no_load_speed)
        commands = jnp.asarray(rng.uniform(-2.0, 2.0, 2000) * motor.stall_torque)
        by_current, i_current = torque_driver(motor, commands, speeds)
        by_voltage, i_voltage = voltage_driver(motor, torque_feedforward(motor, commands, speeds), speeds)
        np.testing.assert_allclose(by_voltage, by_current, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(i_voltage, i_current, rtol=1e-12, atol=1e-14)
        low, high = torque_envelope(motor, speeds)
        assert bool(jnp.any(by_current == high)) and bool(jnp.any(by_current == low))  # the clips were reached


# --- the voltage driver and the inductive current ---------------------------------------------------


def test_the_voltage_driver_gives_stall_torque_at_full_voltage_at_rest():
    motor = xl430()
    tau, current = voltage_driver(motor, jnp.asarray(11.1), jnp.asarray(0.0))
    assert float(tau) == pytest.approx(1.4, rel=1e-14) and float(current) == pytest.approx(1.3, rel=1e-14)
    tau, _ = voltage_driver(motor, jnp.asarray(100.0), jnp.asarray(0.0))  # clipped to the supply
    assert float(tau) == pytest.approx(1.4, rel=1e-14)
    tau, _ = voltage_driver(motor, jnp.asarray(-11.1), jnp.asarray(0.0))
    assert float(tau) == pytest.approx(-1.4, rel=1e-14)
    tau, _ = voltage_driver(motor, jnp.asarray(11.1), jnp.asarray(motor.no_load_speed))
    assert abs(float(tau)) < 1e-14
    # half voltage at rest: half the stall current; the limit clips a stalled motor at full voltage
    tau, current = voltage_driver(motor, jnp.asarray(5.55), jnp.asarray(0.0))
    assert float(current) == pytest.approx(0.65, rel=1e-14) and float(tau) == pytest.approx(0.7, rel=1e-14)
    tau, current = voltage_driver(xl430(current_limit=0.5), jnp.asarray(11.1), jnp.asarray(0.0))
    assert float(current) == pytest.approx(0.5, rel=1e-14)


def test_an_inductive_current_rises_with_its_time_constant_to_the_algebraic_one():
    motor = dataclasses.replace(xl430(), inductance=4e-3)  # L_a / R_a = 0.47 ms
    voltage, speed = jnp.asarray(6.0), jnp.asarray(2.0)
    _, algebraic = voltage_driver(motor, voltage, speed)
    assert abs(float(current_rate(motor, voltage, algebraic, speed))) < 1e-12
    tau_e = motor.inductance / motor.resistance
    current = rk4(lambda i: current_rate(motor, voltage, i, speed), jnp.asarray(0.0), tau_e, 200)
    assert float(current) == pytest.approx(float(algebraic) * (1.0 - math.exp(-1.0)), rel=1e-9)
    # the supply bounds the voltage here too
    assert float(current_rate(motor, jnp.asarray(50.0), 0.0, 0.0)) == pytest.approx(11.1 / 4e-3, rel=1e-14)


# --- the velocity driver on a wheel J phi_ddot = tau - b phi_dot --------------------------------------

WHEEL_INERTIA, WHEEL_DAMPING = 0.005, 0.001  # [kg m^2], [N m s/rad]


def wheel_and_integral_rate(driver: VelocityDriver, setpoint: float):
    def rate(state):
        speed, integral = state
        tau, *_ = driver.output(integral, setpoint, speed)
        return jnp.stack(
            [(tau - WHEEL_DAMPING * speed) / WHEEL_INERTIA, driver.integral_rate(integral, setpoint, speed)]
        )

    return rate


def test_the_velocity_driver_is_the_linear_pi_loop_while_unsaturated():
    """Below the limits the loop is linear: J w_dot = a (kp e + ki z - k_e w) - b w, z_dot = e, a = eta k_t / R_a.
    The driver's continuous form follows the matrix exponential of that system, and converges on the set-point
    with the slower closed-loop pole (about 5.5 1/s here)."""
    motor, setpoint = xl430(), 0.5
    driver = VelocityDriver(motor, kp=2.0, ki=20.0)
    a = motor.efficiency * motor.torque_constant / motor.resistance
    system = np.array(
        [
            [-(a * (driver.kp + motor.back_emf) + WHEEL_DAMPING) / WHEEL_INERTIA, a * driver.ki / WHEEL_INERTIA],
            [-1.0, 0.0],
        ]
    )
    integral_ss = (motor.back_emf + WHEEL_DAMPING / a) * setpoint / driver.ki
    steady = np.array([setpoint, integral_ss])
    slow = max(np.linalg.eigvals(system).real)
    assert -6.0 < slow < -5.0
    state = jnp.zeros(2)
    for _ in range(4):  # 4 x 0.5 s
        state = rk4(wheel_and_integral_rate(driver, setpoint), state, 0.5, 2000)
    expected = steady + jax.scipy.linalg.expm(jnp.asarray(system) * 2.0) @ (np.zeros(2) - steady)
    np.testing.assert_allclose(state, expected, rtol=0, atol=1e-9)
    # the loop converged as its slow pole says: within 0.5 e^{slow t} (times a modest factor) of the set-point
    assert abs(float(state[0]) - setpoint) < 2.0 * setpoint * math.exp(slow * 2.0)
    # and the sampled form (forward Euler on z, torque held for dt) settles on the set-point too
    speed, integral, dt = jnp.asarray(0.0), jnp.asarray(0.0), 1e-4
    for _ in range(3):
        speed, integral = _sampled_run(driver, setpoint, speed, integral, dt, 10_000)
    assert abs(float(speed) - setpoint) < 1e-6


def _sampled_run(driver, setpoint, speed, integral, dt, steps, record=False, inertia=WHEEL_INERTIA):
    def body(carry, _):
        speed, integral = carry
        tau, _, integral_next = driver.step(integral, setpoint, speed, dt)
        *_, frozen = driver.output(integral, setpoint, speed)
        speed_next = speed + dt * (tau - WHEEL_DAMPING * speed) / inertia
        return (speed_next, integral_next), (speed, integral, frozen)

    (speed, integral), history = jax.lax.scan(body, (speed, integral), None, length=steps)
    return (speed, integral, history) if record else (speed, integral)


def test_anti_windup_freezes_the_integral_while_saturated_and_cuts_the_overshoot():
    """A set-point near the no-load speed on a heavier wheel (0.02 kg m^2) saturates the voltage through the rise:
    with anti-windup the integral stays still meanwhile, and the overshoot is a fraction of the one of the same PI
    without it."""
    motor = xl430()
    setpoint = 0.9 * motor.no_load_speed  # needs 10.0 V of the 11.1 V in steady state
    runs = {}
    for anti_windup in (True, False):
        driver = VelocityDriver(motor, kp=5.0, ki=50.0, anti_windup=anti_windup)
        speed, _, (speeds, integrals, frozen) = _sampled_run(
            driver, setpoint, jnp.asarray(0.0), jnp.asarray(0.0), 1e-4, 60_000, record=True, inertia=0.02
        )
        runs[anti_windup] = np.asarray(speeds), np.asarray(integrals), np.asarray(frozen)
        assert abs(float(speed) - setpoint) < 1e-4, anti_windup  # both settle on the set-point in 6 s
    speeds, integrals, frozen = runs[True]
    assert frozen.sum() > 300  # the limit acted for over 30 ms
    np.testing.assert_array_equal(np.diff(integrals)[frozen[:-1] > 0], 0.0)  # and z did not move meanwhile
    overshoot = {key: runs[key][0].max() - setpoint for key in runs}
    assert overshoot[False] > 0.05 * setpoint  # the plain PI overshoots clearly: its integral wound up
    assert overshoot[True] < 0.25 * overshoot[False]
    assert runs[False][1].max() > 1.5 * integrals.max()  # the wound-up integral


def test_the_integral_is_frozen_only_while_the_error_pushes_into_the_limit():
    driver = VelocityDriver(xl430(), kp=2.0, ki=60.0)
    *_, frozen = driver.output(jnp.asarray(1.0), 3.0, 0.0)  # u = 6 + 60 > V_s, error > 0: frozen
    assert float(frozen) == 1.0
    assert float(driver.integral_rate(jnp.asarray(1.0), 3.0, 0.0)) == 0.0
    *_, frozen = driver.output(jnp.asarray(1.0), 1.0, 2.0)  # still clipped, but the error reverses: unwinds
    assert float(frozen) == 0.0
    assert float(driver.integral_rate(jnp.asarray(1.0), 1.0, 2.0)) == -1.0
    *_, frozen = driver.output(jnp.asarray(0.01), 1.0, 0.0)  # u = 2.6 V: unsaturated
    assert float(frozen) == 0.0
