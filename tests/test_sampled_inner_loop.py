"""The inner loop, its torques held over each control period, is a sampled loop (model.md §2.7): loading a scenario
warns when the period makes it unstable, or makes a sliding-mode boundary layer chatter, and a failed run's remedy
says so. The analysis is checked against the simulator: the onsets it predicts are where runs start to ring."""

from __future__ import annotations

import html
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack.feasibility import check, check_sampled_inner_loop, inner_loop_channels, sampled_growth
from ddtrack.sim import remedy

BURGER = SCENARIOS / "burger_sized_20hz.toml"  # K_c = 10 1/s over a nominal model 20 % lighter than the true robot
PERIODS = 300  #: every run below lasts this many periods, so a controller's runs share one program


def test_the_sampled_growth_is_the_spectral_radius_of_the_held_loop():
    """e_{k+1} = (1 - T k - a) e_k + a e_{k-1}, against the eigenvalues of its companion matrix; and the closed-form
    stability limit T k < 2 (1 - a) on both sides."""
    for rate, derivative, period in [(10.0, 0.0, 0.01), (8.3, 0.0, 0.25), (191.0, 0.3, 0.004), (50.0, 1.2, 0.01)]:
        step = np.array([[1.0 - period * rate - derivative, derivative], [1.0, 0.0]])
        assert sampled_growth(rate, derivative, period) == pytest.approx(max(abs(np.linalg.eigvals(step))), rel=1e-12)
    for derivative in (0.0, 0.4):
        limit = 2.0 * (1.0 - derivative) / 10.0
        assert sampled_growth(10.0, derivative, 0.999 * limit) < 1.0 < sampled_growth(10.0, derivative, 1.001 * limit)


def true_robot_scales(scenario) -> tuple[float, float]:
    """How much faster the nominal model's torques act on the true robot, per channel (equal wheel geometry)."""
    nominal, true = scenario.robot.params(), scenario.plant_params()
    return (
        nominal.effective_mass / true.effective_mass,
        nominal.effective_inertia_axle / true.effective_inertia_axle,
    )


def test_the_inner_loops_rates_on_the_true_robot():
    """Computed torque: k = (K_c + g) m_hat / m per channel, g the outer law's share through nu_c_dot (Kanayama's
    K_x, and v_r K_theta at the circle's 0.15 m/s). The wheel PD: its bandwidth formula (model.md §2.6) on the true
    robot, plus g weighted by K_D / K_P."""
    scenario = ddtrack.load_scenario(BURGER, controller="backstepping")
    scales = true_robot_scales(scenario)
    kx, _, ktheta = scenario.controller.gains
    v, w = inner_loop_channels(scenario)
    assert (v.derivative, w.derivative, v.layer, w.layer) == (0.0, 0.0, 0.0, 0.0)
    assert (v.feedback, w.feedback) == pytest.approx((scales[0] * kx, scales[1] * 0.15 * ktheta), rel=1e-12)
    assert v.rate == pytest.approx(scales[0] * (10.0 + kx), rel=1e-12)
    assert w.rate == pytest.approx(scales[1] * (10.0 + 0.15 * ktheta), rel=1e-12)

    pd = ddtrack.load_scenario(
        SCENARIOS / "paper_line.toml", overrides=['controller.inner="pd"', "controller.kd=0.001"]
    )
    bandwidth = pd.controller.inner_bandwidth(pd.plant_params())
    kx, _, ktheta = pd.controller.gains
    outer = (kx, pd.trajectory.speed * ktheta)
    for channel, k, g in zip(inner_loop_channels(pd), bandwidth, outer, strict=True):
        a = k * 0.001 / 0.125
        assert channel.derivative == pytest.approx(a, rel=1e-12)
        assert channel.rate == pytest.approx(k + a * g, rel=1e-12)


