"""The fixed-step RK4 integrator: its coefficients, its measured order, and the plant integration
cross-checked against scipy's adaptive high-order solvers (SPEC 4.1: RK4 with 1 ms sub-steps)."""

from dataclasses import replace
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import ddtrack  # noqa: F401  (turns on float64)
from ddtrack import pytree_dataclass, static_field
from ddtrack.integrators import RK4
from ddtrack.model import DynamicPlant, RobotParams, WheelDisturbance
from ddtrack.parameters import TIMING
from ddtrack.sim import ClosedLoop, Draws, rk4, rk4_step, simulate
from ddtrack.trajectories import Line

CONTROL_PERIOD = 0.01
N_PERIODS = 300
SUBSTEPS = 10

# the "true" plant of SPEC 1.4 with the wheel friction of the brief
TRUE = {
    "mass": 12.0,
    "inertia": 0.70,
    "com_offset": 0.08,
    "wheel_radius": 0.05,
    "half_axle": 0.25,
    "viscous_friction": 0.005,
    "coulomb_friction": 0.05,
    "friction_smoothing": 0.01,
    "max_torque": 10.0,
}
TAU_D = np.array([0.03, -0.02])  # constant wheel disturbance [N m]


def observed_orders(steps, errors):
    """Slopes of log(error) against log(h) between consecutive step counts, and the least-squares slope."""
    h, e = 1.0 / np.asarray(steps, float), np.asarray(errors, float)
    pairwise = np.diff(np.log(e)) / np.diff(np.log(h))
    fitted = np.polyfit(np.log(h), np.log(e), 1)[0]
    return pairwise, fitted


@partial(jax.jit, static_argnums=(0, 3))
def integrate(f, x0, duration, steps):
    return rk4(f, x0, duration, steps)


# --- the scheme itself --------------------------------------------------------------------------


def test_rk4_step_has_classical_coefficients():
    # on x' = z x one step multiplies by the degree-4 Taylor polynomial of exp(z h): this pins all
    # of RK4's weights and nodes (a wrong weight changes one of the coefficients)
    z, h = -1.7, 0.3
    got = float(rk4_step(lambda x: z * x, jnp.asarray(1.0), h))
    zh = z * h
    assert got == pytest.approx(1 + zh + zh**2 / 2 + zh**3 / 6 + zh**4 / 24, rel=1e-15, abs=0)  # rounding only
    # non-autonomous quadrature (t carried in the state): Simpson's rule is exact for cubics
    f = lambda s: jnp.stack([jnp.ones_like(s[0]), 4.0 * s[0] ** 3 - 3.0 * s[0] ** 2 + 1.0])  # noqa: E731
    end = integrate(f, jnp.array([0.5, 2.0]), 1.5, 3)  # t from 0.5 to 2.0 in three steps
    exact = 2.0 + (2.0**4 - 2.0**3 + 2.0) - (0.5**4 - 0.5**3 + 0.5)
    np.testing.assert_allclose(end, [2.0, exact], rtol=1e-14)  # exact scheme: rounding only


def test_rk4_is_repeated_rk4_step():
    plant = DynamicPlant(RobotParams(com_offset=0.08))
    x0 = jnp.array([0.0, 0.0, 0.2, 0.5, 2.0])
    f = lambda x: plant.derivative(x, jnp.array([0.3, -0.1]), jnp.zeros(2))  # noqa: E731
    step = jax.jit(rk4_step, static_argnums=0)
    manual = x0
    for _ in range(4):
        manual = step(f, manual, 0.025)
    np.testing.assert_allclose(integrate(f, x0, 0.1, 4), manual, rtol=1e-15, atol=1e-15)  # same operations


# --- solvers: the method a plant is advanced with, an argument beside it -------------------------


@pytree_dataclass
class Euler:
    """A user's own solver: explicit Euler in ``substeps`` equal steps (first order)."""

    substeps: int = static_field(default=10, why="a loop bound")

    def integrate(self, f, x, duration):
        h = duration / self.substeps
        return jax.lax.fori_loop(0, self.substeps, lambda _, z: z + h * f(z), x)


