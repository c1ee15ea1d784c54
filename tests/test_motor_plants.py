"""Plants driven by geared DC motors through a driver (model.md §1.7): a torque-driven plant whose motor never
binds is the Lagrangian robot; a TurtleBot3's top speed is its motors' no-load speed, reached along the closed-form
lag of the torque-speed curve; logged torques lie in the envelope; a PI velocity loop settles on cmd_vel with no
steady error (its linear step response in closed form); both plants run through ``run_setup``, alone and as a batch."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack.integrators import RK4
from ddtrack.model import (
    DCMotor,
    DynamicPlant,
    KinematicPlant,
    TorqueDrivenPlant,
    VelocityDrivenPlant,
    VelocityDriver,
    motor_from_datasheet,
    torque_driven_model,
    torque_envelope,
    velocity_driven_model,
)
from ddtrack.robots import preset
from ddtrack.runner import prepare, prepare_batch, run_setup

PERIOD, SUBSTEPS = 0.01, 20
BURGER = preset("turtlebot3_burger")


def respond(plant, command, periods, body0=(0.0, 0.0, 0.0, 0.0, 0.0)):
    """(t, full states, logged channels at each state) under a constant command from ``body0``."""
    u = plant.saturate(jnp.asarray(command, dtype=float))

    def one(x, _):
        x_next = plant.advance(x, u, jnp.zeros(2), PERIOD, RK4(SUBSTEPS))
        return x_next, x_next

    x0 = plant.init(jnp.asarray(body0, dtype=float))
    _, states = jax.lax.scan(one, x0, None, length=periods)
    states = jnp.vstack([x0[None], states])
    logged = jax.vmap(lambda x: plant.logged(x, u))(states)
    return PERIOD * np.arange(periods + 1), np.asarray(states), {k: np.asarray(v) for k, v in logged.items()}


def frictionless_burger():
    return dataclasses.replace(BURGER.robot_params(), coulomb_friction=0.0, viscous_friction=0.0)


def burger_motor() -> DCMotor:
    assert BURGER.motor is not None
    return motor_from_datasheet(BURGER.motor)


# --- the motor from a preset's datasheet -----------------------------------------------------------------------------


def test_a_presets_datasheet_gives_its_motor():
    """The XL430-W250 at 11.1 V (1.4 N m, 1.3 A, 57 rpm): R_a = V / I_s, eta k_t = tau_s / I_s, k_e = V / omega_0,
    and no-load speed x R is the Burger's top speed, 0.197 m/s."""
    motor = burger_motor()
    assert motor.resistance == pytest.approx(11.1 / 1.3, rel=1e-15)
    assert motor.efficiency * motor.torque_constant == pytest.approx(1.4 / 1.3, rel=1e-15)
    assert motor.back_emf == pytest.approx(11.1 / (57.0 * 2.0 * np.pi / 60.0), rel=1e-15)
    assert float(motor.stall_torque) == pytest.approx(1.4, rel=1e-14)
    assert motor.no_load_speed * 0.033 == pytest.approx(0.197, abs=5e-4)
    assert BURGER.max_speed == pytest.approx(motor.no_load_speed * 0.033, rel=1e-12)


# --- the torque-driven plant -----------------------------------------------------------------------------------------

SHORT = ["simulation.duration=3", "simulation.metric_window=[0, 3]"]


def ideal_motor(max_torque: float) -> DCMotor:
    """A motor whose only limit is the current limit, at the robot's torque limit: its envelope is +-max_torque at
    every speed a run reaches (the supply, 1e6 V against a back-EMF of 1e-3 V s/rad, never binds), and
    eta k_t = 1 so command -> current -> torque is exact in floating point."""
    return DCMotor(
        resistance=1.0,
        torque_constant=1.0,
        back_emf=1e-3,
        efficiency=1.0,
        supply_voltage=1e6,
        current_limit=max_torque,
    )


