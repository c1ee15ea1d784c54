"""Scenarios that cannot mean what they say are refused when loaded (exit 2, naming the field and the numbers),
and a failed run's remedy names its cause."""

from __future__ import annotations

import html
import json
import math

import numpy as np
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack.errors import ConfigError
from ddtrack.sim import remedy


def test_a_reference_faster_than_the_clamp_is_refused(cli):
    # a 1 m/s circle for a Burger clamped at 0.22 m/s ran "ok" with 1.89 m of error before
    code, _, stderr = cli("validate", SCENARIOS / "burger_20hz.toml", "--set", "trajectory.speed=1")
    assert code == 2 and "Traceback" not in stderr
    assert "trajectory.speed" in stderr and "1 m/s" in stderr and "controller.max_velocity = 0.22" in stderr


def test_a_speed_in_km_per_hour_gets_the_conversion():
    with pytest.raises(ConfigError, match=r"meant in km/h, that is 0\.139 m/s"):
        ddtrack.load_scenario(SCENARIOS / "burger_20hz.toml", overrides=["trajectory.speed=0.5"])


def test_a_yaw_rate_beyond_the_clamp_is_refused():
    with pytest.raises(ConfigError, match="yaw rate.*controller.max_yaw_rate"):
        ddtrack.load_scenario(SCENARIOS / "circle.toml", overrides=["controller.max_yaw_rate=0.1"])


def test_an_angle_in_degrees_is_refused_with_its_radians(cli):
    code, _, stderr = cli("run", SCENARIOS / "paper_line.toml", "--set", "trajectory.heading=45")
    assert code == 2 and "trajectory.heading" in stderr and f"{math.radians(45):.10g}" in stderr
    with pytest.raises(ConfigError, match=r"initial.pose\[2\]"):
        ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=["initial.pose=[0, 10, 90]"])


def test_a_mass_in_grams_is_refused():
    with pytest.raises(ConfigError, match="robot.mass.*radius of gyration"):
        ddtrack.load_scenario(SCENARIOS / "burger_20hz.toml", overrides=["robot.mass=1000"])
    with pytest.raises(ConfigError, match="plant.mass"):
        ddtrack.load_scenario(SCENARIOS / "burger_20hz.toml", overrides=["plant.mass=1000"])


def test_a_reference_near_the_clamp_is_warned(cli):
    code, _, stderr = cli("validate", SCENARIOS / "paper_line.toml", "--set", "trajectory.speed=1.9")
    assert code == 0 and "[reference_near_limit]" in stderr and "95 %" in stderr