def test_the_rk4_solver_is_rk4_bit_for_bit():
    plant = DynamicPlant(RobotParams(**TRUE))
    x0, tau = jnp.array([0.5, -1.0, 0.3, 1.0, 1.5]), jnp.array([1.2, -0.8])
    f = lambda x: plant.derivative(x, tau, jnp.asarray(TAU_D))  # noqa: E731
    for n in (1, 7, 10):
        assert np.array_equal(RK4(n).integrate(f, x0, 0.01), rk4(f, x0, 0.01, n))
        assert np.array_equal(
            jax.jit(lambda s: plant.advance(x0, tau, jnp.asarray(TAU_D), 0.01, s))(RK4(n)), integrate(f, x0, 0.01, n)
        )
    assert RK4().substeps == TIMING.substeps  # the declared default
    assert replace(RK4(3), substeps=5) == RK4(5)  # the same method at another step count


def test_a_users_solver_advances_a_plant_at_its_own_order():
    """A solver of the user's own (explicit Euler) passed to a plant's ``advance``, through ``jit`` as a pytree:
    its result converges to RK4's at first order, the error halving as the steps double."""
    plant = DynamicPlant(RobotParams(**TRUE))
    x0, tau, tau_d = jnp.array([0.5, -1.0, 0.3, 1.0, 1.5]), jnp.array([1.2, -0.8]), jnp.asarray(TAU_D)
    advance = jax.jit(lambda solver: plant.advance(x0, tau, tau_d, 0.5, solver))
    reference = np.asarray(advance(RK4(400)))  # its error is ~1e-13, far below Euler's
    steps = [20, 40, 80, 160]
    errors = [np.max(np.abs(np.asarray(advance(Euler(n))) - reference)) for n in steps]
    assert errors[-1] > 1e-6  # truncation, far above the reference's error
    pairwise, fitted = observed_orders(steps, errors)
    assert np.all((pairwise > 0.9) & (pairwise < 1.1)), pairwise  # Euler: global error ~ C h
    assert 0.9 < fitted < 1.1
    assert np.array_equal(advance(replace(Euler(), substeps=20)), advance(Euler(20)))


# --- measured order of convergence --------------------------------------------------------------


def test_rk4_global_order_on_closed_form_problem():
    # x' = 1 + x^2, y' = -x y from (0, 1): x = tan t, y = cos t (nonlinear and coupled)
    f = lambda s: jnp.stack([1.0 + s[0] ** 2, -s[0] * s[1]])  # noqa: E731
    duration = 1.2
    steps = [12, 24, 48, 96]
    exact = np.array([np.tan(duration), np.cos(duration)])
    errors = [np.max(np.abs(np.asarray(integrate(f, jnp.array([0.0, 1.0]), duration, n)) - exact)) for n in steps]
    assert errors[-1] > 1e-12  # still far above rounding, so the slopes measure truncation
    pairwise, fitted = observed_orders(steps, errors)
    assert np.all((pairwise > 3.7) & (pairwise < 4.3)), pairwise  # RK4: global error ~ C h^4
    assert 3.7 < fitted < 4.3


def test_rk4_global_order_on_robot_plant():
    # wheels kept well away from zero speed, so the tanh Coulomb term is smooth at these step sizes
    plant = DynamicPlant(RobotParams(**TRUE))
    x0 = jnp.array([0.5, -1.0, 0.3, 1.0, 1.5])
    tau = jnp.array([1.2, -0.8])
    f = lambda x: plant.derivative(x, tau, jnp.asarray(TAU_D))  # noqa: E731
    duration = 2.0
    steps = [10, 20, 40, 80]
    reference = np.asarray(integrate(f, x0, duration, 10_240))  # h 128x smaller: its error is ~3e-9 of the finest
    samples = np.stack([np.asarray(integrate(f, x0, t, 400)) for t in (0.5, 1.0, 1.5, 2.0)])
    assert np.min(np.abs(wheel_speeds_np(samples))) > 100 * TRUE["friction_smoothing"]  # precondition
    errors = [np.max(np.abs(np.asarray(integrate(f, x0, duration, n)) - reference)) for n in steps]
    assert errors[-1] > 1e-11  # far above rounding and above the reference's own error
    pairwise, fitted = observed_orders(steps, errors)
    assert np.all((pairwise > 3.7) & (pairwise < 4.3)), pairwise  # RK4: global error ~ C h^4
    assert 3.7 < fitted < 4.3


# --- cross-check against scipy --------------------------------------------------------------------