def test_a_motor_that_never_binds_is_the_lagrangian_robot():
    """Backstepping with computed torque on the paper's line: the torque-driven plant with an ideal motor runs as
    DynamicPlant does, state and applied torques, to 1e-12 (the torques saturate at the same 10 N m)."""
    scenario = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=SHORT)
    setup, draws = prepare(scenario)
    assert setup.plant_model is DynamicPlant
    motor = ideal_motor(float(setup.plant_params.max_torque))
    motored = dataclasses.replace(setup, plant_model=lambda params: TorqueDrivenPlant(params, motor))
    assert isinstance(motored.plant, TorqueDrivenPlant)
    reference, result = run_setup(scenario, setup, draws), run_setup(scenario, motored, draws)
    assert result.status_name == "ok" == reference.status_name
    np.testing.assert_allclose(np.asarray(result.state), np.asarray(reference.state), rtol=0, atol=1e-12)
    ours, theirs = ddtrack.timeseries(result), ddtrack.timeseries(reference)
    for name in ("tau_r", "tau_l"):
        np.testing.assert_allclose(ours[name], theirs[name], rtol=0, atol=1e-12, err_msg=name)
    assert np.max(np.abs(theirs["tau_r"])) == pytest.approx(10.0)  # the torque limit did act
    # the currents are the torques / (eta k_t) = the torques
    np.testing.assert_allclose(ours["i_r"], ours["tau_r"], rtol=0, atol=1e-12)


def test_a_turtlebot_reaches_its_no_load_speed_and_never_passes_it():
    """Full forward torque on both wheels, no friction: each wheel gets eta k_t (V_s - k_e phi_dot) / R_a (the
    current limit is the stall current, so the supply binds at every speed >= 0), so the speed is the lag
    v(t) = v_0 (1 - exp(-t / tau)) with v_0 = R V_s / k_e (no-load speed x R, 0.197 m/s) and
    tau = M_eff R^2 R_a / (2 eta k_t k_e); RK4 matches it, and v never exceeds v_0."""
    params, motor = frictionless_burger(), burger_motor()
    plant = TorqueDrivenPlant(params, motor)
    t, states, logged = respond(plant, (100.0, 100.0), 100)
    gain = motor.efficiency * motor.torque_constant
    v0 = params.wheel_radius * motor.no_load_speed
    tau = params.effective_mass * params.wheel_radius**2 * motor.resistance / (2.0 * gain * motor.back_emf)
    assert 0.005 < tau < 0.05  # a geared servo with its reflected rotor: about 11 ms
    v = states[:, 3]
    # RK4's local error on this linear lag is z^5 / 120 of the gap to v0 per step, z = h / tau ~ 0.05: bound
    # the sum over the steps of a period (the gap then decays) with a factor 2 to spare
    z = PERIOD / SUBSTEPS / tau
    np.testing.assert_allclose(v, v0 * (1.0 - np.exp(-t / tau)), rtol=0, atol=2.0 * SUBSTEPS * z**5 / 120.0 * v0)
    assert np.max(v) <= v0 and v[-1] == pytest.approx(v0, rel=1e-12)  # 1 s is ~90 time constants
    assert v0 == pytest.approx(0.197, abs=5e-4)
    assert np.max(np.abs(states[:, [1, 2, 4]])) < 1e-15  # straight ahead (to rounding)
    # at rest the motor gives its stall torque; at the no-load speed nothing
    np.testing.assert_allclose(logged["tau_r"][0], 1.4, rtol=1e-14)
    np.testing.assert_allclose(logged["i_r"][0], 1.3, rtol=1e-14)
    assert abs(logged["tau_l"][-1]) < 1e-10
    # a command below the stall torque is met at rest, exactly
    _, _, gentle = respond(plant, (0.5, -0.25), 1)
    np.testing.assert_allclose([gentle["tau_r"][0], gentle["tau_l"][0]], [0.5, -0.25], rtol=1e-15)
    np.testing.assert_allclose(np.asarray(plant.saturate(jnp.asarray([100.0, -100.0]))), [1.4, -1.4], rtol=1e-14)


def weak_motor() -> DCMotor:
    """A motor for the paper's 12 kg robot whose torque-speed curve binds: 10 N m at stall, no-load 30 rad/s
    (1.5 m/s on 5 cm wheels) while the controller asks for up to 2 m/s."""
    return DCMotor.from_datasheet(voltage=24.0, stall_torque=10.0, stall_current=20.0, no_load_speed=30.0)


