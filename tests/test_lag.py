"""The identified velocity-lag plant (model.md §1.8): its step responses in closed form, its coupled steady state,
its speed limits, and a velocity-output controller driving it through ``run_setup``, alone and as a batch."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack.integrators import RK4
from ddtrack.model import KinematicPlant
from ddtrack.model.lag import PIONEER_3DX_ALTERNATIVE, PIONEER_3DX_WITH_LASER, LagPlant, lag_plant_model
from ddtrack.runner import prepare, prepare_batch, run_setup

PERIOD, SUBSTEPS = 0.01, 20


def respond(plant, command, periods, body0=(0.0, 0.0, 0.0, 0.0, 0.0)):
    """The BODY state at t = 0, T, ..., periods T under a constant command, from ``body0``."""
    u = jnp.asarray(command, dtype=float)

    def one(x, _):
        x_next = plant.advance(x, plant.saturate(u), jnp.zeros(2), PERIOD, RK4(SUBSTEPS))
        return x_next, x_next

    x0 = plant.init(jnp.asarray(body0, dtype=float))
    _, states = jax.lax.scan(one, x0, None, length=periods)
    t = PERIOD * np.arange(periods + 1)
    return t, np.vstack([np.asarray(x0)[None], np.asarray(states)])


@pytest.mark.parametrize("theta", [PIONEER_3DX_WITH_LASER, PIONEER_3DX_ALTERNATIVE])
def test_forward_step_from_rest_is_a_first_order_lag(theta):
    """omega* = 0 keeps omega = 0 (no yaw drive, and its coupling term is proportional to omega), so v is the
    first-order lag v(t) = v* / theta_4 (1 - exp(-t / tau)), tau = theta_1 / theta_4, and x its integral."""
    command = 0.4
    plant = LagPlant(theta)
    t, states = respond(plant, (command, 0.0), 300)
    tau, gain = theta[0] / theta[3], 1.0 / theta[3]
    np.testing.assert_allclose(np.asarray(plant.time_constants())[0], tau, rtol=1e-15)
    v = gain * command * (1.0 - np.exp(-t / tau))
    x = gain * command * (t - tau * (1.0 - np.exp(-t / tau)))
    np.testing.assert_allclose(states[:, 3], v, rtol=0, atol=1e-9)
    np.testing.assert_allclose(states[:, 0], x, rtol=0, atol=1e-9)
    assert np.all(states[:, [1, 2, 4]] == 0.0)  # straight ahead, no turn
    # after one time constant, 63.2 % of the final speed: the lag is theta_1 / theta_4, not theta_1
    at_tau = np.interp(tau, t, states[:, 3])
    assert at_tau == pytest.approx((1.0 - np.exp(-1.0)) * gain * command, rel=1e-4)


@pytest.mark.parametrize("theta", [PIONEER_3DX_WITH_LASER, PIONEER_3DX_ALTERNATIVE])
def test_turn_step_in_place_is_a_first_order_lag(theta):
    """v* = 0 with theta_3 = 0 keeps v = 0, so omega is the lag omega* / theta_6 (1 - exp(-t / (theta_2 /
    theta_6))) and theta its integral; the turn stays in place."""
    command = 0.8
    plant = LagPlant((theta[0], theta[1], 0.0, theta[3], theta[4], theta[5]))
    t, states = respond(plant, (0.0, command), 300)
    tau, gain = theta[1] / theta[5], 1.0 / theta[5]
    omega = gain * command * (1.0 - np.exp(-t / tau))
    heading = gain * command * (t - tau * (1.0 - np.exp(-t / tau)))
    np.testing.assert_allclose(states[:, 4], omega, rtol=0, atol=1e-9)
    np.testing.assert_allclose(states[:, 2], heading, rtol=0, atol=1e-9)
    assert np.all(states[:, [0, 1, 3]] == 0.0)
    np.testing.assert_allclose(plant.steady_speeds(jnp.asarray([0.0, command])), [0.0, gain * command], rtol=1e-15)


def test_the_coupling_terms_set_the_steady_turn():
    """With both commands on, the coupled steady state solves theta_4 v = theta_3 omega^2 + v* and
    (theta_6 + theta_5 v) omega = omega*: the signs of both coupling terms, checked after 20 time constants."""
    theta = (0.26, 0.25, -0.05, 1.0, 0.3, 1.08)  # coupling strong enough to move the steady state visibly
    command = np.array([0.5, 1.2])
    _, states = respond(LagPlant(theta), command, 2000)
    v, omega = states[-1, 3], states[-1, 4]
    assert theta[3] * v == pytest.approx(theta[2] * omega**2 + command[0], abs=1e-10)
    assert (theta[5] + theta[4] * v) * omega == pytest.approx(command[1], abs=1e-10)
    uncoupled = command / np.array([theta[3], theta[5]])
    assert abs(v - uncoupled[0]) > 0.03 and abs(omega - uncoupled[1]) > 0.1


def test_speed_limits_clip_the_command_and_default_to_none():
    command = jnp.asarray([2.0, -3.0])
    assert np.array_equal(LagPlant(PIONEER_3DX_WITH_LASER).saturate(command), command)
    limited = LagPlant(PIONEER_3DX_WITH_LASER, max_speed=1.2, max_yaw_rate=2.5)
    np.testing.assert_array_equal(limited.saturate(command), [1.2, -2.5])
    assert limited.input_kind == "velocity" and LagPlant.state_layout.names == ("x", "y", "theta", "v", "omega")


def test_disturbance_torques_do_not_move_it():
    plant, x = LagPlant(PIONEER_3DX_WITH_LASER), jnp.asarray([0.1, 0.2, 0.3, 0.4, 0.5])
    u = jnp.asarray([0.3, -0.2])
    with_torque = plant.advance(x, u, jnp.asarray([5.0, -5.0]), PERIOD, RK4(SUBSTEPS))
    assert np.array_equal(with_torque, plant.advance(x, u, jnp.zeros(2), PERIOD, RK4(SUBSTEPS)))


# --- through the runner --------------------------------------------------------------------------------------------

SHORT = ["simulation.duration=4", "simulation.metric_window=[0, 4]"]


def kinematic_scenario():
    return ddtrack.load_scenario(SCENARIOS / "paper_line.toml", controller="kinematic_backstepping", overrides=SHORT)


def test_a_velocity_controller_drives_the_lag_plant_through_run_setup():
    """``Setup`` simulates plant_model when it takes velocity commands (and the ideal unicycle when the true robot
    takes torques); each recorded period is the lag plant's own step from the recorded state and command."""
    scenario = kinematic_scenario()
    setup, draws = prepare(scenario)
    assert isinstance(setup.plant, KinematicPlant)  # the default true robot takes torques
    lagged = dataclasses.replace(setup, plant_model=lag_plant_model(PIONEER_3DX_WITH_LASER))
    plant = lagged.plant
    assert isinstance(plant, LagPlant)
    ideal, result = run_setup(scenario, setup, draws), run_setup(scenario, lagged, draws)
    assert result.status_name == "ok"
    state, control = np.asarray(result.state), np.asarray(result.control)
    sim = scenario.simulation
    replay = jax.vmap(lambda x, u: plant.advance(x, u, jnp.zeros(2), sim.control_period, RK4(sim.substeps)))
    np.testing.assert_allclose(replay(state[:-1], control[:-1]), state[1:], rtol=0, atol=1e-12)
    # the ideal unicycle takes each command at once; the lag plant does not
    np.testing.assert_allclose(np.asarray(ideal.state)[1:, 3:], np.asarray(ideal.control)[:-1], atol=1e-12)
    assert np.max(np.abs(state[1:, 3:] - control[:-1])) > 1e-3
    with pytest.raises(ddtrack.ConfigError, match="Cascade outputs torque commands but LagPlant takes velocity"):
        torque_setup, _ = prepare(ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=SHORT))
        dataclasses.replace(torque_setup, plant_model=lag_plant_model(PIONEER_3DX_WITH_LASER))