def smooth_random(rng, n, period):
    """A smooth signal on the control grid with max |.| = 1: a sum of four random sinusoids."""
    t = np.arange(n) * period
    a, w, phase = rng.normal(size=4), rng.uniform(0.5, 4.0, 4), rng.uniform(0.0, 2 * np.pi, 4)
    s = np.sum(a[:, None] * np.sin(w[:, None] * t[None] + phase[:, None]), axis=0)
    return s / np.max(np.abs(s))


def scipy_rhs(t, state, tau, tau_d, p=TRUE):
    """SPEC 1.3's scalar form, typed out with NumPy (independent of ddtrack's implementation)."""
    _, _, theta, v, w = state
    m, d, r, half = p["mass"], p["com_offset"], p["wheel_radius"], p["half_axle"]
    i_a = p["inertia"] + m * d * d
    phi = np.array([(v + half * w) / r, (v - half * w) / r])
    tf = p["viscous_friction"] * phi + p["coulomb_friction"] * np.tanh(phi / p["friction_smoothing"])
    net = tau - tf - tau_d
    v_dot = ((net[0] + net[1]) / r + m * d * w * w) / m
    w_dot = (half / r * (net[0] - net[1]) - m * d * w * v) / i_a
    return [v * np.cos(theta), v * np.sin(theta), w, v_dot, w_dot]


def scipy_zoh(x0, torques, method="DOP853"):
    """Integrate period by period under a zero-order hold; returns the states at t_0 .. t_N."""
    states = [np.asarray(x0, float)]
    for tau in torques:
        sol = solve_ivp(
            scipy_rhs, (0.0, CONTROL_PERIOD), states[-1], method=method, rtol=1e-12, atol=1e-12, args=(tau, TAU_D)
        )
        assert sol.success
        states.append(sol.y[:, -1])
    return np.array(states)


@partial(jax.jit, static_argnames="substeps")
def ddtrack_zoh(plant, x0, torques, tau_d, substeps=SUBSTEPS):
    """What the simulator does in one control period, scanned over the torque sequence."""

    def period(x, tau):
        x_next = rk4(lambda z: plant.derivative(z, tau, tau_d), plant.hold(x, tau), CONTROL_PERIOD, substeps)
        return x_next, x_next

    _, states = jax.lax.scan(period, x0, torques)
    return jnp.concatenate([x0[None], states])


def wheel_speeds_np(states):
    v, w, r, half = states[:, 3], states[:, 4], TRUE["wheel_radius"], TRUE["half_axle"]
    return np.column_stack([(v + half * w) / r, (v - half * w) / r])


@pytest.fixture(scope="module")
def forward_drive():
    """300 periods of smooth random torques within +-5 N m that never reverse a wheel."""
    rng = np.random.default_rng(2024)
    common, differential = smooth_random(rng, N_PERIODS, CONTROL_PERIOD), smooth_random(rng, N_PERIODS, CONTROL_PERIOD)
    torques = np.column_stack([0.15 + 0.5 * common + 2.0 * differential, 0.15 + 0.5 * common - 2.0 * differential])
    x0 = np.array([0.5, -1.0, 0.3, 1.0, 0.0])
    reference = scipy_zoh(x0, torques)
    return x0, torques, reference


def test_plant_integration_matches_scipy(forward_drive):
    x0, torques, reference = forward_drive
    assert np.max(np.abs(torques)) <= 5.0 and np.ptp(torques) > 3.0  # within the brief's +-5 N m, well spread
    phi = wheel_speeds_np(reference)
    assert np.min(np.abs(phi)) > 100 * TRUE["friction_smoothing"]  # no wheel reversal (see the next test)
    assert np.max(np.abs(reference[:, 4])) > 1.0  # the robot really turns (Coriolis and trig terms active)
    radau = scipy_zoh(x0, torques[:50], method="Radau")
    # the two scipy solvers agree (checks the reference itself): rtol = atol = 1e-12 per step, 50 steps
    np.testing.assert_allclose(radau, reference[:51], rtol=0, atol=1e-9)

    plant = DynamicPlant(RobotParams(**TRUE))
    states = np.asarray(ddtrack_zoh(plant, jnp.asarray(x0), jnp.asarray(torques), jnp.asarray(TAU_D)))
    # RK4 at h = 1 ms: global error ~ C h^4 T, measured 8e-12 here; the brief's 1e-8 holds with margin
    np.testing.assert_allclose(states, reference, rtol=0, atol=1e-8)