def test_logged_torques_lie_in_the_envelope_and_it_binds():
    """Closed loop on the paper's line with a weak motor: every logged torque lies in torque_envelope at the
    recorded wheel speeds, and on some rows the speed-dependent end (well below the stall torque) is what acted."""
    scenario = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=SHORT)
    setup, draws = prepare(scenario)
    motor = weak_motor()
    result = run_setup(scenario, dataclasses.replace(setup, plant_model=torque_driven_model(motor)), draws)
    columns = ddtrack.timeseries(result)
    params = setup.plant_params
    radius, half = float(params.wheel_radius), float(params.half_axle)
    right = (columns["v"] + half * columns["omega"]) / radius
    left = (columns["v"] - half * columns["omega"]) / radius
    stall, bound = float(motor.stall_torque), 0
    for tau, speed in ((columns["tau_r"], right), (columns["tau_l"], left)):
        low, high = (np.asarray(e) for e in torque_envelope(motor, speed))
        assert np.all(tau >= low - 1e-12) and np.all(tau <= high + 1e-12)
        bound += int(np.sum((np.abs(tau - high) < 1e-12) & (high < 0.9 * stall)))
    assert bound > 10


# --- the velocity-driven plant -------------------------------------------------------------------------------------


def burger_driver(ki: float = 50.0) -> VelocityDriver:
    return VelocityDriver(burger_motor(), kp=2.0, ki=ki)


def test_a_straight_step_is_the_linear_pi_loop_in_closed_form():
    """Straight ahead, no friction, below the limits, each wheel is J phi_ddot = a (kp e + ki z - k_e phi_dot),
    z_dot = e, with J = M_eff R^2 / 2 and a = eta k_t / R_a: a linear system whose step response is
    s(t) = s_inf + exp(A t) (s_0 - s_inf), s_inf = (phi_dot*, k_e phi_dot* / ki). The plant follows it to RK4's
    accuracy, and after 2 s (28 times the slow pole's time constant) the speed error is below 1e-9."""
    params, driver = frictionless_burger(), burger_driver()
    motor = driver.motor
    plant = VelocityDrivenPlant(params, driver)
    command = 0.1
    t, states, logged = respond(plant, (command, 0.0), 200)
    radius = params.wheel_radius
    inertia, a = params.effective_mass * radius**2 / 2.0, motor.efficiency * motor.torque_constant / motor.resistance
    system = np.array([[-a * (driver.kp + motor.back_emf) / inertia, a * driver.ki / inertia], [-1.0, 0.0]])
    target = command / radius
    steady = np.array([target, motor.back_emf * target / driver.ki])
    values, vectors = np.linalg.eig(system)
    assert np.all(values.real < -10.0)  # both poles well damped: -14 and -176 1/s
    weights = np.linalg.solve(vectors, -steady)
    exact = steady[:, None] + np.real(vectors @ (weights[:, None] * np.exp(values[:, None] * t[None, :])))
    np.testing.assert_allclose(states[:, 3] / radius, exact[0], rtol=0, atol=1e-7 * target)
    np.testing.assert_allclose(states[:, 5], exact[1], rtol=0, atol=1e-7 * steady[1])
    np.testing.assert_allclose(states[:, 5], states[:, 6], rtol=0, atol=1e-15)
    voltage = driver.kp * (target - states[:, 3] / radius) + driver.ki * states[:, 5]
    assert np.max(voltage) < motor.supply_voltage  # never clipped: the linear analysis holds
    assert abs(states[-1, 3] - command) < 1e-9 and np.max(np.abs(states[:, [1, 2, 4]])) < 1e-15
    # at rest the logged torque is a (u - k_e phi_dot) with u = kp phi_dot*: the P term alone
    assert logged["tau_r"][0] == pytest.approx(a * driver.kp * target, rel=1e-12)
    # without the integral the loop settles short, at kp / (kp + k_e) of the set-point
    _, p_only, _ = respond(VelocityDrivenPlant(params, burger_driver(ki=0.0)), (command, 0.0), 200)
    assert p_only[-1, 3] == pytest.approx(command * driver.kp / (driver.kp + motor.back_emf), rel=1e-9)


def test_a_turning_step_settles_on_the_command_with_friction():
    """The preset's wheel friction and centre-of-mass offset (which loads the wheels in a turn): the integrals
    absorb both, so (v, omega) settle on (v*, omega*) with no steady error."""
    params = BURGER.robot_params()
    assert params.coulomb_friction > 0.0 and params.com_offset != 0.0
    command = np.array([0.1, 0.5])
    _, states, _ = respond(VelocityDrivenPlant(params, burger_driver()), command, 300)
    np.testing.assert_allclose(states[-1, 3:5], command, rtol=0, atol=1e-9)


