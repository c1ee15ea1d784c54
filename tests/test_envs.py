"""The Gymnasium environment ddtrack/DiffDriveTracking-v0: API conformance, determinism, and that it steps
exactly as the simulator does."""

from __future__ import annotations

import math
import subprocess
import sys
import warnings

import gymnasium
import numpy as np
import pytest
from conftest import SCENARIOS
from gymnasium.utils.env_checker import check_env

import ddtrack
from ddtrack.envs import ENV_ID, DiffDriveTrackingEnv, register_envs
from ddtrack.envs.tracking import GAMMA
from ddtrack.geometry import posture_error

PAPER_LINE = SCENARIOS / "paper_line.toml"
MODES = ("torque", "gains")


def short(seconds: float, *extra: str) -> ddtrack.Scenario:
    return ddtrack.load_scenario(
        PAPER_LINE, overrides=[f"simulation.duration={seconds}", f"simulation.metric_window=[0, {seconds}]", *extra]
    )


@pytest.mark.parametrize("mode", MODES)
def test_check_env_passes_without_a_warning(mode):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # Gymnasium's checker reports most problems as warnings
        env = gymnasium.make(ENV_ID, scenario=short(2.0), action_mode=mode)
        check_env(env.unwrapped)  # made through gymnasium.make, so it has a spec and the render/close checks run
        obs, _ = env.reset(seed=1)
        obs, *_ = env.step(env.action_space.sample())  # through gymnasium's own wrappers, checker included
    assert obs.dtype == np.float32 and obs.shape == env.observation_space.shape
    assert np.all(np.isfinite(env.observation_space.low)) and np.all(np.isfinite(env.observation_space.high))


def test_make_with_a_path_and_registration_is_idempotent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # re-registering would warn "Overriding environment"
        register_envs()
        register_envs()
        env = gymnasium.make(ENV_ID, scenario=str(PAPER_LINE), action_mode="gains")
    assert env.unwrapped.scenario.name == "paper_line"
    assert env.action_space.shape == (3,) and env.observation_space.shape == (11,)