def test_the_lag_plant_runs_as_a_batch_row_for_row():
    scenario = kinematic_scenario()
    model = lag_plant_model(PIONEER_3DX_ALTERNATIVE, max_speed=0.6)
    setup, draws = prepare_batch(scenario, [0, 1])
    batch = run_setup(scenario, dataclasses.replace(setup, plant_model=model), draws, batched=True)
    single_setup, single_draws = prepare(scenario, seed=1)
    single = run_setup(scenario, dataclasses.replace(single_setup, plant_model=model), single_draws)
    np.testing.assert_allclose(np.asarray(batch.state)[1], np.asarray(single.state), rtol=0, atol=1e-12)
    assert np.max(np.asarray(batch.control)[..., 0]) <= 0.6


def test_a_scenario_names_the_lag_plant_of_its_preset():
    """``[plant] model = "lag"`` with ``[robot] preset = "pioneer_3dx"``: the preset's identified theta, limited to its
    top speed and yaw rate; a preset without an identified model is refused, naming the ones that have one."""
    from ddtrack.robots import preset

    pioneer = [*SHORT, 'robot.preset="pioneer_3dx"', "plant.model=lag"]
    scenario = ddtrack.load_scenario(
        SCENARIOS / "paper_line.toml", controller="kinematic_backstepping", overrides=pioneer
    )
    setup, draws = prepare(scenario)
    robot = preset("pioneer_3dx")
    assert isinstance(setup.plant, LagPlant)
    np.testing.assert_array_equal(np.asarray(setup.plant.theta), np.asarray(robot.lag))
    assert float(setup.plant.max_speed) == robot.max_speed and float(setup.plant.max_yaw_rate) == robot.max_yaw_rate
    result = run_setup(scenario, setup, draws)
    assert result.status_name == "ok"
    # the command is limited to the top speed; the speed settles at command / theta_4 (its DC gain), not above
    assert float(np.max(np.abs(result.control[:, 0]))) <= robot.max_speed + 1e-12
    assert float(np.max(np.abs(result.state[:, 3]))) <= robot.max_speed / robot.lag[3] + 1e-9
    burger = [*SHORT, 'robot.preset="turtlebot3_burger"', "plant.model=lag"]
    unidentified = ddtrack.load_scenario(
        SCENARIOS / "paper_line.toml", controller="kinematic_backstepping", overrides=burger
    )
    with pytest.raises(
        ddtrack.ConfigError, match="(?s)plant.model: 'lag' needs .*preset 'turtlebot3_burger' has none.*pioneer_3dx"
    ):
        prepare(unidentified)