def test_init_holds_the_initial_speed():
    """init puts in the integrals what holding the initial (v, omega) needs against friction, the offset's term
    and the back-EMF, so commanding that velocity keeps it; integrals of 0 would brake first."""
    params, driver = BURGER.robot_params(), burger_driver()
    plant = VelocityDrivenPlant(params, driver)
    body0 = (0.0, 0.0, 0.0, 0.1, -0.8)  # wheels at 1.1 and 5.0 rad/s, below the no-load 5.97 rad/s
    _, states, _ = respond(plant, body0[3:], 100, body0=body0)
    np.testing.assert_allclose(states[:, 3:], np.broadcast_to(states[0, 3:], states[:, 3:].shape), atol=1e-12)
    assert np.all(plant.init(jnp.zeros(5))[5:] == 0.0)
    cold = jnp.concatenate([jnp.asarray(body0), jnp.zeros(2)])
    braked = plant.advance(cold, jnp.asarray(body0[3:]), jnp.zeros(2), PERIOD, RK4(SUBSTEPS))
    assert float(braked[3]) < 0.1 - 1e-3


def paper_driver() -> VelocityDriver:
    """A PI loop on the paper robot's wheels: 24 V, 10 N m at stall, no-load 40 rad/s (2 m/s)."""
    motor = DCMotor.from_datasheet(voltage=24.0, stall_torque=10.0, stall_current=20.0, no_load_speed=40.0)
    return VelocityDriver(motor, kp=5.0, ki=50.0)


def velocity_scenario():
    return ddtrack.load_scenario(SCENARIOS / "paper_line.toml", controller="kinematic_backstepping", overrides=SHORT)


def test_a_velocity_controller_drives_it_through_run_setup():
    """Kinematic backstepping (velocity output) on the velocity-driven plant: each recorded period is the plant's
    own step from the recorded state (BODY and the integrals), command and the scenario's sinusoidal wheel
    disturbance, unlike the ideal unicycle it would
    drive otherwise; a torque controller on it is refused."""
    scenario = velocity_scenario()
    setup, draws = prepare(scenario)
    assert isinstance(setup.plant, KinematicPlant)
    driven = dataclasses.replace(setup, plant_model=velocity_driven_model(paper_driver()))
    plant = driven.plant
    assert isinstance(plant, VelocityDrivenPlant)
    result = run_setup(scenario, driven, draws)
    assert result.status_name == "ok"
    state = np.column_stack([np.asarray(result.state), *(np.asarray(result.plant_state[n]) for n in ("pi_r", "pi_l"))])
    control, sim = np.asarray(result.control), scenario.simulation
    disturbance = jax.vmap(lambda t: setup.disturbance.torque(t, jnp.zeros(2)))(result.t[:-1])  # no Gaussian part
    replay = jax.vmap(lambda x, u, d: plant.advance(x, u, d, sim.control_period, RK4(sim.substeps)))
    np.testing.assert_allclose(replay(state[:-1], control[:-1], disturbance), state[1:], rtol=0, atol=1e-10)
    assert np.max(np.abs(state[1:, 3:5] - control[:-1])) > 1e-3  # the loop lags the command
    columns = ddtrack.timeseries(result)
    assert {"tau_r", "tau_l", "i_r", "i_l", "pi_r", "pi_l"} <= set(columns)
    assert np.all(np.isfinite(columns["tau_r"]))
    with pytest.raises(ddtrack.ConfigError, match="takes velocity"):
        torque_setup, _ = prepare(ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=SHORT))
        dataclasses.replace(torque_setup, plant_model=velocity_driven_model(paper_driver()))


def test_a_batch_row_is_the_single_run():
    scenario = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=SHORT)
    model = torque_driven_model(weak_motor())
    setup, draws = prepare_batch(scenario, [0, 1])
    batch = run_setup(scenario, dataclasses.replace(setup, plant_model=model), draws, batched=True)
    single_setup, single_draws = prepare(scenario, seed=1)
    single = run_setup(scenario, dataclasses.replace(single_setup, plant_model=model), single_draws)
    np.testing.assert_allclose(np.asarray(batch.state)[1], np.asarray(single.state), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(batch.logs["tau_r"])[1], np.asarray(single.logs["tau_r"]), atol=1e-12)


