"""Baselines B: the LTV/LQR unicycle tracker (``ltv_lqr``) and sliding-mode backstepping with a boundary
layer (``sliding_mode_backstepping``): their defining properties, then each as a scenario controller."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from conftest import SCENARIOS

import ddtrack
from ddtrack.controllers import Backstepping, Cascade, ComputedTorque, VelocityCommand
from ddtrack.controllers.baselines import LTVUnicycleLQR, SlidingModeTorque, switching_term, unicycle_error_model
from ddtrack.model import DynamicPlant, RobotParams, WheelDisturbance, pose_rate, reduced_input, reduced_mass
from ddtrack.sim import ClosedLoop, Draws, simulate, stack
from ddtrack.trajectories import Circle, Line

EXACT = RobotParams(max_torque=1e9)  # nominal robot, no friction, torque limit off
TC = 0.01


# --- LTV/LQR ------------------------------------------------------------------------------------------


def _scipy_gain(v: float, control_period: float, q_tol, r_tol) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A_d, B_d, K) from the continuous model, scipy's expm and scipy's DARE solver."""
    block = np.zeros((5, 5))
    block[1, 2] = v  # A = [[0,0,0],[0,0,v],[0,0,0]]
    block[0, 3] = block[2, 4] = 1.0  # B = [[1,0],[0,0],[0,1]]
    discrete = scipy.linalg.expm(block * control_period)
    a, b = discrete[:3, :3], discrete[:3, 3:]
    q, r = np.diag(1.0 / np.asarray(q_tol) ** 2), np.diag(1.0 / np.asarray(r_tol) ** 2)
    p = scipy.linalg.solve_discrete_are(a, b, q, r)
    return a, b, np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)


@jax.jit
def _gains(law: LTVUnicycleLQR, speeds: jax.Array) -> jax.Array:
    """K(v) for each speed, jitted and vmapped as in a batch; the law is an argument, so it compiles once."""
    return jax.vmap(law.gain)(speeds)


@pytest.mark.parametrize(
    ("q_tol", "r_tol", "control_period"),
    [
        ((0.0625, 0.125, 2.0), (1.0, 2.0), 0.01),  # WPILib's defaults
        ((0.3, 0.05, 0.5), (0.5, 4.0), 0.02),
    ],
    ids=["wpilib", "other"],
)
def test_ltv_lqr_gain_is_the_dare_solution(q_tol, r_tol, control_period):
    speeds = np.array([0.0, 5e-5, 1e-4, 0.01, 0.5, 2.0, -0.5])
    law = LTVUnicycleLQR(q_tolerance=q_tol, r_tolerance=r_tol, control_period=control_period)
    gains = np.asarray(_gains(law, jnp.asarray(speeds)))
    for v, k in zip(speeds, gains, strict=True):
        linearised = v if abs(v) >= law.min_velocity else law.min_velocity  # WPILib's guard at v ~ 0
        a, b, k_scipy = _scipy_gain(linearised, control_period, q_tol, r_tol)
        a_d, b_d = unicycle_error_model(jnp.asarray(linearised), control_period)
        np.testing.assert_allclose(a_d, a, rtol=0, atol=1e-15)  # exp(A T) = I + A T exactly (A^2 = 0)
        np.testing.assert_allclose(b_d, b, rtol=0, atol=1e-15)
        # |K| ~ 16; at v = 1e-4 scipy's own P (~4e6) is the less accurate of the two, by ~1e-9 in K
        np.testing.assert_allclose(k, k_scipy, rtol=0, atol=1e-8)
        # u = K e with e = -x: the closed-loop error map is A_d - B_d K, stable
        assert np.max(np.abs(np.linalg.eigvals(a - b @ k))) < 1.0
    # counter-check: five doubling steps are not enough at the slowest speed
    few = LTVUnicycleLQR(q_tolerance=q_tol, r_tolerance=r_tol, control_period=control_period, dare_iterations=5)
    assert np.max(np.abs(np.asarray(_gains(few, jnp.asarray(speeds)))[2] - gains[2])) > 1e-2


