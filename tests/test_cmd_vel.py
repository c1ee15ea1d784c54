"""Velocity-level laws over cmd_vel: ``[controller] inner = "none"`` (model.md §2.7)."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from conftest import SCENARIOS

from ddtrack import load_scenario
from ddtrack.errors import ConfigError
from ddtrack.runner import prepare, run, run_setup

SHORT = ["simulation.duration=4", "simulation.metric_window=[0, 4]"]
BURGER = SCENARIOS / "burger_cmd_vel_figure8.toml"
#: the Burger's PI wheel-speed loop alone (its latency and odometry are the NN test's; they only slow compiling here)
BURGER_BASE = ["sensing.actuation_delay=0", "sensing.odometry=false", "sensing.encoder_counts=0"]
#: the Pioneer 3-DX's identified lags (Martins et al.) on the 6 m figure eight, which starts on the robot's pose
PIONEER_LAG = ["robot.preset=pioneer_3dx", "plant.model=lag"]


def e_tr(result) -> np.ndarray:
    error = np.asarray(result.error)
    return np.hypot(error[:, 0], error[:, 1])


def test_backstepping_without_inner_loop_is_kinematic_backstepping():
    # same gains and clamps: on the default plant both drive the unicycle with ideal velocity tracking
    alone = run(load_scenario(SCENARIOS / "paper_line.toml", overrides=[*SHORT, "controller.inner=none"]))
    kinematic = run(load_scenario(SCENARIOS / "paper_line.toml", overrides=SHORT, controller="kinematic_backstepping"))
    np.testing.assert_array_equal(np.asarray(alone.state), np.asarray(kinematic.state))
    assert set(alone.logs) == set(kinematic.logs)
    for name in alone.logs:
        np.testing.assert_array_equal(np.asarray(alone.logs[name]), np.asarray(kinematic.logs[name]))


@pytest.mark.parametrize("kind", ["backstepping", "ltv_lqr", "regulated_pure_pursuit"])
@pytest.mark.parametrize(
    ("path", "plant"),
    [(BURGER, BURGER_BASE), (SCENARIOS / "figure_eight.toml", PIONEER_LAG)],
    ids=["motor_velocity", "lag"],
)
def test_velocity_laws_drive_velocity_commanded_bases(kind, path, plant):
    scenario = load_scenario(path, overrides=[*SHORT, *plant, "controller.inner=none"], controller=kind)
    result = run(scenario)
    assert int(result.status) == 0
    errors = e_tr(result)
    # both start on the reference at rest: the base's lag costs centimetres while it speeds up to the reference's
    # 0.1-0.5 m/s (measured: at most 4 cm on the Burger, 8.5 cm on the Pioneer), and the laws close the gap below 5 cm
    assert errors.max() < 0.15 and errors[-1] < 0.05, (errors.max(), errors[-1])


def test_torque_controller_on_velocity_base_names_controller_inner():
    with pytest.raises(ConfigError, match="inner") as caught:
        prepare(load_scenario(BURGER, overrides=SHORT, controller="backstepping"))
    assert caught.value.field == "controller.inner" and 'inner = "none"' in caught.value.suggestion


def test_velocity_output_on_torque_plant_names_controller_inner():
    with pytest.raises(ConfigError) as caught:
        overrides = [*SHORT, "plant.model=motor_torque", "controller.inner=none"]
        prepare(load_scenario(BURGER, overrides=overrides, controller="backstepping"))
    assert caught.value.field == "controller.inner" and "computed_torque" in caught.value.suggestion


def test_strict_without_inner_loop_is_refused_and_writes_nothing(tmp_path, cli):
    out = tmp_path / "run"
    code, _, stderr = cli(
        "run", SCENARIOS / "paper_line.toml", "--set", "controller.strict=true", "--set", "controller.inner=none",
        "--out", out,
    )  # fmt: skip
    assert code == 2 and "controller.strict" in stderr and not out.exists()


def test_nn_model_jacobians_need_an_inner_loop():
    with pytest.raises(ConfigError) as caught:
        load_scenario(
            BURGER,
            overrides=["controller.inner=none", "controller.jacobian=analytic"],
            controller="nn_adaptive_backstepping",
        )
    assert caught.value.field == "controller.jacobian" and "network" in caught.value.suggestion


def test_nn_adaptive_over_cmd_vel_identifies_the_true_base():
    nn = ["controller.inner=none", "controller.identification_duration=5", "controller.epochs=3"]
    scenario = load_scenario(BURGER, overrides=[*SHORT, *nn], controller="nn_adaptive_backstepping")
    setup, draws = prepare(scenario)
    result = run_setup(scenario, setup, draws)
    assert int(result.status) == 0 and e_tr(result).max() < 0.15
    # the same identification on the ideal unicycle (the dynamic plant under velocity commands) learns another map:
    # the Burger's PI loop and 50 ms latency are in the data the emulator learned from
    ideal = load_scenario(BURGER, overrides=[*SHORT, *nn, "plant.model=dynamic"], controller="nn_adaptive_backstepping")
    ideal_setup, _ = prepare(ideal)
    true_weights, ideal_weights = (
        jax.tree_util.tree_leaves(s.identification.emulator.mlp) for s in (setup, ideal_setup)
    )
    assert max(float(np.max(np.abs(a - b))) for a, b in zip(true_weights, ideal_weights, strict=True)) > 1e-3
    assert not np.allclose(setup.identification.nmse, ideal_setup.identification.nmse, rtol=1e-3)