def test_a_scenario_names_the_motor_plants_and_gets_its_presets_motor():
    """``[plant] model = "motor_velocity"`` with ``[robot] preset``: the preset's motors under the PI loop of
    ``[plant] velocity_pi``, by name, for a velocity-output controller (as over cmd_vel); without a motor, refused."""
    burger = [*SHORT, 'robot.preset="turtlebot3_burger"']
    scenario = ddtrack.load_scenario(
        SCENARIOS / "burger_sized_20hz.toml",
        overrides=[*burger, "plant.model=motor_velocity", "plant.velocity_pi=[3, 40]"],
        controller="kinematic_backstepping",
    )
    setup, draws = prepare(scenario)
    plant = setup.plant
    assert isinstance(plant, VelocityDrivenPlant) and (float(plant.driver.kp), float(plant.driver.ki)) == (3.0, 40.0)
    expected = motor_from_datasheet(preset("turtlebot3_burger").motor)
    assert float(plant.driver.motor.back_emf) == pytest.approx(float(expected.back_emf), rel=1e-15)
    columns = ddtrack.timeseries(run_setup(scenario, setup, draws))
    assert {"i_r", "i_l", "pi_r", "pi_l"} <= set(columns)  # the plant's own states and logs, by name
    # every applied torque within the motor's torque-speed curve at the wheel's recorded speed
    wheel = (columns["v"] + float(setup.plant_params.half_axle) * columns["omega"]) / float(
        setup.plant_params.wheel_radius
    )
    low, high = torque_envelope(expected, wheel)
    assert np.all(columns["tau_r"][:-1] <= np.asarray(high)[:-1] + 1e-9)
    assert np.all(columns["tau_r"][:-1] >= np.asarray(low)[:-1] - 1e-9)
    torque = ddtrack.load_scenario(
        SCENARIOS / "burger_sized_20hz.toml", overrides=[*burger, "plant.model=motor_torque"]
    )
    assert isinstance(prepare(torque)[0].plant, TorqueDrivenPlant)
    no_motor = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=[*SHORT, "plant.model=motor_torque"])
    with pytest.raises(ddtrack.ConfigError, match="(?s)plant.model: 'motor_torque' needs the robot's motor.*burger"):
        prepare(no_motor)


def test_a_pwm_board_drives_through_its_model_of_the_motor():
    """PWM (model.md §1.7): the board's voltage R_a' tau* / (eta k_t) + k_e phi_dot from its model; on a true motor of
    another resistance the torque is tau* R_a' / R_a, and with the true model it is current control's torque."""
    from ddtrack.model.motors import drive_torque, torque_driver

    true = motor_from_datasheet(preset("turtlebot3_burger").motor)
    speeds = jnp.array([0.0, 3.0, -2.0])
    command = jnp.array([0.3, 0.2, -0.1])  # inside the torque-speed curve at those speeds
    same, _ = drive_torque(true, command, speeds, true)
    assert np.asarray(same) == pytest.approx(np.asarray(torque_driver(true, command, speeds)[0]), rel=1e-12)
    hotter = dataclasses.replace(true, resistance=1.2 * true.resistance)  # a warm winding the board does not know
    applied, _ = drive_torque(hotter, command, speeds, true)
    assert np.asarray(applied) == pytest.approx(np.asarray(command) / 1.2, rel=1e-12)
    assert np.asarray(drive_torque(hotter, command, speeds)[0]) == pytest.approx(np.asarray(command), rel=1e-12)


@pytest.mark.parametrize(
    ("robot", "overrides", "drive", "says"),
    [
        ("turtlebot3_burger", [], "pwm", "drives them by PWM"),
        ("turtlebot3_burger", ['plant.motor.drive="current"'], "current", "as if they controlled current"),
        ("turtlebot3_waffle_pi", [], "current", None),  # the XM430 has a current mode
    ],
)
def test_a_torque_law_on_a_servo_without_a_current_mode_drives_it_by_pwm_and_says_so(robot, overrides, drive, says):
    from ddtrack.scenario.motor_configs import check_drive

    scenario = ddtrack.load_scenario(
        SCENARIOS / "burger_sized_20hz.toml",
        overrides=[*SHORT, f'robot.preset="{robot}"', "plant.model=motor_torque", *overrides],
        controller="backstepping",
    )
    plant = prepare(scenario)[0].plant
    assert isinstance(plant, TorqueDrivenPlant) and (plant.pwm_model is not None) == (drive == "pwm")
    warnings = check_drive(scenario)
    assert [says in w["message"] for w in warnings] == ([] if says is None else [True])
    velocity = ddtrack.load_scenario(
        SCENARIOS / "burger_sized_20hz.toml",
        overrides=[*SHORT, f'robot.preset="{robot}"', "plant.model=motor_velocity"],
        controller="kinematic_backstepping",
    )
    assert check_drive(velocity) == []  # cmd_vel: as the robot runs
