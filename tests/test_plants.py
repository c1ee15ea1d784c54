"""Plants are read by their layouts: a plant with more states than BODY, registered by name, runs through a single
run, a batch (what ``mc`` runs) and the Gymnasium environment (and, installed as a plugin, through ``ddtrack run``
and ``mc``: test_plugins.py), and a controller whose output a plant does not take is refused."""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest
from conftest import ROOT, SCENARIOS

import ddtrack
from ddtrack.layout import BODY, Layout
from ddtrack.model import DynamicPlant, KinematicPlant, RobotParams
from ddtrack.runner import prepare, prepare_batch, run_setup
from ddtrack.scenario import registry
from ddtrack.sim.simulate import recorded
from ddtrack.studies.batches import batch_metrics

sys.path.insert(0, str(ROOT / "examples" / "plugin" / "src"))  # the example plugin, as installed
from ddtrack_integral_kanayama import wheel_angles
from ddtrack_integral_kanayama.wheel_angles import WheelAnglePlant

SHORT = ["simulation.duration=2", "simulation.metric_window=[0, 2]"]


@pytest.fixture(scope="module", autouse=True)
def registered():
    """The example plugin's 7-state plant, registered as its entry point would (one file, one registration)."""
    wheel_angles.register()
    yield
    del registry._PLANTS["wheel_angles"]


def scenario(*overrides):
    return ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=[*SHORT, *overrides])


SEVEN = "plant.model=wheel_angles"


def described(plant) -> str:
    """The built plant and its layouts, for a failure's message (a CI run once saw it record no wheel angles)."""
    kind = f"{type(plant).__module__}.{type(plant).__name__}"
    return f"{kind}: states {plant.state_layout.names}, recorded {recorded(plant).names}"


def test_a_seven_state_plant_runs_alone_and_matches_the_five_state_robot():
    paper, wheels = scenario(), scenario(SEVEN)
    setup, draws = prepare(paper)
    five = ddtrack.timeseries(run_setup(paper, setup, draws))
    wheels_setup, wheels_draws = prepare(wheels)
    seven = ddtrack.timeseries(run_setup(wheels, wheels_setup, wheels_draws))
    assert set(seven) - set(five) == {"phi_r", "phi_l"}, described(
        wheels_setup.plant
    )  # its own states, by their names; the rest unchanged
    for name in five:  # the wheel angles feed nothing back, so the robot moves as the 5-state one does
        np.testing.assert_allclose(seven[name], five[name], rtol=1e-12, atol=1e-12, err_msg=name)
    # each wheel turned by the integral of its speed (v +- L omega) / r (trapezoids of the recorded speeds)
    params = setup.plant_params
    for name, sign in (("phi_r", 1.0), ("phi_l", -1.0)):
        speed = (five["v"] + sign * float(params.half_axle) * five["omega"]) / float(params.wheel_radius)
        turned = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(five["t"]))])
        assert seven[name][0] == 0.0
        np.testing.assert_allclose(seven[name], turned, atol=2e-3 * np.max(np.abs(turned)), err_msg=name)
    assert np.max(np.abs(seven["phi_r"])) > 1.0  # it did turn


def test_a_seven_state_plant_runs_as_a_batch():
    paper, wheels = scenario(), scenario(SEVEN)
    setup, draws = prepare_batch(paper, [0, 1, 2])
    seven, _ = prepare_batch(wheels, [0, 1, 2])
    result = run_setup(wheels, seven, draws, batched=True)
    assert result.state.shape[0] == 3 and result.state.shape[-1] == 5  # BODY rows, whatever the plant
    why = (
        f"{type(seven.plant).__name__}: states {seven.plant.state_layout.names}, recorded {recorded(seven.plant).names}"
    )
    assert set(result.plant_state) == {"phi_r", "phi_l"}, why
    assert result.plant_state["phi_r"].shape == result.t.shape
    five, seven_rows = batch_metrics(paper, setup, draws), batch_metrics(paper, seven, draws)
    for a, b in zip(five, seven_rows, strict=True):
        assert b["e_tr_mean"] == pytest.approx(a["e_tr_mean"], rel=1e-12)