@pytest.mark.parametrize("path", sorted(SCENARIOS.glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_scenario_is_feasible(path):
    from ddtrack.feasibility import check

    assert check(ddtrack.load_scenario(path)) == []


def test_the_remedy_names_saturation_as_the_cause():
    saturated = {"saturated": np.r_[np.ones(80), np.zeros(20)]}
    assert "lower the gains" in remedy("diverged", {"saturated": np.ones(3)})  # failed at once: no evidence
    assert "could not do what the reference asked" in remedy("diverged", saturated)
    assert "lower the gains" in remedy("diverged", {"saturated": np.zeros(100)})


def test_the_sampled_growth_is_the_spectral_radius_of_the_held_loop():
    """e_{k+1} = (1 - T k - a) e_k + a e_{k-1} (model.md §2.7), against the eigenvalues of its companion matrix; and
    the closed-form stability limit T k < 2 (1 - a) on both sides."""
    from ddtrack.feasibility import sampled_growth

    for rate, derivative, period in [(10.0, 0.0, 0.01), (8.3, 0.0, 0.25), (191.0, 0.3, 0.004), (50.0, 1.2, 0.01)]:
        step = np.array([[1.0 - period * rate - derivative, derivative], [1.0, 0.0]])
        assert sampled_growth(rate, derivative, period) == pytest.approx(max(abs(np.linalg.eigvals(step))), rel=1e-12)
    for derivative in (0.0, 0.4):
        limit = 2.0 * (1.0 - derivative) / 10.0
        assert sampled_growth(10.0, derivative, 0.999 * limit) < 1.0 < sampled_growth(10.0, derivative, 1.001 * limit)


def test_the_inner_loops_rates_on_the_true_robot():
    """Computed torque on a model whose masses are off: k = K_c m_hat / m per channel. The wheel PD: the rates of
    its bandwidth formula (model.md §2.6) evaluated on the true robot."""
    from ddtrack.feasibility import inner_loop_channels

    scenario = ddtrack.load_scenario(SCENARIOS / "burger_20hz.toml", controller="backstepping")
    nominal, true = scenario.robot.params(), scenario.plant_params()
    (_, k_v, a_v, _), (_, k_w, a_w, _) = inner_loop_channels(scenario)
    assert (a_v, a_w) == (0.0, 0.0)
    assert k_v == pytest.approx(10.0 * nominal.effective_mass / true.effective_mass, rel=1e-12)
    assert k_w == pytest.approx(10.0 * nominal.effective_inertia_axle / true.effective_inertia_axle, rel=1e-12)
    pd = ddtrack.load_scenario(
        SCENARIOS / "paper_line.toml", overrides=['controller.inner="pd"', "controller.kd=0.001"]
    )
    rates = pd.controller.inner_bandwidth(pd.plant_params())
    (_, k_v, a_v, _), (_, k_w, a_w, _) = inner_loop_channels(pd)
    assert (k_v, k_w) == pytest.approx(rates, rel=1e-12)
    assert (a_v, a_w) == pytest.approx((rates[0] * 0.001 / 0.125, rates[1] * 0.001 / 0.125), rel=1e-12)


def test_a_control_period_that_makes_the_inner_loop_unstable_is_named(tmp_path, cli):
    """A Burger's computed-torque loop (K_c = 10 1/s, its true robot 20 % heavier: k_v = 8.33 1/s) held over
    T_c: stable below T_c = 2 / k_v = 0.24 s. At 0.25 s the run diverges, and the run, its remedy, metrics.json and
    the report name the control period and K_c, not the Kanayama gains; at 0.25 s with the advised K_c it tracks."""
    from ddtrack.feasibility import check

    burger = SCENARIOS / "burger_20hz.toml"
    short = ["simulation.duration=5", "simulation.metric_window=[0, 5]"]
    stable = ddtrack.load_scenario(
        burger, overrides=[*short, "simulation.control_period=0.2"], controller="backstepping"
    )
    assert check(stable) == []
    scenario = ddtrack.load_scenario(
        burger, overrides=[*short, "simulation.control_period=0.25"], controller="backstepping"
    )
    nominal, true = scenario.robot.params(), scenario.plant_params()
    per_gain = (
        nominal.effective_mass / true.effective_mass,
        nominal.effective_inertia_axle / true.effective_inertia_axle,
    )
    assert 2.0 / (10.0 * per_gain[0]) == pytest.approx(0.24, rel=1e-12)  # the v channel's limit on T_c
    advised = [f"{1.0 / (0.25 * c):.3g}" for c in per_gain]  # half of each channel's limit on K_c
    assert advised == ["4.8", "5.16"]
    (warning,) = check(scenario)
    assert warning["code"] == "sampled_inner_loop_unstable"
    assert "simulation.control_period to 0.12 s or less" in warning["message"]
    assert f"controller.kc to [{advised[0]}, {advised[1]}] 1/s or less" in warning["message"]
    assert "omega channel" not in warning["message"]  # k_w T_c = 1.94: that channel is stable, if barely

    def run(out, *overrides: str):
        sets = [a for o in [*short, "simulation.control_period=0.25", *overrides] for a in ("--set", o)]
        return cli("run", burger, "--controller", "backstepping", *sets, "--out", out)

    code, _, stderr = run(tmp_path / "unstable")
    assert code == 1 and stderr == f"run diverged at t = 2.50 s: {warning['message']}\n", stderr
    assert json.loads((tmp_path / "unstable" / "metrics.json").read_text())["warnings"] == [warning]
    code, _, _ = cli("report", tmp_path / "unstable")
    page = html.unescape((tmp_path / "unstable" / "report.html").read_text())
    assert code == 0 and f"To try: {warning['message']}." in page
    code, _, stderr = run(tmp_path / "advised", f"controller.kc=[{advised[0]}, {advised[1]}]")  # the same program
    assert code == 0 and stderr == "", stderr


def test_the_remedy_names_the_unstable_inner_loop_only_for_a_failed_run():
    warning = {"code": "sampled_inner_loop_unstable", "message": "the inner loop is unstable"}
    assert remedy("diverged", {"saturated": np.zeros(100)}, [warning]) == "the inner loop is unstable"
    assert remedy("non_finite", {}, [{"code": "reference_near_limit", "message": "x"}, warning]) == warning["message"]
    assert remedy("ok", {}, [warning]) == ""


@pytest.mark.parametrize("name", ["paper_square", "figure_eight"])
def test_the_sampled_reference_is_the_reference_at_each_period(name):
    """The load-time checks sample the reference over a padded length (one program for many lengths) and keep
    the run's samples: they must be the trajectory's own values at t = 0, T_c, ..., the duration."""
    import jax

    from ddtrack.feasibility import sample_reference

    scenario = ddtrack.load_scenario(SCENARIOS / f"{name}.toml")
    sim = scenario.simulation
    times = np.linspace(0.0, sim.duration, int(sim.duration / sim.control_period) + 1)
    expected = jax.vmap(scenario.trajectory.build())(times)
    sampled = sample_reference(scenario)
    for got, want in zip(jax.tree_util.tree_leaves(sampled), jax.tree_util.tree_leaves(expected), strict=True):
        assert got.shape == times.shape
        np.testing.assert_allclose(got, np.asarray(want), rtol=0, atol=1e-12)
