"""NN-adaptive backstepping: the gain law and the whole controller. SPEC 6, items 14-20 and 24, and
SPEC 3.1-3.8.

The closed-loop tests share one compiled simulator per controller structure: every paper-line run
below is the full 40 s scenario (a run costs well under a second once compiled), and runs that only
change the gain law reuse one identification through ``prepare(..., identification=...)``.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import central_difference, simulate_unbatched
from jax.flatten_util import ravel_pytree

import ddtrack
from ddtrack.controllers import (
    AdaptiveMemory,
    ComputedTorque,
    Emulator,
    NNAdaptiveBackstepping,
    cost_gradient,
    emulator_scales,
    error_jacobian_body,
    gain_sensitivity,
    init_mlp,
    kanayama_command,
    one_step_coefficient,
)
from ddtrack.controllers.nn import backprop, input_jacobian, momentum_step, predict, sample_loss
from ddtrack.geometry import body_increment, posture_error, rotation
from ddtrack.identification import identify
from ddtrack.model import RobotParams
from ddtrack.runner import prepare, run_setup
from ddtrack.trajectories import Reference

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
LINE = SCENARIOS / "paper_line.toml"
NN = "controller.kind=nn_adaptive_backstepping"
WINDOW = (20.0, 40.0)  # the paper line's steady-state metric window (SPEC 4.4)
TC = 0.01
# the columns that backstepping and the NN-adaptive controller both produce
SHARED = (
    "t",
    "x",
    "y",
    "theta",
    "v",
    "omega",
    "x_ref",
    "y_ref",
    "theta_ref",
    "v_ref",
    "omega_ref",
    "e_x",
    "e_y",
    "e_theta",
    "e_tr",
    "v_cmd",
    "omega_cmd",
    "tau_r",
    "tau_l",
    "kx",
    "ky",
    "ktheta",
    "saturated",
)
GAINS = ("kx", "ky", "ktheta")


def window_mean(columns: dict, window=WINDOW) -> float:
    t = columns["t"]
    inside = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    return float(np.mean(columns["e_tr"][inside]))


def run_line(*overrides: str, identification=None):
    """The paper line with the NN-adaptive controller and ``overrides``; returns (columns, setup, result)."""
    scenario = ddtrack.load_scenario(LINE, overrides=[NN, *overrides])
    setup, draws = prepare(scenario, identification=identification)
    result = run_setup(scenario, setup, draws)
    return ddtrack.timeseries(result), setup, result


@pytest.fixture(scope="module")
def line():
    """Backstepping and the default NN-adaptive controller on the paper line, and the identification."""
    bs = ddtrack.run(ddtrack.load_scenario(LINE))
    assert bs.status_name == "ok"
    nn, setup, result = run_line()
    assert result.status_name == "ok"
    return {"bs": ddtrack.timeseries(bs), "nn": nn, "identification": setup.identification}


def random_reference(rng) -> Reference:
    return Reference(
        *(
            jnp.asarray(v)
            for v in (
                rng.uniform(-5, 5),
                rng.uniform(-5, 5),
                rng.uniform(-3, 3),
                rng.uniform(0.1, 1.5),
                rng.uniform(-1, 1),
                rng.uniform(-1, 1),
                rng.uniform(-1, 1),
            )
        )
    )


def random_error(rng) -> np.ndarray:
    return np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-1.5, 1.5)])


def body_basis(theta) -> jnp.ndarray:
    """S(theta) = [[c, 0], [s, 0], [0, 1]]: the first and last columns of R_3(theta)."""
    return rotation(jnp.asarray(theta))[:, jnp.array([0, 2])]


# --- item 14: Lambda = 0 is backstepping --------------------------------------------------------------


@pytest.mark.parametrize("identification", [False, True], ids=["untrained", "identified"])
def test_zero_rates_reproduce_backstepping_bit_for_bit(line, identification):
    """The law itself, on the unbatched simulator. Through ``ddtrack.run`` (a batch's row, tests/test_determinism.py)
    the two laws' programs are fused differently and LLVM contracts different multiply-adds into FMAs: there they
    agree to ~4e-14 (measured), which the second check bounds."""
    overrides = ["controller.rates=[0, 0, 0]", f"controller.identification={str(identification).lower()}"]
    scenario = ddtrack.load_scenario(LINE, overrides=[NN, *overrides])
    setup, draws = prepare(scenario, identification=line["identification"] if identification else None)
    assert (setup.identification is not None) == identification
    nn = ddtrack.timeseries(simulate_unbatched(scenario, setup, draws))
    backstepping = ddtrack.load_scenario(LINE)
    bs = ddtrack.timeseries(simulate_unbatched(backstepping, *prepare(backstepping)))
    for name in SHARED:
        assert np.array_equal(nn[name], bs[name]), name
    batched = run_line(*overrides, identification=line["identification"] if identification else None)[0]
    for name in SHARED:
        np.testing.assert_allclose(batched[name], line["bs"][name], rtol=0, atol=1e-12, err_msg=name)
    # the emulator did learn online meanwhile (so the equality is not from a dead branch)...
    assert np.any(nn["emulator_loss"] > 0)
    # ...and the gate opened, so the update ran with a zero rate rather than being skipped
    assert np.any(nn["gate"] == 1.0)


# --- item 15: Phi ----------------------------------------------------------------------------------------


def test_gain_sensitivity_matches_finite_differences_of_the_law():
    rng = np.random.default_rng(15)
    for _ in range(30):
        ref, error = random_reference(rng), random_error(rng)
        gains = rng.uniform([0.5, 10.0, 2.0], [5.0, 200.0, 40.0])
        phi = np.asarray(gain_sensitivity(jnp.asarray(error), ref))
        fd = central_difference(
            lambda a, error=error, ref=ref: kanayama_command(jnp.asarray(error), ref, jnp.asarray(a)), gains, 1e-6
        )
        # the law is linear in the gains: central differences are exact up to rounding ~eps |nu_c| / h ~ 1e-9
        np.testing.assert_allclose(phi, fd, rtol=1e-7, atol=1e-7 * np.max(np.abs(phi)))
        v_r = float(ref.v)
        # d omega_c / d Ky = v_r e_y (the paper's eq. 24 has v_r e_x); e_x != e_y here, so the typo would fail
        assert abs(error[0] - error[1]) > 1e-6
        assert phi[1, 1] == pytest.approx(v_r * error[1], rel=1e-15)
        assert phi[0, 0] == error[0] and phi[1, 2] == pytest.approx(v_r * np.sin(error[2]), rel=1e-15)
        assert phi[0, 1] == phi[0, 2] == phi[1, 0] == 0.0


# --- item 16: D = d e_p / d q ---------------------------------------------------------------------------


def test_error_jacobian_exact_form_and_identities():
    rng = np.random.default_rng(16)
    for _ in range(30):
        q = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-3, 3)])
        q_r = q + np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1.5, 1.5)])  # no wrap nearby
        error = np.asarray(posture_error(*q, *q_r))
        d = central_difference(lambda p, q_r=q_r: posture_error(*p, *q_r), q, 1e-6)
        c, s = np.cos(q[2]), np.sin(q[2])
        exact = np.array([[-c, -s, error[1]], [s, -c, -error[0]], [0.0, 0.0, -1.0]])
        # h = 1e-6: truncation ~h^2 |q_r - q| ~ 1e-12, rounding ~eps |q| / h ~ 1e-9
        np.testing.assert_allclose(d, exact, rtol=0, atol=1e-7)
        r3 = np.asarray(rotation(jnp.asarray(q[2])))
        # D R_3(theta) = D_b, and the package's D_b equals it; the D above carries the 1e-9 FD error
        np.testing.assert_allclose(d @ r3, error_jacobian_body(jnp.asarray(error), True), rtol=0, atol=1e-7)
        np.testing.assert_allclose(exact @ r3, error_jacobian_body(jnp.asarray(error), True), rtol=0, atol=1e-14)
        s_mat = np.asarray(body_basis(q[2]))
        np.testing.assert_allclose(d @ s_mat, [[-1.0, error[1]], [0.0, -error[0]], [0.0, -1.0]], rtol=0, atol=1e-7)
    # the paper's approximation D ~ -T_e gives D_b = -I
    np.testing.assert_array_equal(error_jacobian_body(jnp.asarray([0.3, -0.2, 0.1]), False), -np.eye(3))


# --- item 17: the closed form of SPEC 3.5 -------------------------------------------------------------------


def test_cost_gradient_equals_the_closed_form():
    rng = np.random.default_rng(17)
    for _ in range(50):
        ref, e = random_reference(rng), random_error(rng)
        e_x, e_y, e_th = e
        gamma = rng.uniform(0.1, 60.0, 3)
        g_v, g_w = rng.uniform(0.1, 2.0, 2)
        jb = jnp.asarray([[g_v, 0.0], [0.0, 0.0], [0.0, g_w]])
        v_r = float(ref.v)
        for exact in (True, False):
            psi = ((gamma[1] - gamma[0]) * e_x * e_y if exact else 0.0) + gamma[2] * e_th
            closed = [-gamma[0] * g_v * e_x**2, -g_w * v_r * e_y * psi, -g_w * v_r * np.sin(e_th) * psi]
            grad = np.asarray(cost_gradient(jnp.asarray(e), ref, jnp.asarray(gamma), jb, exact))
            # the same products in another order: rounding of terms of size <= ~100
            np.testing.assert_allclose(grad, closed, rtol=1e-12, atol=1e-12)
        # with -T_e, gamma_y drops out completely (exactly: it only ever multiplies a zero Jacobian row)
        other = gamma.copy()
        other[1] = 1e3
        paper = cost_gradient(jnp.asarray(e), ref, jnp.asarray(gamma), jb, False)
        assert np.array_equal(paper, cost_gradient(jnp.asarray(e), ref, jnp.asarray(other), jb, False))
        # while the exact D does depend on it (whenever e_x e_y != 0)
        exact_grad = cost_gradient(jnp.asarray(e), ref, jnp.asarray(gamma), jb, True)
        assert not np.allclose(exact_grad, cost_gradient(jnp.asarray(e), ref, jnp.asarray(other), jb, True))


# --- item 18: exact one-step gradient check ---------------------------------------------------------------


def _one_step_case(rng):
    q = np.array([rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-3, 3)])
    q_r = q + np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-0.4, 0.4)])
    ref = Reference(
        *(jnp.asarray(v) for v in (q_r[0], q_r[1], q_r[2], rng.uniform(0.2, 1.0), rng.uniform(-0.5, 0.5), 0.0, 0.0))
    )
    q_r_next = q_r + TC * np.asarray(body_basis(q_r[2])) @ np.array([float(ref.v), float(ref.omega)])
    gains = rng.uniform([0.5, 20.0, 5.0], [5.0, 100.0, 30.0])
    gamma = np.array([1.0, 50.0, 1.0])
    return q, ref, q_r_next, gains, gamma


def _euler(q, nu_c, model):
    return q + TC * body_basis(q[2]) @ nu_c


def _euler_sensitivity(q, nu_c, model):
    return TC * body_basis(q[2])


def _emulator(q, nu_c, model):
    mlp, scales, nu = model
    return q + rotation(q[2]) @ predict(mlp, scales, jnp.concatenate([nu_c, nu]))


def _emulator_sensitivity(q, nu_c, model):
    mlp, scales, nu = model
    return rotation(q[2]) @ input_jacobian(mlp, scales, jnp.concatenate([nu_c, nu]))[:, :2]


@partial(jax.jit, static_argnums=0)
def _one_step_cost(step, alpha, q, ref, q_r_next, gamma, model):
    """J+ = e_p(q+)^T Gamma e_p(q+) / 2 with q+ = step(q, nu_c(alpha)) and nu_c from the error at q."""
    error = posture_error(q[0], q[1], q[2], ref.x, ref.y, ref.theta)
    q_next = step(q, kanayama_command(error, ref, alpha), model)
    e_next = posture_error(q_next[0], q_next[1], q_next[2], q_r_next[0], q_r_next[1], q_r_next[2])
    return 0.5 * e_next @ (gamma * e_next)


_one_step_autodiff = jax.jit(jax.grad(_one_step_cost, argnums=1), static_argnums=0)


@partial(jax.jit, static_argnums=(0, 1))
def _one_step_gradient(step, sensitivity, alpha, q, ref, q_r_next, gamma, model):
    """e_p(q+)^T Gamma D(q+) dF/dnu_c Phi(e_p(q)), built from the package's pieces (SPEC 6.18)."""
    error = posture_error(q[0], q[1], q[2], ref.x, ref.y, ref.theta)
    nu_c = kanayama_command(error, ref, alpha)
    q_next = step(q, nu_c, model)
    e_next = posture_error(q_next[0], q_next[1], q_next[2], q_r_next[0], q_r_next[1], q_r_next[2])
    d_next = error_jacobian_body(e_next, True) @ rotation(q_next[2]).T  # D(q+) = D_b R_3(theta+)^T
    return (gamma * e_next) @ d_next @ sensitivity(q, nu_c, model) @ gain_sensitivity(error, ref)


def _check_one_step(step, sensitivity, model, rng, h: float = 1e-6):
    q, ref, q_r_next, gains, gamma = (jax.tree_util.tree_map(jnp.asarray, x) for x in _one_step_case(rng))
    analytic = np.asarray(_one_step_gradient(step, sensitivity, gains, q, ref, q_r_next, gamma, model))
    fd = central_difference(
        lambda a: float(_one_step_cost(step, jnp.asarray(a), q, ref, q_r_next, gamma, model)), np.asarray(gains), h
    )
    # SPEC 6.18: relative 1e-5 (prototype 5.8e-6); scaled by the largest entry so a near-zero one passes
    np.testing.assert_allclose(analytic, fd, rtol=1e-5, atol=1e-5 * np.max(np.abs(analytic)))
    # reverse-mode AD of the same one-step cost: the chain rule is the same, only rounding differs
    auto = np.asarray(_one_step_autodiff(step, gains, q, ref, q_r_next, gamma, model))
    np.testing.assert_allclose(analytic, auto, rtol=1e-10, atol=1e-12 * np.max(np.abs(analytic)))
    assert np.all(np.isfinite(analytic)) and np.max(np.abs(analytic)) > 0


def test_exact_one_step_gradient_euler():
    rng = np.random.default_rng(18)
    for _ in range(20):
        _check_one_step(_euler, _euler_sensitivity, (), rng)


def test_exact_one_step_gradient_emulator():
    """The same check with the emulator as the one-step model, q+ = q + R_3(theta) y(nu_c, nu) (SPEC 6.18)."""
    rng = np.random.default_rng(181)
    scales = emulator_scales(TC, uses_velocity=True)
    k1, k2, k3 = jax.random.split(jax.random.PRNGKey(18), 3)
    mlp = init_mlp(k1, 4, 20, 3)
    mlp = mlp.__class__(mlp.w1, 0.3 * jax.random.normal(k2, (20,)), mlp.w2, 0.3 * jax.random.normal(k3, (3,)))
    for _ in range(10):
        # the emulator's sensitivity is ~100x below T_c, so |grad| / J+ ~ 1e-5 and h = 1e-6 would leave a
        # rounding error eps J+ / (h |grad|) ~ 1e-4; at h = 1e-4 it is ~1e-6 and the truncation (h^2) ~1e-7
        _check_one_step(_emulator, _emulator_sensitivity, (mlp, scales, jnp.asarray([0.4, 0.1])), rng, h=1e-4)


# --- item 19: sign facts ----------------------------------------------------------------------------------------


def test_only_along_track_error_raises_only_kx():
    rng = np.random.default_rng(19)
    for _ in range(20):
        ref = random_reference(rng)
        e = jnp.asarray([rng.choice([-1, 1]) * rng.uniform(0.01, 0.5), 0.0, 0.0])
        # any plant Jacobian whose direct forward entry is positive (cross terms arbitrary)
        jb = jnp.asarray(rng.uniform(-1.0, 1.0, (3, 2))).at[0, 0].set(rng.uniform(0.1, 2.0))
        for exact in (True, False):
            grad = np.asarray(cost_gradient(e, ref, jnp.asarray([1.0, 50.0, 1.0]), jb, exact))
            assert grad[0] < 0
            assert grad[1] == 0.0 and grad[2] == 0.0


def test_kx_never_decreases_with_the_analytic_jacobian(line):
    nn, _setup, result = run_line('controller.jacobian="analytic"', identification=line["identification"])
    assert result.status_name == "ok"
    assert np.all(np.diff(nn["kx"]) >= 0.0)
    # and it did adapt (not a frozen gain)
    assert nn["kx"][-1] > nn["kx"][0] + 0.5
    # the analytic Jacobian, normalised by c_v, is [[1, 0], [0, 0], [0, c_w / c_v]] = diag-like with c_w = c_v here
    np.testing.assert_array_equal(nn["jacobian_v"], 1.0)
    np.testing.assert_array_equal(nn["jacobian_omega"], 1.0)


# --- item 20: bounds, per-step clip, gate -------------------------------------------------------------------

BOUNDS = {"gain_min": (0.5, 20.0, 5.0), "gain_max": (3.0, 100.0, 30.0), "max_step": (0.05, 5.0, 0.5)}


def _clipped_run(line, freeze_time: float):
    """Rates far above the defaults and narrow bounds, so the per-step clip and the box both bind."""
    overrides = ["controller.rates=[1e5, 1e8, 1e7]", f"controller.freeze_time={freeze_time}"]
    overrides += [f"controller.{k}={list(v)}" for k, v in BOUNDS.items()]
    nn, _setup, result = run_line(*overrides, identification=line["identification"])
    assert result.status_name == "ok"
    return nn


def _expected_gate(nn, freeze_time: float) -> np.ndarray:
    """Open iff k > 0, e_tr < e_gate (0.5 m), no saturation at k-1, t >= freeze_time (SPEC 3.6, 3.8)."""
    previous_saturated = np.r_[1.0, nn["saturated"][:-1]]
    k = np.arange(nn["t"].size)
    return (k > 0) & (nn["e_tr"] < 0.5) & (previous_saturated == 0.0) & (nn["t"] >= freeze_time - 1e-9)


@pytest.mark.parametrize("freeze_time", [3.0, 8.0])
def test_gains_bounded_steps_clipped_and_frozen_while_the_gate_is_closed(line, freeze_time):
    nn = _clipped_run(line, freeze_time)
    gate = nn["gate"]
    assert set(np.unique(gate)) <= {0.0, 1.0}
    for i, name in enumerate(GAINS):
        gains, step = nn[name], np.diff(nn[name])
        assert np.all(gains >= BOUNDS["gain_min"][i]) and np.all(gains <= BOUNDS["gain_max"][i])
        # (a + s) - a differs from s by one rounding of a (<= 1e-13 for gains <= 100)
        assert np.all(np.abs(step) <= BOUNDS["max_step"][i] + 1e-12)
        # row k logs the gains after the update of period k: no change where the gate was closed
        assert np.all(step[gate[1:] == 0.0] == 0.0), name
        assert gains[0] == (1.0, 55.0, 15.0)[i]
        if freeze_time == 3.0:  # the clip and both bounds bind in this run (else the checks above are idle)
            assert np.sum(np.isclose(np.abs(step), BOUNDS["max_step"][i], rtol=1e-9)) >= 10, name
            assert np.isclose(gains.max(), BOUNDS["gain_max"][i], rtol=1e-12), name
    if freeze_time == 3.0:
        assert np.isclose(nn["ky"].min(), 20.0) and np.isclose(nn["ktheta"].min(), 5.0)
    # the gate is exactly the stated condition
    expected = _expected_gate(nn, freeze_time)
    np.testing.assert_array_equal(gate == 1.0, expected)
    # and each closing reason occurs in these runs (large error, saturation at k-1, the freeze)
    previous_saturated = np.r_[1.0, nn["saturated"][:-1]]
    t, small = nn["t"], nn["e_tr"] < 0.5
    if freeze_time == 3.0:
        assert np.any(~small & (t >= 3.0) & (previous_saturated == 0.0))
        assert np.any(small & (t >= 3.0) & (previous_saturated == 1.0))
    else:
        assert np.any(small & (t < 8.0) & (t > 0) & (previous_saturated == 0.0))
        assert np.all(gate[t < 8.0 - 1e-9] == 0.0) and np.any(gate[t >= 8.0] == 1.0)


# --- item 24: identification ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def identified():
    """The E1 emulator identified on the nominal plant and on the mismatched one (same seed)."""
    emulator = Emulator(init_mlp(jax.random.PRNGKey(1), 4, 20, 3), emulator_scales(TC, uses_velocity=True), True)
    inner = ComputedTorque(RobotParams(), kc=(10.0, 10.0))  # the nominal computed-torque inner loop, K_c = 10
    plants = {"nominal": RobotParams(), "mismatch": RobotParams(mass=12.0, inertia=0.7, com_offset=0.08)}
    return {name: identify(plant, inner, emulator, jax.random.PRNGKey(24)) for name, plant in plants.items()}


TYPICAL_INPUTS = [(0.5, 0.0, 0.5, 0.0), (0.5, 0.5, 0.5, 0.5), (0.3, -0.4, 0.3, -0.4)]


def test_identification_prediction_error(identified):
    for result in identified.values():
        assert result.samples == 5999
        nmse = np.asarray(result.nmse)
        # SPEC 6.24: < 1e-3 for the forward and yaw channels (prototype 2e-5 and 4e-5)
        assert nmse[0] < 1e-3 and nmse[2] < 1e-3
        # the lateral increment is second order and noisier; SPEC 3.7 quotes 4e-3
        assert nmse[1] < 2e-2
        losses = np.asarray(result.epoch_loss)
        assert losses.shape == (100,) and losses[-1] < 0.1 * losses[0]


@pytest.mark.parametrize("z", TYPICAL_INPUTS, ids=["straight", "left", "right"])
def test_identified_jacobian_matches_the_one_step_coefficient(identified, z):
    nominal, true_plant = RobotParams(), RobotParams(mass=12.0, inertia=0.7, com_offset=0.08)
    c_nom = float(one_step_coefficient(jnp.asarray(10.0), TC))
    c_v = float(one_step_coefficient(jnp.asarray(10.0 * nominal.mass / true_plant.mass), TC))
    c_w = float(one_step_coefficient(jnp.asarray(10.0 * nominal.inertia_axle / true_plant.inertia_axle), TC))
    jac = {
        name: np.asarray(input_jacobian(r.emulator.mlp, r.emulator.scales, jnp.asarray(z)))
        for name, r in identified.items()
    }
    # SPEC 6.24: within 25 % of c(k_c), resp. c(k_c m_hat/m) and c(k_c I_A_hat/I_A)
    assert jac["nominal"][0, 0] == pytest.approx(c_nom, rel=0.25)
    assert jac["nominal"][2, 1] == pytest.approx(c_nom, rel=0.25)
    assert jac["mismatch"][0, 0] == pytest.approx(c_v, rel=0.25)
    assert jac["mismatch"][2, 1] == pytest.approx(c_w, rel=0.25)
    # the network sees the mismatch: the heavier robot's sensitivities are smaller (predicted 0.84, 0.75 of nominal)
    assert jac["mismatch"][0, 0] < jac["nominal"][0, 0] and jac["mismatch"][2, 1] < jac["nominal"][2, 1]
    # cross terms are small next to the direct ones (v_c barely turns the robot, omega_c barely moves it)
    assert abs(jac["nominal"][2, 0]) < 0.1 * c_nom and abs(jac["nominal"][0, 1]) < 0.1 * c_nom


def test_one_step_coefficient():
    # SPEC 3.4: k = 10, T_c = 0.01 gives 4.84e-4; closed form T - (1 - e^{-kT})/k evaluated in numpy
    assert float(one_step_coefficient(jnp.asarray(10.0), 0.01)) == pytest.approx(
        0.01 - (1 - np.exp(-0.1)) / 10, rel=1e-12
    )
    assert float(one_step_coefficient(jnp.asarray(10.0), 0.01)) == pytest.approx(4.84e-4, abs=5e-7)
    # small k T: c -> k T^2 / 2 (the next term is -k^2 T^3 / 6, relative kT/3 = 3.3e-4 here)
    assert float(one_step_coefficient(jnp.asarray(0.1), 0.01)) == pytest.approx(0.1 * 0.01**2 / 2, rel=1e-3)


# --- SPEC 3.8: one control step, by hand -----------------------------------------------------------------------


@jax.jit
def _command(controller, t, y, ref, memory):
    return controller.command(t, y, ref, memory)  # jitted: one compile instead of slow op-by-op dispatch


def _one_control_step(previous_saturated: float):
    scales = emulator_scales(TC, uses_velocity=True)
    k1, k2, k3 = jax.random.split(jax.random.PRNGKey(38), 3)
    mlp = init_mlp(k1, 4, 20, 3)
    mlp = mlp.__class__(mlp.w1, 0.2 * jax.random.normal(k2, (20,)), mlp.w2, 0.2 * jax.random.normal(k3, (3,)))
    velocity = jax.tree_util.tree_map(lambda w: 1e-3 * jnp.ones_like(w), mlp)
    controller = NNAdaptiveBackstepping(
        gains=(1.0, 55.0, 15.0),
        emulator=Emulator(mlp, scales, True),
        control_period=TC,
        analytic_coefficients=one_step_coefficient(jnp.asarray([10.0, 8.0]), TC),
        freeze_time=0.0,
        rates=(300.0, 2e4, 5e3),
        gain_momentum=0.3,
        leakage=0.5,
    )
    memory = AdaptiveMemory(
        gains=jnp.asarray([1.2, 60.0, 14.0]),
        last_step=jnp.asarray([0.01, -0.2, 0.05]),
        mlp=mlp,
        mlp_velocity=velocity,
        previous_pose=jnp.asarray([1.0, 2.0, 0.7]),
        previous_input=jnp.asarray([0.52, 0.1, 0.5, 0.08]),
        previous_saturated=jnp.asarray(previous_saturated),
        started=jnp.asarray(1.0),
    )
    y = jnp.asarray([1.0038, 2.0033, 0.7009, 0.505, 0.09])
    ref = Reference(*(jnp.asarray(v) for v in (1.09, 1.98, 0.75, 0.5, 0.1, 0.0, 0.0)))
    command, new_memory, logs = _command(controller, jnp.asarray(5.0), y, ref, memory)
    return controller, memory, y, ref, command, new_memory, logs


def test_one_control_step_follows_the_pseudo_code():
    """Train on the last transition, then the gradient through the *trained* emulator's Jacobian at the
    current gains' command, then the clipped gain step with momentum and leakage, then the new command."""
    controller, memory, y, ref, command, new_memory, logs = _one_control_step(previous_saturated=0.0)
    scales = controller.emulator.scales
    z_prev = memory.previous_input / scales.inputs
    target = body_increment(memory.previous_pose, y[:3]) / scales.outputs
    trained, velocity = momentum_step(
        memory.mlp,
        memory.mlp_velocity,
        backprop(memory.mlp, z_prev, target),
        learning_rate=0.2,
        momentum=0.3,
        clip_norm=5.0,
    )
    error = posture_error(y[0], y[1], y[2], ref.x, ref.y, ref.theta)
    assert float(jnp.hypot(error[0], error[1])) < 0.5  # the gate is open
    nu_c_now = kanayama_command(error, ref, memory.gains)  # well inside the clamps here
    c_v = float(one_step_coefficient(jnp.asarray(10.0), TC))
    jb = input_jacobian(trained, scales, jnp.concatenate([nu_c_now, y[3:5]]))[:, :2] / c_v
    gradient = cost_gradient(error, ref, jnp.asarray([1.0, 50.0, 1.0]), jb, True)
    step = (
        -TC * jnp.asarray([300.0, 2e4, 5e3]) * gradient
        + 0.3 * memory.last_step
        - TC * 0.5 * (memory.gains - jnp.asarray([1.0, 55.0, 15.0]))
    )
    step = np.clip(np.asarray(step), -np.asarray([0.05, 5.0, 0.5]), [0.05, 5.0, 0.5])
    # the step is a real one: not all zero, not all clipped
    assert np.all(np.abs(step) > 1e-4) and np.any(np.abs(step) < [0.05, 5.0, 0.5])
    gains = np.asarray(memory.gains) + step
    # the same operations in the same order: rounding only
    tol = {"rtol": 1e-12, "atol": 1e-15}
    np.testing.assert_allclose(logs["emulator_loss"], sample_loss(memory.mlp, z_prev, target), **tol)
    np.testing.assert_allclose(ravel_pytree(new_memory.mlp)[0], ravel_pytree(trained)[0], **tol)
    np.testing.assert_allclose(ravel_pytree(new_memory.mlp_velocity)[0], ravel_pytree(velocity)[0], **tol)
    np.testing.assert_allclose([logs["jacobian_v"], logs["jacobian_omega"]], [jb[0, 0], jb[2, 1]], **tol)
    assert float(logs["gate"]) == 1.0
    np.testing.assert_allclose(new_memory.gains, gains, **tol)
    np.testing.assert_allclose(new_memory.last_step, step, **tol)
    np.testing.assert_allclose([logs["kx"], logs["ky"], logs["ktheta"]], gains, **tol)
    nu_c = kanayama_command(error, ref, jnp.asarray(gains))
    np.testing.assert_allclose(command.nu_c, nu_c, **tol)
    np.testing.assert_allclose(new_memory.previous_input, jnp.concatenate([nu_c, y[3:5]]), **tol)
    np.testing.assert_array_equal(new_memory.previous_pose, y[:3])


def test_no_gain_change_after_a_saturated_period():
    _controller, memory, _y, _ref, _command, new_memory, logs = _one_control_step(previous_saturated=1.0)
    assert float(logs["gate"]) == 0.0
    np.testing.assert_array_equal(new_memory.gains, memory.gains)
    np.testing.assert_array_equal(new_memory.last_step, 0.0)
    # the package's choice (learn_saturated = False): a saturated transition is not learned either
    np.testing.assert_array_equal(new_memory.mlp.w1, memory.mlp.w1)


# --- the controller as a whole ------------------------------------------------------------------------------------


def test_nn_adaptive_beats_backstepping_on_the_paper_line(line):
    bs, nn = window_mean(line["bs"]), window_mean(line["nn"])
    # SPEC 4.5 expects a clear margin (paper: 60 %); 20 % rules out a noise-level "improvement"
    assert nn < 0.8 * bs, (nn, bs)
    # adaptation mainly raises K_x (the error is along-track, SPEC 4.5)
    assert line["nn"]["kx"][-1] > 1.5


def test_emulator_loss_is_finite_and_small_after_the_transient(line):
    nn = line["nn"]
    loss = nn["emulator_loss"]
    assert np.all(np.isfinite(loss)) and loss[0] == 0.0  # nothing to learn from at k = 0
    # normalised units: the forward target is about 0.5, i.e. a target energy ~0.1; 1e-6 is a sub-% error
    assert np.max(loss[nn["t"] >= 10.0]) < 1e-6
    assert np.all(np.isfinite(nn["jacobian_v"])) and np.all(np.isfinite(nn["jacobian_omega"]))


@pytest.mark.parametrize(
    "override", ['controller.emulator="E0"', 'controller.error_jacobian="paper"'], ids=["E0", "paper_error_jacobian"]
)
def test_options_run_and_adapt(line, override):
    identification = None if "E0" in override else line["identification"]
    nn, setup, result = run_line(override, identification=identification)
    assert result.status_name == "ok"
    if "E0" in override:
        assert setup.controller.outer.emulator.scales.inputs.shape == (2,)
        assert not setup.controller.outer.emulator.uses_velocity
        assert np.asarray(setup.identification.nmse)[0] < 0.3  # SPEC 3.7: E0's NMSE is 5-30 % in transients
    else:
        assert setup.controller.outer.error_jacobian == "paper"
    assert np.all(np.isfinite(nn["emulator_loss"]))
    assert any(nn[g][-1] != nn[g][0] for g in GAINS)
    # both ablations still improve on backstepping here (observed ~0.007 and ~0.016 m vs 0.046 m)
    assert window_mean(nn) < window_mean(line["bs"])


# --- the nominal model's Jacobians (issue 5: exact sensitivity, one-step and SPEC 3.6 Mode B) ------------------


def _held(nu_c):
    from ddtrack.controllers import VelocityCommand

    return VelocityCommand(nu_c, jnp.zeros(2), jnp.zeros(2), jnp.asarray(0.0))


def _nominal_period(**robot):
    from ddtrack.controllers import ComputedTorque
    from ddtrack.model import DynamicPlant
    from ddtrack.sim import NominalPeriod

    nominal = RobotParams(**robot)
    return NominalPeriod(DynamicPlant(nominal), ComputedTorque(nominal, kc=(10.0, 8.0)), TC, substeps=10)


def test_model_jacobian_is_the_derivative_of_one_nominal_period():
    period = _nominal_period()
    nu, nu_c = jnp.asarray([0.5, 0.2]), jnp.asarray([0.55, 0.25])
    numeric = central_difference(lambda c: period.increment(nu, _held(jnp.asarray(c))), np.asarray(nu_c), 1e-6)
    np.testing.assert_allclose(np.asarray(period.jacobian(nu, nu_c, _held)), numeric, atol=1e-10)


def test_model_jacobian_on_the_nominal_model_is_the_sampled_data_coefficient():
    # computed torque on its own model, torque held over the period: nu_dot = K (nu_c - nu_k) is constant, so the
    # displacement's sensitivity is K T_c^2 / 2, a few % above SPEC 3.4 (a)'s c = T_c - (1 - exp(-K T_c)) / K,
    # which assumes a continuous inner loop; the yaw channel also feels the Coriolis coupling (about 0.1 %)
    jacobian = np.asarray(_nominal_period().jacobian(jnp.asarray([0.5, 0.0]), jnp.asarray([0.5, 0.0]), _held))
    gains = np.asarray([10.0, 8.0])
    assert jacobian[0, 0] == pytest.approx(gains[0] * TC**2 / 2, rel=1e-9)
    assert jacobian[2, 1] == pytest.approx(gains[1] * TC**2 / 2, rel=1e-2)
    np.testing.assert_allclose(
        [jacobian[0, 0], jacobian[2, 1]], one_step_coefficient(jnp.asarray(gains), TC), rtol=0.05
    )
    assert abs(jacobian[1, 0]) < 1e-12 and abs(jacobian[0, 1]) < 1e-12


def test_model_jacobian_is_zero_through_a_saturated_torque():
    period = _nominal_period(max_torque=0.1)  # any sizeable command saturates both wheels
    jacobian = np.asarray(period.jacobian(jnp.asarray([0.0, 0.0]), jnp.asarray([1.0, 0.5]), _held))
    assert np.all(jacobian == 0.0)


def test_mode_b_one_step_sensitivity_gives_the_mode_a_gradient():
    """Sigma after one step from 0 is J^n Phi, and then e^T Gamma D Sigma is Mode A's e^T Gamma D_b J_b^n Phi."""
    from ddtrack.controllers.nn_adaptive import sensitivity_gradient, sensitivity_step

    y = jnp.asarray([1.0, 2.0, 0.7, 0.5, 0.1])
    ref = Reference(*(jnp.asarray(v) for v in (1.09, 1.98, 0.75, 0.5, 0.1, 0.0, 0.0)))
    gains, gamma = jnp.asarray([1.0, 55.0, 15.0]), jnp.asarray([1.0, 50.0, 1.0])
    jb = jnp.asarray([[0.97, 0.01], [0.0, 0.002], [0.02, 0.8]])
    error = posture_error(y[0], y[1], y[2], ref.x, ref.y, ref.theta)
    sigma = sensitivity_step(jnp.zeros((3, 3)), y, ref, gains, jb, 4.8e-4, TC)
    np.testing.assert_allclose(sigma, rotation(y[2]) @ jb @ gain_sensitivity(error, ref), atol=1e-15)
    for exact in (True, False):
        np.testing.assert_allclose(
            sensitivity_gradient(error, y, gamma, sigma, exact), cost_gradient(error, ref, gamma, jb, exact), rtol=1e-12
        )
    # and the transition carries Sigma on: a second step from the same pose adds (I + ...) Sigma
    twice = sensitivity_step(sigma, y, ref, gains, jb, 4.8e-4, TC)
    assert not np.allclose(twice, 2 * sigma) and np.all(np.isfinite(twice))


@pytest.mark.parametrize("jacobian", ["model", "model_sensitivity"])
def test_model_jacobian_variants_adapt_and_beat_backstepping_on_the_line(jacobian):
    # measured on the full paper line case, seed 0: model 0.0104 m, model_sensitivity 0.0048 m, backstepping 0.046 m;
    # here 25 s with the window [15, 25] s to keep the test short
    short = ["simulation.duration=25", "simulation.metric_window=[15, 25]", "controller.identification=false"]
    root = Path(__file__).resolve().parents[1] / "scenarios" / "paper_line.toml"
    errors = {}
    for kind, extra in (("backstepping", []), ("nn_adaptive_backstepping", [f'controller.jacobian="{jacobian}"'])):
        scenario = ddtrack.load_scenario(root, controller=kind, overrides=short + extra if extra else short[:2])
        result = ddtrack.run(scenario)
        columns = ddtrack.timeseries(result)
        window = columns["t"] >= 15.0
        errors[kind] = float(np.mean(columns["e_tr"][window]))
        assert result.status_name == "ok"
    assert errors["nn_adaptive_backstepping"] < 0.5 * errors["backstepping"], errors