def test_simulator_schedule_matches_scipy(forward_drive):
    """ddtrack.simulate with a controller that replays the torques: the same ZOH and sub-steps."""
    x0, torques, reference = forward_drive

    @pytree_dataclass
    class Replay:
        table: jax.Array

        def init(self, x0, ref0, key):
            return jnp.asarray(0)

        def step(self, t, y, ref, k):
            return self.table[k], k + 1, {}

    plant = DynamicPlant(RobotParams(**TRUE))
    loop = ClosedLoop(
        plant,
        Replay(jnp.asarray(torques)),
        Line(),
        WheelDisturbance(bias=tuple(TAU_D)),
        control_period=CONTROL_PERIOD,
        divergence_error=1e9,
        solver=RK4(SUBSTEPS),
    )
    result = simulate(loop, jnp.asarray(x0), Draws.zeros(N_PERIODS), n_steps=N_PERIODS)
    assert int(result.status) == 0
    # simulate records x_k at t_k (k = 0..N-1), the state before the k-th period's integration
    np.testing.assert_allclose(np.asarray(result.state), reference[:-1], rtol=0, atol=1e-8)  # as above
    np.testing.assert_array_equal(np.asarray(result.control), torques)  # held as given (|tau| < max_torque)


def test_plant_integration_through_wheel_reversals_converges_to_scipy():
    """Starting at rest with torques of both signs the wheels reverse, and the tanh Coulomb term of
    width eps_f = 0.01 rad/s is crossed in ~25 us, far below h = 1 ms. There the right-hand side is
    effectively discontinuous at the scale of h, so RK4 is not fourth order: each reversal costs an
    error O(h * tau_c / (R m)) rather than O(h^4). 1e-8 at 10 sub-steps is not reachable there. What
    must hold is convergence to the scipy solution as the sub-step shrinks."""
    rng = np.random.default_rng(7)
    torques = 5.0 * np.column_stack(
        [smooth_random(rng, N_PERIODS, CONTROL_PERIOD), smooth_random(rng, N_PERIODS, CONTROL_PERIOD)]
    )
    x0 = np.array([0.5, -1.0, 0.3, 0.0, 0.0])
    reference = scipy_zoh(x0, torques)
    reversals = np.sum(np.diff(np.sign(wheel_speeds_np(reference)[1:]), axis=0) != 0)
    assert reversals >= 2  # the case this test is about
    plant = DynamicPlant(RobotParams(**TRUE))
    errors = []
    for substeps in (10, 40, 160):
        states = ddtrack_zoh(plant, jnp.asarray(x0), jnp.asarray(torques), jnp.asarray(TAU_D), substeps=substeps)
        errors.append(np.max(np.abs(np.asarray(states) - reference)))
    # a kink per reversal: at least first order (4x per 4x smaller h) is required; measured ~h^2 (15x, 20x)
    assert errors[0] / errors[1] > 4.0 and errors[1] / errors[2] > 4.0, errors
    # and it is small in absolute terms: O(h tau_c / (R m)) ~ 1e-4 per reversal, amplified over 3 s
    assert errors[0] < 1e-2 and errors[2] < 1e-5, errors


def test_semi_implicit_euler_is_first_order_and_keeps_an_undamped_oscillator_bounded():
    """x'' = -x from (1, 0): semi-implicit Euler's error halves with the step (first order), and over 100 periods
    its energy stays within O(h) of 1/2 where explicit Euler's grows as (1 + h^2)^n."""
    from ddtrack.integrators import semi_implicit_euler_step

    def run(h, n):
        q, v = jnp.array([1.0]), jnp.array([0.0])
        for _ in range(n):
            q, v = semi_implicit_euler_step(lambda q, v: -q, lambda q, v, h: h * v, q, v, h)
        return float(q[0]), float(v[0])

    errors = [abs(run(h, round(1.0 / h))[0] - np.cos(1.0)) for h in (0.02, 0.01)]
    assert errors[0] / errors[1] == pytest.approx(2.0, rel=0.05)
    h = 0.1
    q, v = jnp.array([1.0]), jnp.array([0.0])
    energy = []
    for _ in range(round(200 * np.pi / h)):
        q, v = semi_implicit_euler_step(lambda q, v: -q, lambda q, v, h: h * v, q, v, h)
        energy.append(0.5 * float(q[0] ** 2 + v[0] ** 2))
    assert max(abs(e - 0.5) for e in energy) < h  # explicit Euler: 0.5 (1 + h^2)^6283, about 1e27