def test_ltv_lqr_command_and_its_rate():
    """nu_c = nu_r at zero error; at constant v_r (K constant) the rate equals d nu_c / dt along the motion."""
    law = LTVUnicycleLQR(max_velocity=1e9, max_yaw_rate=1e9)
    circle = Circle(center=(1.0, 2.0), radius=2.0, speed=0.6, start_angle=0.3)
    ref0 = circle(0.0)
    on_ref = jnp.stack([ref0.x, ref0.y, ref0.theta, ref0.v, ref0.omega])

    @jax.jit
    @jax.vmap
    def rates(y0):
        """(nu_c, its analytic rate, d nu_c / dt by forward-mode autodiff) at y0 moving with its own nu."""
        y_dot = jnp.concatenate([pose_rate(y0[2], y0[3], y0[4]), jnp.zeros(2)])
        command = law.command(0.0, y0, ref0, ())[0]
        _, exact = jax.jvp(lambda t: law.command(t, y0 + t * y_dot, circle(t), ())[0].nu_c, (0.0,), (1.0,))
        return command.nu_c, command.nu_c_dot, exact

    offsets = np.random.default_rng(5).uniform(-0.3, 0.3, (6, 5))
    offsets[0] = 0.0
    nu_c, analytic, exact = rates(on_ref + jnp.asarray(offsets))
    np.testing.assert_allclose(nu_c[0], [ref0.v, ref0.omega], rtol=0, atol=1e-15)  # zero error: feed-forward
    np.testing.assert_allclose(analytic, exact, rtol=0, atol=1e-10)


# --- sliding mode -----------------------------------------------------------------------------------------


def test_switching_term_saturates_outside_the_layer_and_is_linear_inside():
    rng = np.random.default_rng(7)
    gain, layer = np.array([1.5, 2.5]), np.array([0.02, 0.05])
    for _ in range(50):
        outside = np.sign(rng.uniform(-1, 1, 2)) * layer * rng.uniform(1.001, 100.0, 2)
        np.testing.assert_array_equal(switching_term(outside, gain, layer), np.sign(outside) * gain)  # reaching: K_s
        inside = layer * rng.uniform(-1.0, 1.0, 2)
        np.testing.assert_allclose(switching_term(inside, gain, layer), gain * inside / layer, rtol=1e-15)
        np.testing.assert_allclose(
            switching_term(0.5 * inside, gain, layer), 0.5 * switching_term(inside, gain, layer), rtol=1e-15
        )  # linear in s
    # the torque: computed torque plus B_bar^-1 M_hat K_s sat(s / phi); K_s = 0 is computed torque itself
    y = jnp.asarray([0.3, -0.2, 0.4, 0.35, 0.1])
    command = VelocityCommand(jnp.asarray([0.5, -0.3]), jnp.asarray([0.2, 0.1]), jnp.zeros(2), jnp.asarray(0.0))
    base, _, _ = ComputedTorque(EXACT, kc=(10.0, 10.0)).torque(y, command, ())
    smc = SlidingModeTorque(EXACT, kc=(10.0, 10.0), switching_gain=tuple(gain), boundary_layer=tuple(layer))
    tau, saturated, _ = smc.torque(y, command, ())
    expected = np.linalg.solve(reduced_input(EXACT), reduced_mass(EXACT) @ (gain * np.sign(command.nu_c - y[3:5])))
    np.testing.assert_allclose(tau - base, expected, rtol=0, atol=1e-12)
    assert float(saturated) == 0.0
    off, _, _ = SlidingModeTorque(EXACT, switching_gain=(0.0, 0.0)).torque(y, command, ())
    np.testing.assert_array_equal(off, base)


SMC_STEPS = 500  # 5 s
CONSTANT = WheelDisturbance(bias=(0.2, 0.1))  # matched: (0.6 m/s^2, 0.85 rad/s^2) below K_s = (1, 2)
LAYERS = (1e-4, 1e-2, 1e-1)  # phi_v [m/s] of the chattering rows (phi_omega twice that)


def _smc(switching_gain, boundary_layer) -> Cascade:
    inner = SlidingModeTorque(EXACT, kc=(1.0, 1.0), switching_gain=switching_gain, boundary_layer=boundary_layer)
    return Cascade(Backstepping(max_velocity=1e9, max_yaw_rate=1e9), inner)


