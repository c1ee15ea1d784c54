"""Baselines C: adaptive backstepping (computed torque on online estimates of m, I_C, b_w) and MPPI over
wheel torques: their defining properties, then each as a scenario controller."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack.controllers import Backstepping, Cascade, VelocityCommand
from ddtrack.controllers.baselines import MPPI, AdaptiveComputedTorque, regressor
from ddtrack.model import RobotParams, reduced_input, reduced_mass, wheel_friction
from ddtrack.scenario import AdaptiveBacksteppingConfig, MPPIConfig, build

KINDS = ("adaptive_backstepping", "mppi")


def _scenario(name: str, kind: str, duration: int, *overrides: str):
    window = f"simulation.metric_window=[{duration // 2}, {duration}]"
    return ddtrack.load_scenario(
        SCENARIOS / name, controller=kind, overrides=[f"simulation.duration={duration}", window, *overrides]
    )


def _mean_error(result, scenario) -> float:
    start, end = scenario.simulation.window
    t = np.asarray(result.t)
    e_tr = np.hypot(np.asarray(result.error[:, 0]), np.asarray(result.error[:, 1]))
    return float(np.mean(e_tr[(t >= start - 1e-9) & (t <= end + 1e-9)]))


@functools.cache
def _circle_run(kind: str):
    """The circle, 10 s, seed 0: shared by the tracking and the batch tests (one compile)."""
    scenario = _scenario("circle.toml", kind, 10)
    return scenario, ddtrack.run(scenario, seed=0)


# --- adaptive backstepping --------------------------------------------------------------------------


def test_regressor_is_the_reduced_model():
    rng = np.random.default_rng(5)
    for _ in range(50):
        params = RobotParams(
            mass=rng.uniform(1, 50),
            inertia=rng.uniform(0.05, 5),
            com_offset=rng.uniform(-0.3, 0.3),
            wheel_radius=rng.uniform(0.02, 0.3),
            half_axle=rng.uniform(0.1, 1.0),
            viscous_friction=rng.uniform(0, 0.05),
        )
        nu, nu_c, nu_c_dot = (jnp.asarray(rng.uniform(-2, 2, 2)) for _ in range(3))
        md_omega = params.mass * params.com_offset * nu[1]
        coriolis = jnp.array([[0.0, -md_omega], [md_omega, 0.0]])  # V_bar(nu) (SPEC 1.3), applied to nu_c
        expected = (
            reduced_mass(params) @ nu_c_dot
            + coriolis @ nu_c
            + reduced_input(params)
            @ wheel_friction(
                params,
                jnp.array([nu_c[0] + params.half_axle * nu_c[1], nu_c[0] - params.half_axle * nu_c[1]])
                / params.wheel_radius,
            )
        )
        p = jnp.array([params.mass, params.inertia, params.viscous_friction])
        # |terms| <= ~1e4 (b_w / R^2): a few ulps of that
        np.testing.assert_allclose(regressor(params, nu, nu_c, nu_c_dot) @ p, expected, rtol=1e-12, atol=1e-10)


def test_update_follows_the_lyapunov_sign_and_stops_at_the_bounds():
    """p_hat_dot = -Gamma Y^T e: a robot slower than commanded while accelerating (heavier than believed)
    raises m_hat; the projection holds the estimate at its bound; a saturated period does not adapt."""
    nominal = RobotParams()
    law = AdaptiveComputedTorque(nominal, gamma=(500.0, 5.0, 0.0), lower=(5.0, 0.28, 0.0), upper=(10.5, 1.12, 0.05))
    y = jnp.array([0.0, 0.0, 0.0, 0.3, 0.0])
    command = VelocityCommand(jnp.array([0.4, 0.0]), jnp.array([0.5, 0.0]), jnp.zeros(2), jnp.asarray(0.0))
    p0 = law.init(y, None, None)
    np.testing.assert_array_equal(p0, [10.0, 0.56, 0.0])  # starts at the nominal model
    _, saturated, p1 = law.torque(y, command, p0)
    # Y_11 e_v = 0.5 m/s^2 * (-0.1 m/s): m_hat grows by T_c * 500 * 0.05 = 0.25 kg
    assert float(saturated) == 0.0 and float(p1[0]) == pytest.approx(10.25, rel=1e-12)
    _, _, p2 = law.torque(y, command, p1)
    assert float(p2[0]) == 10.5  # projected onto the upper bound
    stalled = y.at[3].set(-20.0)  # a torque far above max_torque
    _, saturated, p3 = law.torque(stalled, command, p0)
    assert float(saturated) == 1.0 and np.array_equal(p3, p0)


# figure-eight 6 m wide in 20 s (persistent excitation: |v_dot_r| and |omega_dot_r| keep changing), from rest at
# the reference pose, true m and I_C +30 %, the same centre-of-mass offset, no friction, disturbance or noise
EXCITED = (
    "plant.mass=13.0",
    "plant.inertia=0.728",
    "plant.com_offset=0.05",
    "plant.viscous_friction=0.0",
    "plant.coulomb_friction=0.0",
    "disturbance.mean=[0, 0]",
    "disturbance.std=[0, 0]",
    "noise.position_std=0",
    "noise.heading_std=0",
    "trajectory.period=20",
)


def test_adaptive_estimates_converge_under_persistent_excitation():
    adaptive = _scenario("figure_eight.toml", "adaptive_backstepping", 60, *EXCITED)
    result = ddtrack.run(adaptive)
    assert result.status_name == "ok"
    m_hat, inertia_hat = np.asarray(result.logs["m_hat"]), np.asarray(result.logs["inertia_hat"])
    assert (m_hat[0], inertia_hat[0]) == (10.0, 0.56)  # the nominal model's, 30 % off
    # measured at 60 s: 12.974 kg (-0.2 %) and 0.7307 kg m^2 (+0.4 %); the rest is the zero-order hold's bias
    assert abs(m_hat[-1] / 13.0 - 1.0) < 0.01
    assert abs(inertia_hat[-1] / 0.728 - 1.0) < 0.01
    # measured over [30, 60] s: 1.1e-4 m, against 4.1e-3 m for backstepping on the nominal (wrong) model
    fixed = _scenario("figure_eight.toml", "backstepping", 60, *EXCITED)
    assert _mean_error(result, adaptive) < 0.1 * _mean_error(ddtrack.run(fixed), fixed)


# --- MPPI ---------------------------------------------------------------------------------------------


@jax.jit
def _plan_costs(law: MPPI, t, y, start, keys):
    """The cost of the plan one MPPI update makes from ``start``, for each key."""
    return jax.vmap(lambda key: law.sequence_cost(t, y, law.plan(t, y, start, key)[0]))(keys)


def test_mppi_plan_improves_with_more_samples():
    """The cost of one MPPI update's plan, from a fixed state 0.3 m and 0.2 rad off the line, averaged over
    eight keys, does not increase with the number of samples (measured 332, 306, 282 for K = 16, 64, 256)."""
    scenario = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", controller="mppi")
    mppi = build(scenario).controller
    t = 5.0
    ref = scenario.trajectory.build()(t)
    normal = np.array([-np.sin(ref.theta), np.cos(ref.theta)])
    y = jnp.array([*(np.array([ref.x, ref.y]) + 0.3 * normal), ref.theta + 0.2, 0.3, 0.0])
    start = jnp.zeros((mppi.horizon, 2))
    keys = jax.random.split(jax.random.PRNGKey(0), 8)
    before = float(mppi.sequence_cost(t, y, start))
    costs = []
    for samples in (16, 64, 256):
        costs.append(float(np.mean(_plan_costs(dataclasses.replace(mppi, samples=samples), t, y, start, keys))))
    assert before > costs[0] >= costs[1] >= costs[2]  # measured 424 before
    assert costs[2] < 0.9 * costs[0]


def test_mppi_is_deterministic_per_seed_and_draws_from_its_key():
    scenario, result = _circle_run("mppi")
    again = ddtrack.run(scenario, seed=0)
    np.testing.assert_array_equal(again.control, result.control)
    other = ddtrack.run(scenario, seed=1)  # the circle has no random disturbance: only the controller key changes
    assert np.max(np.abs(np.asarray(other.control) - np.asarray(result.control))) > 1e-3


# --- as scenario controllers ----------------------------------------------------------------------------

# e_tr_mean [m] on paper_line over [10, 20] s and on the circle over [5, 10] s (backstepping: 0.046 on both).
# Adaptive: the viscous-friction estimate absorbs the unmodelled drag (about 0.0017 m over the paper's [20, 40]).
# MPPI: no integral action, so the drag leaves an offset; its sampling makes the error wander by ~1 cm.
MEASURED = {"adaptive_backstepping": (0.0043, 0.0018), "mppi": (0.0258, 0.0290)}


@pytest.mark.parametrize("kind", KINDS)
def test_tracks_the_paper_line_and_a_circle(kind):
    line = _scenario("paper_line.toml", kind, 20)
    assert line.controller.kind == kind  # selected by name over the file's backstepping
    circle, circle_result = _circle_run(kind)
    for scenario, result, measured in (
        (line, ddtrack.run(line), MEASURED[kind][0]),
        (circle, circle_result, MEASURED[kind][1]),
    ):
        assert result.status_name == "ok"
        assert _mean_error(result, scenario) < 1.5 * measured  # below backstepping's 0.046 m


def test_selectable_by_name():
    for kind, config, law in (
        ("adaptive_backstepping", AdaptiveBacksteppingConfig, Cascade),
        ("mppi", MPPIConfig, MPPI),
    ):
        scenario = ddtrack.load_scenario(SCENARIOS / "paper_line.toml", controller=kind)
        assert isinstance(scenario.controller, config)
        assert isinstance(build(scenario).controller, law)
    cascade = build(ddtrack.load_scenario(SCENARIOS / "paper_line.toml", controller="adaptive_backstepping")).controller
    assert isinstance(cascade.outer, Backstepping) and isinstance(cascade.inner, AdaptiveComputedTorque)
    # the estimates are bounded around the nominal model, which must lie inside the bounds
    with pytest.raises(ddtrack.ConfigError, match="controller.estimate_range"):
        ddtrack.load_scenario(
            SCENARIOS / "paper_line.toml",
            controller="adaptive_backstepping",
            overrides=["controller.estimate_range=[1.2, 2.0]"],
        )