def test_a_seven_state_plant_runs_in_the_environment():
    from gymnasium.utils.env_checker import check_env

    from ddtrack.envs import DiffDriveTrackingEnv

    env = DiffDriveTrackingEnv(scenario(SEVEN), action_mode="gains")
    check_env(env, skip_render_check=True)
    reference = DiffDriveTrackingEnv(scenario(), action_mode="gains")
    for e in (env, reference):
        e.reset(seed=3)
    for _ in range(20):
        observation, reward, *_, info = env.step(np.zeros(3))
        expected, expected_reward, *_ = reference.step(np.zeros(3))
        np.testing.assert_allclose(observation, expected, rtol=1e-6)
        assert info["state"].shape == (5,) and reward == pytest.approx(expected_reward, rel=1e-9)
    assert env._x.shape == (7,) and float(env._x[5]) != 0.0  # the environment carries the plant's whole state


def test_two_classes_with_the_same_fields_have_different_structures():
    """A pytree's class is part of its structure. jaxlib 0.10 compares ``register_dataclass`` nodes by their fields
    alone, so the 5-state and the 7-state plant (one field, ``params``, each) compared equal, and a jitted function
    whose two cache entries met in one hash bucket ran the other plant's program: the environment's reference
    robot once got a 7-state x (about one CI run in three)."""
    import jax

    params = RobotParams()
    five, seven = (jax.tree_util.tree_structure(plant) for plant in (DynamicPlant(params), WheelAnglePlant(params)))
    assert five != seven
    sensed = ddtrack.model.SensedPlant(DynamicPlant(params), 0.033, 0.08, 0.033, 0.08, odometry=True)
    assert jax.tree_util.tree_structure(sensed) != jax.tree_util.tree_structure(
        dataclasses.replace(sensed, odometry=False)
    )
    assert jax.tree_util.tree_structure(dataclasses.replace(params, mass=2.0)) == jax.tree_util.tree_structure(params)
    paths = [jax.tree_util.keystr(path) for path, _ in jax.tree_util.tree_flatten_with_path(sensed)[0]]
    assert ".inner.params.mass" in paths  # leaves keep their names (errors inside jit name the field)


def test_a_controller_the_plant_cannot_take_is_refused_when_assembled():
    setup, _ = prepare(scenario())
    with pytest.raises(ddtrack.ConfigError, match="Backstepping outputs velocity commands but DynamicPlant takes"):
        dataclasses.replace(setup, controller=ddtrack.controllers.Backstepping())
    with pytest.raises(ddtrack.ConfigError, match="controller.inner: Cascade outputs torque commands but Kinematic"):
        prepare(scenario("plant.model=unicycle"))
    with pytest.raises(ddtrack.ConfigError, match="(?s)plant.model: unknown plant 'wheel_angle'.*'wheel_angles'"):
        scenario("plant.model=wheel_angle")
    with pytest.raises(ValueError, match="Cascade outputs torque commands but KinematicPlant takes velocity"):
        loop = ddtrack.ClosedLoop(KinematicPlant(), setup.controller, setup.trajectory)
        ddtrack.simulate(loop, setup.x0, ddtrack.sim.Draws.zeros(5), n_steps=5)


def test_registration_checks_the_plant():
    with pytest.raises(TypeError, match="letters, digits"):
        ddtrack.register_plant("wheel angles", WheelAnglePlant)
    with pytest.raises(TypeError, match="already registered"):
        ddtrack.register_plant("dynamic", WheelAnglePlant)
    assert registry.plant_kind("wheel_angles").summary == "The Lagrangian robot with its wheel angles."


def test_layouts_name_their_channels():
    assert BODY.index("omega") == 4 and BODY.unit("v") == "m/s" and len(WheelAnglePlant.state_layout) == 7
    assert DynamicPlant(RobotParams()).input_kind == "torque" and KinematicPlant().input_kind == "velocity"
    with pytest.raises(ValueError, match="no channel 'v_x'"):
        BODY.index("v_x")
    with pytest.raises(ValueError, match="one unit per name"):
        Layout(("a", "a"), ("m", "m"))