def test_gymnasium_makes_it_in_a_fresh_process_without_importing_ddtrack_first():
    code = (
        "import sys, gymnasium\n"
        "assert 'ddtrack' not in sys.modules\n"
        f"env = gymnasium.make('ddtrack.envs:{ENV_ID}', scenario={str(PAPER_LINE)!r}, action_mode='torque')\n"
        "print(env.unwrapped.action_space.shape)\n"
    )
    done = subprocess.run([sys.executable, "-W", "error", "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "(2,)" and done.stderr == ""  # no warning printed


def test_importing_ddtrack_registers_the_environment():
    code = (
        "import gymnasium, ddtrack\n"
        f"env = gymnasium.make({ENV_ID!r}, scenario={str(PAPER_LINE)!r}, action_mode='gains')\n"
        "print(env.unwrapped.action_space.shape)\n"
    )
    done = subprocess.run([sys.executable, "-W", "error", "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "(3,)" and done.stderr == ""


@pytest.mark.parametrize("mode", MODES)
def test_a_seeded_rollout_is_identical_twice(mode):
    scenario = ddtrack.load_scenario(
        SCENARIOS / "figure_eight.toml",  # Gaussian disturbance, measurement noise
        overrides=["simulation.duration=3", "simulation.metric_window=[0, 3]"],
    )

    def rollout():
        env = DiffDriveTrackingEnv(scenario, action_mode=mode)
        actions = np.random.default_rng(7).uniform(-1, 1, (300, env.action_space.shape[0])).astype(np.float32)
        obs, _ = env.reset(seed=11)
        trace = [obs]
        for action in actions:
            obs, reward, terminated, truncated, info = env.step(action)
            trace += [obs, np.float64(reward), info["state"]]
            if terminated or truncated:
                break
        return trace

    first, again = rollout(), rollout()
    assert len(first) == len(again) > 100
    assert all(a.tobytes() == b.tobytes() for a, b in zip(first, again, strict=True))  # the same bits


@pytest.mark.parametrize("mode", MODES)
def test_a_random_agent_runs_a_thousand_steps(mode):
    env = gymnasium.make(ENV_ID, scenario=ddtrack.load_scenario(PAPER_LINE), action_mode=mode)
    assert env.unwrapped.scenario.simulation.n_steps >= 1000
    env.action_space.seed(0)
    obs, info = env.reset(seed=0)
    steps, episodes, rewards = 0, 1, []
    while steps < 1000:
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert obs in env.observation_space and math.isfinite(reward)
        rewards.append(reward)
        steps += 1
        if terminated or truncated:
            obs, info = env.reset()
            episodes += 1
    assert all(r <= 0.0 for r in rewards)  # a cost, never a bonus
    if mode == "gains":  # any positive gains stabilise Kanayama's law: 10 s of random ones still close the 10 m gap
        assert episodes == 1 and info["status"] == "ok" and info["e_tr"] < 1.0, info


def test_constant_gains_reproduce_the_run():
    """Action 0 is the scenario's own gains; its rollout is ddtrack.run's, period for period."""
    scenario = ddtrack.load_scenario(PAPER_LINE)
    result = ddtrack.run(scenario, seed=0)
    env = DiffDriveTrackingEnv(scenario, action_mode="gains")
    assert np.array_equal(env.gains_to_action(scenario.controller.gains), np.zeros(3))
    _obs, info = env.reset(seed=0)
    states, rewards, controls = [info["state"]], [], []
    for _ in range(scenario.simulation.n_steps - 1):
        _obs, reward, terminated, truncated, info = env.step(np.zeros(3, np.float32))
        assert not terminated and not truncated and np.array_equal(info["gains"], scenario.controller.gains)
        states.append(info["state"])
        rewards.append(reward)
        controls.append(info["control"])
    # XLA compiles the period alone differently from inside the simulator's scan (fusion, FMA), so the two
    # agree to rounding, not bit for bit; the tracking loop is contracting, so rounding does not grow.
    np.testing.assert_allclose(np.array(states), np.asarray(result.state), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array(controls), np.asarray(result.control)[:-1], rtol=0, atol=1e-9)
    # the reward is -T_c (J + w |tau|^2) with J of eq. 22 on the next period's error
    error, tau = np.asarray(result.error)[1:], np.asarray(result.control)[:-1]
    cost = 0.5 * error**2 @ np.asarray(GAMMA) + env.effort_weight * np.sum(tau**2, axis=1)
    np.testing.assert_allclose(rewards, -scenario.simulation.control_period * cost, rtol=1e-9)


@pytest.mark.parametrize(
    "action_dtype, atol",
    [
        (np.float64, 1e-10),  # tau / max * max is tau to an ulp; an ulp of torque moves a 40 s open loop by ~1e-14 m
        # float32 rounds each torque by up to 6e-8 relative (6e-7 N m at 10 N m): even all of one sign for 40 s,
        # 6e-7 N m * 2 / (m R = 0.6 kg m) = 2e-6 m/s^2 moves the robot 0.5 * 2e-6 * 40^2 = 1.6e-3 m; random
        # signs average out to ~1e-6 m, measured 2e-7 m
        (np.float32, 1e-4),
    ],
)
def test_replayed_torques_reproduce_the_run(action_dtype, atol):
    scenario = ddtrack.load_scenario(PAPER_LINE)
    result = ddtrack.run(scenario, seed=0)
    env = DiffDriveTrackingEnv(scenario, action_mode="torque")
    _, info = env.reset(seed=0)
    actions = (np.asarray(result.control) / scenario.robot.max_torque).astype(action_dtype)
    states = [info["state"]]
    for action in actions[:-1]:
        states.append(env.step(action)[4]["state"])
    difference = np.abs(np.array(states) - np.asarray(result.state)).max()
    assert difference <= atol
    assert difference > 0.0 or action_dtype is np.float64  # float32 actions do lose the torques' low bits


def test_reset_draws_the_run_s_plant_and_randomness_from_the_seed():
    scenario = ddtrack.load_scenario(SCENARIOS / "waypoints.toml")  # randomizes the mass
    env = DiffDriveTrackingEnv(scenario, action_mode="torque")
    masses = set()
    for seed in (3, 4):
        _, info = env.reset(seed=seed)
        setup, draws = ddtrack.prepare(scenario, seed=seed)
        assert env.setup.plant_params == setup.plant_params and info["seed"] == seed
        assert np.array_equal(env.draws.disturbance, draws.disturbance)
        assert np.array_equal(env.draws.noise, draws.noise)
        assert np.array_equal(env._episode.loop.plant.params.mass, setup.plant_params.mass)  # what it simulates
        masses.add(setup.plant_params.mass)
    assert len(masses) == 2
    # no seed: one is drawn from the environment's generator, so a seeded first reset fixes the next ones
    env.reset(seed=5)
    follow = [env.reset()[1]["seed"] for _ in range(2)]
    env.reset(seed=5)
    assert [env.reset()[1]["seed"] for _ in range(2)] == follow and follow[0] != follow[1]


def test_initial_pose_option_and_bad_options():
    env = DiffDriveTrackingEnv(short(1.0), action_mode="gains")
    obs, info = env.reset(seed=0, options={"initial_pose": [1.0, 2.0, 0.5]})
    assert np.array_equal(info["state"], [1.0, 2.0, 0.5, 0.0, 0.0])
    ref = env.setup.trajectory(0.0)
    e = posture_error(1.0, 2.0, 0.5, ref.x, ref.y, ref.theta)
    np.testing.assert_allclose(obs[:4], [e[0], e[1], np.sin(e[2]), np.cos(e[2])], rtol=1e-6)  # float32
    with pytest.raises(ddtrack.ConfigError, match="(?s)options.initial_pos.*did you mean 'initial_pose'"):
        env.reset(options={"initial_pos": [0, 0, 0]})
    with pytest.raises(ddtrack.ConfigError, match="options.initial_pose: expected 3 finite"):
        env.reset(options={"initial_pose": [0, math.nan, 0]})


def test_divergence_terminates_and_charges_the_rest_of_the_episode():
    scenario = short(1.0, "simulation.divergence_error=5.0")  # the robot starts 10 m from the reference
    env = DiffDriveTrackingEnv(scenario, action_mode="torque", effort_weight=0.0)
    env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(np.zeros(2))
    assert terminated and not truncated and info["status"] == "diverged"
    assert np.array_equal(info["state"], env.setup.x0)  # frozen, as the simulator freezes it
    assert obs in env.observation_space  # the 10 m error is clipped to the 5 m bound
    bound = 0.5 * (50.0 * 5.0**2 + math.pi**2)  # the largest running cost, per second
    assert reward == pytest.approx(-scenario.simulation.duration * bound, rel=1e-12)
    with pytest.raises(ddtrack.RunError, match="reset"):
        env.step(np.zeros(2))


def test_truncated_at_the_scenario_s_end():
    env = DiffDriveTrackingEnv(short(0.05), action_mode="gains")
    env.reset(seed=0)
    flags = [env.step(np.zeros(3))[2:4] for _ in range(5)]
    assert flags == [(False, False)] * 4 + [(False, True)]


def test_gains_action_maps_zero_to_the_scenario_s_gains_and_the_ends_to_the_bounds():
    env = DiffDriveTrackingEnv(short(1.0, "controller.gains=[2.0, 40.0, 10.0]"), action_mode="gains")
    env.reset(seed=0)
    gains = {a: env.step(np.full(3, a, np.float32))[4]["gains"] for a in (-1.0, 0.0, 1.0, 7.0)}
    assert np.array_equal(gains[0.0], [2.0, 40.0, 10.0])
    np.testing.assert_allclose(gains[-1.0], [0.1, 1.0, 0.1], rtol=1e-12)
    np.testing.assert_allclose(gains[1.0], [10.0, 600.0, 60.0], rtol=1e-12)
    assert np.array_equal(gains[7.0], gains[1.0])  # out-of-range actions are clipped
    middle = np.array([5.0, 100.0, 1.0])
    np.testing.assert_allclose(env.step(env.gains_to_action(middle))[4]["gains"], middle, rtol=1e-12)


def test_bad_arguments_are_config_errors_naming_the_argument():
    with pytest.raises(ddtrack.ConfigError, match="(?s)action_mode: unknown action mode 'gain'.*did you mean 'gains'"):
        DiffDriveTrackingEnv(PAPER_LINE, action_mode="gain")
    with pytest.raises(ddtrack.ConfigError, match="action_mode.*controller.kind is 'mppi'"):
        DiffDriveTrackingEnv(ddtrack.load_scenario(PAPER_LINE, controller="mppi"), action_mode="gains")
    with pytest.raises(ddtrack.ConfigError, match="does not exist"):
        gymnasium.make(ENV_ID, scenario="no_such_scenario.toml")
    with pytest.raises(ddtrack.ConfigError, match="effort_weight"):
        DiffDriveTrackingEnv(PAPER_LINE, effort_weight=-1.0)
    env = DiffDriveTrackingEnv(PAPER_LINE, action_mode="torque")
    with pytest.raises(ddtrack.RunError, match="reset"):
        env.step(np.zeros(2))
    env.reset(seed=0)
    with pytest.raises(ddtrack.ConfigError, match=r"action: expected shape \(2,\)"):
        env.step(np.zeros(3))


def test_an_nn_adaptive_scenario_runs_as_backstepping_with_its_own_gain_bounds():
    scenario = ddtrack.load_scenario(
        PAPER_LINE, controller="nn_adaptive_backstepping", overrides=["controller.gain_max=[5.0, 100.0, 20.0]"]
    )
    env = DiffDriveTrackingEnv(scenario, action_mode="gains")
    assert env.scenario.controller.kind == "backstepping"
    assert env.scenario.controller.gains == scenario.controller.gains
    assert env.scenario.controller.inner == scenario.controller.inner
    np.testing.assert_array_equal(env.observation_space.high[8:], np.float32([5.0, 100.0, 20.0]))


def test_make_with_no_arguments_runs_the_default_scenario_and_passes_check_env():
    env = gymnasium.make(ENV_ID)  # Gymnasium's convention: no argument needed
    try:
        assert env.unwrapped.scenario.name == "training"
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(env.unwrapped)
    finally:
        env.close()


def test_on_the_default_every_seed_is_a_different_episode():
    env = DiffDriveTrackingEnv()
    episodes = []
    for seed in (0, 1):
        env.reset(seed=seed)
        episodes.append([env.step(np.zeros(2))[1] for _ in range(50)])
    assert episodes[0] != episodes[1]  # another plant, disturbance and noise: another episode
    again = DiffDriveTrackingEnv()
    again.reset(seed=0)
    assert [again.step(np.zeros(2))[1] for _ in range(50)] == episodes[0]  # and the same seed, the same one


def test_on_a_paper_scenario_the_seed_changes_nothing():
    # documented loudly (docs/guide.md, "What a seed changes"): the paper's cases have no randomness
    env = DiffDriveTrackingEnv(PAPER_LINE)
    rollouts = []
    for seed in (0, 1):
        env.reset(seed=seed)
        rollouts.append([env.step(np.zeros(2))[1] for _ in range(20)])
    assert rollouts[0] == rollouts[1]


def test_importing_ddtrack_envs_after_ddtrack_registers_the_environment():
    """``import ddtrack`` then ``import ddtrack.envs``: Gymnasium loads inside ddtrack.envs' own import, which
    registers the environment at its end (the import hook once tried to register from the half-loaded module)."""
    code = (
        "import ddtrack\nimport ddtrack.envs\nimport gymnasium\n"
        "print('ddtrack/DiffDriveTracking-v0' in gymnasium.registry)\n"
    )
    done = subprocess.run([sys.executable, "-W", "error", "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"
