"""``ddtrack tune``: the gradient through whole rollouts is right, and the command writes a usable fragment."""

from __future__ import annotations

import json
import tomllib

import jax.numpy as jnp
import numpy as np
import pytest
from conftest import SCENARIOS, central_difference

import ddtrack
from ddtrack.studies.tune import DEFAULT_GAMMA, problems, total_loss

# 3 s from 0.3 m off the line: the gains act from the start (no clamp-dominated transient), the window is [1, 3] s
SHORT = ["simulation.duration=3", "simulation.metric_window=[1, 3]", "initial.pose=[0, 0.3, 0]"]


@pytest.mark.parametrize("effort_weight, whole_run", [(0.0, False), (1e-3, True)])
def test_gradient_through_rollouts_matches_finite_differences(effort_weight, whole_run):
    scenario = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=SHORT)
    training = problems([scenario], [0, 1])
    gamma = jnp.asarray(DEFAULT_GAMMA)
    log_gains = np.log([1.5, 40.0, 10.0])

    def loss(lg):
        return float(total_loss(training, jnp.asarray(lg), gamma, effort_weight, whole_run))

    import jax

    analytic = np.asarray(
        jax.grad(lambda lg: total_loss(training, lg, gamma, effort_weight, whole_run))(jnp.asarray(log_gains))
    )
    numeric = central_difference(loss, log_gains, 1e-5)
    assert np.all(np.abs(analytic) > 0)  # every gain matters to this loss
    np.testing.assert_allclose(analytic, numeric, rtol=1e-5)


def test_tune_command_lowers_the_loss_and_writes_a_fragment(tmp_path, cli):
    out = tmp_path / "tune"
    code, stdout, stderr = cli(
        "tune",
        SCENARIOS / "paper_line.toml",
        SCENARIOS / "circle.toml",
        "--seeds",
        "2",
        "--steps",
        "4",
        *[a for s in SHORT for a in ("--set", s)],
        "--out",
        out,
    )
    assert code == 0, stderr
    summary = json.loads((out / "tune.json").read_text())
    assert summary["final_loss"] < summary["initial_loss"] and "lower" in stdout
    fragment = tomllib.loads((out / "tuned.toml").read_text())
    assert fragment["controller"]["gains"] == pytest.approx(summary["gains"])
    rows = (out / "loss.csv").read_text().splitlines()
    assert rows[0].startswith("step,loss,kx") and len(rows) == 1 + 5
    assert (out / "loss.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the fragment's gains, applied to the same training runs, give the reported final loss, and the scenarios'
    # own gains its initial loss: what tuned.toml holds is what was measured
    settings = summary["settings"]
    specs = [ddtrack.load_scenario(SCENARIOS / name, overrides=SHORT) for name in ("paper_line.toml", "circle.toml")]
    training = problems(specs, range(settings["seeds"]))
    gamma, weight = jnp.asarray(settings["gamma"]), settings["effort_weight"]
    for gains, reported in (
        (fragment["controller"]["gains"], "final_loss"),
        (settings["initial_gains"], "initial_loss"),
    ):
        loss = float(total_loss(training, jnp.log(jnp.asarray(gains)), gamma, weight, settings["whole_run"]))
        assert loss == pytest.approx(summary[reported], rel=1e-9), reported


@pytest.mark.parametrize(
    "args, field",
    [
        (["--controller", "nn_adaptive_backstepping"], "--controller"),
        (["--gamma", "1", "-1", "0"], "--gamma"),
        (["--set", "controller.gains=[1, 0, 1]"], "controller.gains"),
        # a slip plant's substep loop runs a traced count: no reverse-mode gradient (was a JAX traceback)
        (["--set", "plant.model=slip", "--set", "plant.wheel_inertia=2e-3"], "plant.model"),
    ],
)
def test_tune_bad_input_exits_2_and_writes_nothing(tmp_path, cli, args, field):
    code, _, stderr = cli("tune", SCENARIOS / "paper_line.toml", *args, "--out", tmp_path / "tune")
    assert code == 2 and stderr.startswith(f"error: {field}"), stderr
    assert not (tmp_path / "tune").exists()


CMD_VEL = """name = "pioneer_cmd_vel"
[simulation]
duration = 3.0
control_period = 0.05
metric_window = [1.0, 3.0]
[robot]
preset = "pioneer_3dx"
[plant]
model = "lag"
[trajectory]
kind = "line"
speed = 0.4
[initial]
pose = [0.0, 0.3, 0.0]
[controller]
kind = "backstepping"
inner = "none"
"""


def test_gains_of_a_law_over_cmd_vel_are_tuned_through_a_velocity_plant(tmp_path, cli):
    """Over cmd_vel (inner = "none") on the Pioneer's identified lags: the same gradient check, and the effort term,
    which integrates wheel torques that such a law never commands, is refused."""
    path = tmp_path / "pioneer.toml"
    path.write_text(CMD_VEL)
    training = problems([ddtrack.load_scenario(path)], [0])
    gamma = jnp.asarray(DEFAULT_GAMMA)
    log_gains = np.log([1.5, 40.0, 10.0])
    import jax

    analytic = np.asarray(jax.grad(lambda lg: total_loss(training, lg, gamma, 0.0))(jnp.asarray(log_gains)))
    numeric = central_difference(lambda lg: float(total_loss(training, jnp.asarray(lg), gamma, 0.0)), log_gains, 1e-5)
    assert np.all(np.abs(analytic) > 0)
    np.testing.assert_allclose(analytic, numeric, rtol=1e-5)
    code, _, stderr = cli("tune", path, "--effort-weight", "0.1", "--steps", "1", "--out", tmp_path / "tune")
    assert code == 2 and stderr.startswith("error: --effort-weight") and not (tmp_path / "tune").exists()


@pytest.mark.parametrize("delay", [0.08, 0.1])  # 1.6 periods (a fraction splits one), 2 whole periods
def test_tuning_sees_the_actuation_delay(tmp_path, delay):
    """tune builds its plants inside its jitted loss (traced parameters): the delay acts there as in a run. A plant
    built in a trace once lost its command queue, and tune optimised a robot without its delay (caught by the
    identify-and-tune example, whose identified delay is 0.996 of a period)."""
    import jax

    losses = {}
    for name, sensing in (("none", ""), ("delayed", f"[sensing]\nactuation_delay = {delay}\n")):
        path = tmp_path / f"{name}.toml"
        path.write_text(CMD_VEL + sensing)
        training = problems([ddtrack.load_scenario(path)], [0])
        gamma = jnp.asarray(DEFAULT_GAMMA)
        log_gains = jnp.log(jnp.asarray([1.5, 40.0, 10.0]))
        eager = float(total_loss(training, log_gains, gamma, 0.0))
        in_jit = jax.jit(lambda lg, training=training, gamma=gamma: total_loss(training, lg, gamma, 0.0))
        traced = float(in_jit(log_gains))
        np.testing.assert_allclose(traced, eager, rtol=1e-12)
        losses[name] = traced
    assert abs(losses["delayed"] / losses["none"] - 1) > 1e-3  # the delay changes the loss it tunes