@pytest.mark.parametrize("controller", ["backstepping", "ltv_lqr"])
def test_the_outer_laws_share_is_the_jacobian_of_its_command_rate(controller):
    """The share each outer law declares (Kanayama's (K_x, v_r K_theta) by hand, the LQR's from its gain) equals
    minus the derivative of the nu_c_dot it computes with respect to the measured velocity, taken by autodiff on
    the built law at a point of the reference (zero error), divided by the true-robot scale."""
    scenario = ddtrack.load_scenario(BURGER, controller=controller)
    period = scenario.simulation.control_period
    law = scenario.controller.build(scenario.robot.params(), period, jax.random.key(0))
    ref = scenario.trajectory.build()(jnp.asarray(20.0))  # a point of the circle, at its 0.15 m/s

    def command_rate(nu):
        y = jnp.stack([ref.x, ref.y, ref.theta, nu[0], nu[1]])
        command, _, _ = law.outer.command(jnp.asarray(0.0), y, ref, law.outer.init(y, ref, jax.random.key(0)))
        return command.nu_c_dot

    jacobian = np.asarray(jax.jacfwd(command_rate)(jnp.stack([ref.v, ref.omega])))
    scales = true_robot_scales(scenario)
    shares = [c.feedback / s for c, s in zip(inner_loop_channels(scenario), scales, strict=True)]
    np.testing.assert_allclose(-np.diag(jacobian), shares, rtol=1e-9)
    np.testing.assert_allclose(jacobian[[0, 1], [1, 0]], 0.0, atol=1e-9)  # nothing crosses channels at zero error


def at_period(period: float) -> list[str]:
    """The Burger's run at ``period`` for :data:`PERIODS` periods, metrics over all of it."""
    length = PERIODS * period
    return [
        f"simulation.control_period={period!r}",
        f"simulation.duration={length!r}",
        f"simulation.metric_window=[0, {length!r}]",
    ]


def ringing(controller: str, overrides: list[str], period: float) -> float:
    """The run's torque change per period over its last 100 periods (median, N m), after 200 to settle; inf for
    a run that failed. A held loop that is stable settles to 0; past its limit the torque flips sign every period."""
    scenario = ddtrack.load_scenario(BURGER, overrides=[*at_period(period), *overrides], controller=controller)
    result = ddtrack.run(scenario, seed=0)
    if result.status_name != "ok":
        return float("inf")
    torques = np.asarray(result.control)[-100:]
    return float(np.median(np.abs(np.diff(torques, axis=0))))


def onset(controller: str) -> float:
    """The shortest control period at which the analysis finds the inner loop unstable (bisection on the check,
    to 1e-9 s)."""
    low, high = 0.01, 1.0
    for _ in range(30):
        middle = (low + high) / 2.0
        scenario = ddtrack.load_scenario(BURGER, overrides=at_period(middle), controller=controller)
        low, high = (middle, high) if not check_sampled_inner_loop(scenario) else (low, middle)
    return high


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["backstepping", "ltv_lqr", "adaptive_backstepping"])
def test_the_predicted_onset_is_where_runs_start_to_ring(controller):
    """5 % below the period the analysis calls unstable the run settles (torque steps under 1e-6 N m); 5 % above
    it the torque rings (steps over 1e-3 N m) or the run fails. Without the outer law's share the onsets would
    be 0.24 s for all three; they are 0.211 s (backstepping), 0.153 s (the LQR, whose K_00 at this period is
    5.7 1/s) and 0.178 s (the adaptive law, its estimates at the top of their range)."""
    limit = onset(controller)
    assert limit < 0.22
    assert ringing(controller, [], 0.95 * limit) < 1e-6
    assert ringing(controller, [], 1.05 * limit) > 1e-3


def test_a_control_period_that_makes_the_inner_loop_unstable_is_named(tmp_path, cli):
    """The Burger's computed-torque loop is stable below T_c = 0.211 s (its omega channel: K_c = 10 1/s plus the
    outer law's 2.25 1/s, 22.5 % slower on the true robot). At 0.25 s the run diverges, and the run, its remedy,
    metrics.json and the report name the control period and K_c, not the Kanayama gains; at 0.25 s with the
    advised K_c it tracks."""
    short = ["simulation.duration=5", "simulation.metric_window=[0, 5]"]
    stable = ddtrack.load_scenario(
        BURGER, overrides=[*short, "simulation.control_period=0.2"], controller="backstepping"
    )
    assert check(stable) == []
    scenario = ddtrack.load_scenario(
        BURGER, overrides=[*short, "simulation.control_period=0.25"], controller="backstepping"
    )
    scales = true_robot_scales(scenario)
    outer = (1.0, 0.15 * 15.0)  # K_x, v_r K_theta
    assert 2.0 / (scales[1] * (10.0 + outer[1])) == pytest.approx(0.2107, abs=1e-4)  # the omega channel's limit
    advised = [f"{1.0 / (0.25 * c) - g:.3g}" for c, g in zip(scales, outer, strict=True)]  # half of each limit
    assert advised == ["3.8", "2.91"]
    (warning,) = check(scenario)
    assert warning["code"] == "sampled_inner_loop_unstable"
    assert "simulation.control_period to 0.105 s or less" in warning["message"]
    assert f"controller.kc to [{advised[0]}, {advised[1]}] 1/s or less" in warning["message"]
    assert "its v channel" in warning["message"] and "its omega channel" in warning["message"]

    def run(out, *overrides: str):
        sets = [a for o in [*short, "simulation.control_period=0.25", *overrides] for a in ("--set", o)]
        return cli("run", BURGER, "--controller", "backstepping", *sets, "--out", out)

    code, _, stderr = run(tmp_path / "unstable")
    assert code == 1 and stderr == f"run diverged at t = 2.50 s: {warning['message']}\n", stderr
    assert json.loads((tmp_path / "unstable" / "metrics.json").read_text())["warnings"] == [warning]
    code, _, _ = cli("report", tmp_path / "unstable")
    page = html.unescape((tmp_path / "unstable" / "report.html").read_text())
    assert code == 0 and f"To try: {warning['message']}." in page
    code, _, stderr = run(tmp_path / "advised", f"controller.kc=[{advised[0]}, {advised[1]}]")  # the same program
    assert code == 0 and stderr == "", stderr