@pytest.fixture(scope="module")
def smc_runs():
    """One vmapped simulation (one compile) under a constant wheel disturbance, with a weak linear part
    K_c = 1/s so that the switching term does the work; the robot starts at rest on a line run at 0.5 m/s.

    Rows: 0 K_s = (1, 2), phi = (0.02, 0.04); 1 the same with K_s = 0; 2-4 K_s = (1, 2), phi = LAYERS.
    """
    controllers = [_smc((1.0, 2.0), (0.02, 0.04)), _smc((0.0, 0.0), (0.02, 0.04))]
    controllers += [_smc((1.0, 2.0), (phi, 2 * phi)) for phi in LAYERS]
    line = Line(start=(0.0, 0.0), heading=0.0, speed=0.5)

    def one(controller):
        loop = ClosedLoop(DynamicPlant(EXACT), controller, line, CONSTANT, control_period=TC)
        return simulate(loop, jnp.zeros(5), Draws.zeros(SMC_STEPS), n_steps=SMC_STEPS)

    result = jax.jit(jax.vmap(one))(stack(controllers))
    assert np.all(np.asarray(result.status) == 0)
    # s = nu_c - nu at each period, from the logged command and the (noise-free) state
    s = np.stack(
        [
            np.asarray(result.logs["v_cmd"]) - np.asarray(result.state[..., 3]),
            np.asarray(result.logs["omega_cmd"]) - np.asarray(result.state[..., 4]),
        ],
        axis=-1,
    )
    return np.asarray(result.t[0]), s, np.asarray(result.control)


def test_sliding_variable_reaches_the_layer_in_finite_time_and_stays(smc_runs):
    t, s, _ = smc_runs
    layer = np.array([0.02, 0.04])
    delta = np.linalg.solve(reduced_mass(EXACT), reduced_input(EXACT) @ np.asarray(CONSTANT.bias))  # matched, as nu_dot
    assert np.all(np.abs(delta) < [1.0, 2.0])
    outside = np.any(np.abs(s[0]) > layer, axis=1)
    assert outside[0]  # |s_v(0)| = v_r = 0.5 m/s
    reached = t[np.nonzero(outside)[0][-1] + 1]  # first period from which s stays inside
    # sliding condition: reached within |s(0)| / (K_s - |delta|) (= 1.25 s for v); measured 0.76 s
    assert reached <= abs(s[0, 0, 0]) / (1.0 - abs(delta[0]))
    # inside the layer it settles at delta / (K_c + K_s / phi) (0.012 m/s, 0.017 rad/s), below phi
    np.testing.assert_allclose(s[0, -1], delta / (1.0 + np.array([1.0, 2.0]) / layer), rtol=0.05)
    # counter-check: without the switching term the linear loop leaves s = delta / K_c, far outside the layer
    np.testing.assert_allclose(s[1, -1], delta, rtol=0.05)


def test_a_wider_boundary_layer_chatters_less(smc_runs):
    t, _, tau = smc_runs
    window = t >= 2.0  # after the reaching phase
    variation = [np.abs(np.diff(tau[row][window], axis=0)).sum() for row in (2, 3, 4)]  # total variation [N m]
    # measured 172, 0.014, 0.007 N m: phi = 1e-4 switches at every period ((K_c + K_s / phi) T_c = 100 >> 2)
    assert variation[0] > variation[1] > variation[2]
    assert variation[0] > 1000 * variation[1]


# --- as scenario controllers ------------------------------------------------------------------------------

# e_tr_mean [m] measured on paper_line over [10, 20] s and on the circle over [5, 10] s; backstepping's is
# 0.046 on both. The LQR's along-track gain (14.8 1/s against Kx = 1) and the switching term both shrink
# the offset that the unmodelled friction and disturbance leave.
MEASURED = {"ltv_lqr": (0.0052, 0.0044), "sliding_mode_backstepping": (0.0078, 0.0078)}
KINDS = list(MEASURED)


def _scenario(name: str, kind: str, duration: int):
    window = f"simulation.metric_window=[{duration // 2}, {duration}]"
    return ddtrack.load_scenario(
        SCENARIOS / name, controller=kind, overrides=[f"simulation.duration={duration}", window]
    )


def _mean_error(result, scenario) -> float:
    start, end = scenario.simulation.window
    t = np.asarray(result.t)
    e_tr = np.hypot(np.asarray(result.error[:, 0]), np.asarray(result.error[:, 1]))
    return float(np.mean(e_tr[(t >= start - 1e-9) & (t <= end + 1e-9)]))


@pytest.mark.parametrize("kind", KINDS)
def test_tracks_the_paper_line_and_a_circle(kind):
    for name, duration, measured in (
        ("paper_line.toml", 20, MEASURED[kind][0]),
        ("circle.toml", 10, MEASURED[kind][1]),
    ):
        scenario = _scenario(name, kind, duration)
        assert scenario.controller.kind == kind  # selected by name over the file's backstepping
        result = ddtrack.run(scenario)
        assert result.status_name == "ok"
        assert _mean_error(result, scenario) < 1.5 * measured  # far below backstepping's 0.046 m