def test_a_sliding_mode_layer_that_the_period_makes_chatter_is_named():
    """The shipped 20 Hz Burger under sliding mode: K_s / phi = 50 1/s inside the boundary layer on both channels,
    so T k is about 2.5 there, past the limit of 2. It ran "ok", its torque flipping sign every period; loading
    warns, and the advised layer (T k = 1 inside it, computed here by hand) settles."""
    scenario = ddtrack.load_scenario(BURGER, controller="sliding_mode_backstepping")
    period = scenario.simulation.control_period
    (warning,) = check_sampled_inner_loop(scenario)
    assert warning["code"] == "sampled_inner_loop_chatters"
    scales = true_robot_scales(scenario)
    outer = (1.0, 0.15 * 15.0)
    layer = [
        c * ks / (1.0 / period - c * (10.0 + g))
        for c, ks, g in zip(scales, scenario.controller.switching_gain, outer, strict=True)
    ]
    advised = f"[{layer[0]:.3g}, {layer[1]:.3g}]"
    assert f"controller.boundary_layer to {advised} or wider" in warning["message"]
    assert ringing("sliding_mode_backstepping", [], period) > 1e-2
    widened = [f"controller.boundary_layer={advised}"]
    assert (
        check_sampled_inner_loop(ddtrack.load_scenario(BURGER, overrides=widened, controller=scenario.controller.kind))
        == []
    )
    assert ringing("sliding_mode_backstepping", widened, period) < 1e-9


def test_the_remedy_names_the_unstable_inner_loop_only_for_a_failed_run():
    warning = {"code": "sampled_inner_loop_unstable", "message": "the inner loop is unstable"}
    assert remedy("diverged", {"saturated": np.zeros(100)}, [warning]) == "the inner loop is unstable"
    assert remedy("non_finite", {}, [{"code": "reference_near_limit", "message": "x"}, warning]) == warning["message"]
    assert remedy("ok", {}, [warning]) == ""


@pytest.mark.parametrize(
    ("overrides", "field"),
    [
        (["controller.kp=2", "simulation.control_period=0.02", "simulation.substeps=20"], "kp"),
        (["controller.kd=0.03"], "kd"),
    ],
)
def test_the_wheel_pds_advice_puts_its_binding_channel_at_half_the_limit(overrides, field):
    """The wheel PD on the paper's line: too stiff a K_P for a 50 Hz loop is advised down to T k = 1 - a on its
    faster channel; a K_D whose backward difference alone destabilises a channel (a >= 1) is advised down to
    a = 1/2. Loading the advised value warns no more."""
    import re

    base = ['controller.inner="pd"', *overrides]
    scenario = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=base)
    (warning,) = check_sampled_inner_loop(scenario)
    unit = "N m s/rad" if field == "kp" else "N m s\\^2/rad"
    advised = float(re.search(rf"controller\.{field} to ([0-9.e+-]+) {unit} or less", warning["message"]).group(1))
    fixed = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=[*base, f"controller.{field}={advised!r}"])
    assert check_sampled_inner_loop(fixed) == []
    period = fixed.simulation.control_period
    channels = inner_loop_channels(fixed)
    if field == "kp":
        binding = max(period * c.rate / (1.0 - c.derivative) for c in channels)
    else:
        binding = 2.0 * max(c.derivative for c in channels)
    assert binding == pytest.approx(1.0, abs=5e-3)  # the advice is printed to 3 significant digits
