"""Latency, encoders and odometry in the closed loop (model.md §1.9): the [sensing] section, ``SensedPlant`` and
what a run records of them."""

from __future__ import annotations

import functools
import json
import math
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack import pytree_dataclass
from ddtrack.errors import ConfigError
from ddtrack.integrators import RK4
from ddtrack.layout import BODY, Layout
from ddtrack.model import DynamicPlant, KinematicPlant, RobotParams, SensedPlant, Sensing, wheel_speeds
from ddtrack.model.sensing import QUEUE_BUCKET
from ddtrack.scenario import build
from ddtrack.sim import ClosedLoop, Draws, simulate
from ddtrack.trajectories import Line

T = 0.01  #: control period [s]
N = 200  #: periods per run
PARAMS = RobotParams()  # the paper's robot: R = 0.05 m, L = 0.25 m


@pytree_dataclass
class OpenLoop:
    """Commands that depend on time only, (a + b sin(t), c + d cos(t)), and logs of what the controller sees."""

    offset: tuple[float, float] = (0.3, 0.0)
    swing: tuple[float, float] = (0.2, 0.3)
    output_kind: ClassVar[str] = "torque"

    def init(self, y0, ref0, key):
        return ()

    def step(self, t, y, ref, memory):
        u = jnp.asarray(self.offset) + jnp.asarray(self.swing) * jnp.stack([jnp.sin(t), jnp.cos(t)])
        return u, memory, {"seen_x": y[0], "seen_theta": y[2]}


@pytree_dataclass
class OpenLoopVelocity(OpenLoop):
    output_kind: ClassVar[str] = "velocity"


def run(plant, controller=None, n_steps: int = N):
    controller = OpenLoop() if controller is None else controller
    return simulate(
        ClosedLoop(plant, controller, Line(), control_period=T), jnp.zeros(5), Draws.zeros(n_steps), n_steps=n_steps
    )


def sensed(
    inner, *, delay: float = 0.0, measurement: float = 0.0, counts: int = 0, odometry: bool = False, nominal=None
):
    chain = Sensing(delay, measurement, counts, odometry, T)
    return chain.wrap(inner, PARAMS if nominal is None else nominal, PARAMS)


@functools.cache
def plain_run():
    return run(DynamicPlant(PARAMS))


DELAY, MEASUREMENT = 3, 2  #: periods


@functools.cache
def late_run():
    """The paper's robot under an actuation delay of 3 periods and a measurement delay of 2."""
    return run(sensed(DynamicPlant(PARAMS), delay=DELAY * T, measurement=MEASUREMENT * T))


def odometry_run(counts: int, nominal: RobotParams, command: tuple[float, float]):
    """The unicycle driven at the constant (v, omega) ``command``, seen through odometry (one compilation for all)."""
    controller = OpenLoopVelocity(offset=command, swing=(0.0, 0.0))
    return run(sensed(KinematicPlant(), counts=counts, odometry=True, nominal=nominal), controller)


def test_a_chain_with_everything_off_changes_no_bit():
    plain, wrapped = plain_run(), run(sensed(DynamicPlant(PARAMS)))
    for a, b in zip(jax.tree_util.tree_leaves(plain), jax.tree_util.tree_leaves(wrapped), strict=True):
        np.testing.assert_array_equal(a, b)
    scenario = ddtrack.load_scenario(SCENARIOS / "paper_line.toml")
    assert build(scenario).sensing is None and type(build(scenario).plant) is DynamicPlant  # off: not even wrapped


def test_a_delay_of_k_periods_shifts_the_applied_torques_and_the_motion_by_k_rows():
    plain, late, k = plain_run(), late_run(), DELAY
    commanded = np.asarray(plain.control)
    np.testing.assert_array_equal(late.control, commanded)  # the controller's commands are what it computed
    applied = np.stack([late.logs["tau_r"], late.logs["tau_l"]], axis=1)
    np.testing.assert_array_equal(applied[k:], commanded[:-k])
    np.testing.assert_array_equal(applied[:k], 0.0)  # no torque was held before the run
    np.testing.assert_allclose(late.state[k:], plain.state[:-k], rtol=0, atol=1e-13)  # time-invariant: shifted
    assert not any(name.startswith(("queued", "delayed")) for name in late.plant_state)  # the queues are internal


def test_the_controller_sees_the_measurement_of_k_periods_ago():
    late, k = late_run(), MEASUREMENT
    x = np.asarray(late.state[:, 0])
    np.testing.assert_array_equal(late.logs["seen_x"][k:], x[:-k])
    np.testing.assert_array_equal(late.logs["seen_x"][:k], x[0])


def test_a_fractional_delay_splits_each_period_between_two_commands():
    """On the unicycle driving straight the distance over period j is T_c (f c_{j-k-1} + (1 - f) c_{j-k}): a delay
    of 1.5 periods drives the mean of the distances under 1 and 2 periods, from a start at rest."""
    result = run(sensed(KinematicPlant(), delay=1.5 * T), OpenLoopVelocity(swing=(0.2, 0.0)))
    c = np.concatenate([[0.0, 0.0], np.asarray(result.control[:, 0])])  # at rest before the run
    expected = np.concatenate([[0.0], np.cumsum(T * (0.5 * c[:-2] + 0.5 * c[1:-1]))[:-1]])
    np.testing.assert_allclose(result.state[:, 0], expected, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(result.state[:, 3], np.concatenate([[0.0], c[1:-2]]), atol=1e-15)  # the later one


@pytest.mark.parametrize("counts", [0, 4096])
def test_a_one_percent_wheel_radius_error_stretches_the_odometry_distance_by_one_percent(counts):
    """Straight ahead at 0.5 m/s, the odometry believes R-hat = 1.01 R: x_est - x = 0.01 (x - x_0), the heading and
    lateral estimate stay exact, within one encoder count of R-hat 2 pi / n."""
    nominal = RobotParams(wheel_radius=1.01 * PARAMS.wheel_radius)
    result = odometry_run(counts, nominal, (0.5, 0.0))
    x, ex = np.asarray(result.state[:, 0]), np.asarray(result.logs["odom_ex"])
    count = nominal.wheel_radius * 2 * math.pi / counts if counts else 1e-12
    assert x[-1] > 0.9  # it drove about a metre
    np.testing.assert_allclose(ex, 0.01 * x, rtol=0, atol=count)
    np.testing.assert_allclose(result.logs["odom_ey"], 0.0, atol=1e-12)
    np.testing.assert_allclose(result.logs["odom_etheta"], 0.0, atol=1e-12)
    np.testing.assert_allclose(result.logs["seen_x"], result.plant_state["odom_x"])  # the controller sees it
    assert {"phi_r", "phi_l", "odom_x", "odom_theta"} <= set(result.plant_state)


def test_quantized_encoders_bound_the_heading_error_by_one_count_per_wheel():
    """The heading estimate telescopes, so its error stays under R-hat (2 pi / n) / L-hat however far it turns."""
    counts = 64
    result = odometry_run(counts, PARAMS, (0.3, 5.0))
    bound = PARAMS.wheel_radius * 2 * math.pi / counts / PARAMS.half_axle
    heading = np.abs(np.asarray(result.logs["odom_etheta"]))
    assert heading.max() <= bound * (1 + 1e-9)
    assert heading.max() > 0.3 * bound  # the counts do show
    assert float(result.state[-1, 2]) > 9.0  # it turned more than a revolution and a half


def test_an_absolute_fix_pulls_the_estimate_back_to_the_truth():
    """With a fix every 10 periods, gain 1 and no noise, the 1 % radius error's drift restarts from 0 at each fix."""
    nominal = RobotParams(wheel_radius=1.01 * PARAMS.wheel_radius)
    chain = Sensing(odometry=True, control_period=T, fix_period=10 * T, fix_gain=1.0)
    straight = OpenLoopVelocity(offset=(0.5, 0.0), swing=(0.0, 0.0))
    ex = np.asarray(run(chain.wrap(KinematicPlant(), nominal, PARAMS), straight).logs["odom_ex"])
    np.testing.assert_allclose(ex[::10], 0.0, atol=1e-12)
    np.testing.assert_allclose(ex[9::10], 0.01 * 0.5 * 9 * T, rtol=1e-9)  # 9 periods of drift since the last fix
    with pytest.raises(ValueError, match="need odometry"):
        Sensing(control_period=T, fix_period=10 * T).wrap(KinematicPlant(), nominal, PARAMS)


def gyro_run(nominal: RobotParams, density: float, bias: float, key=None):
    """The unicycle turning at a constant 2 rad/s, its odometry's heading from a gyro (one compilation for all)."""
    chain = Sensing(odometry=True, control_period=T, gyro=True, gyro_noise_density=density, gyro_bias=bias)
    turning = OpenLoopVelocity(offset=(0.3, 2.0), swing=(0.0, 0.0))
    return run(chain.wrap(KinematicPlant(), nominal, PARAMS, key), turning)


def test_a_gyro_heading_ignores_the_wheels_and_drifts_by_its_bias():
    """With R-hat 1 % too large the encoders' heading gains 1 % of every turn; a gyro's stays exact (no noise, no
    bias), or drifts by exactly bias t, and its yaw rate reads omega + bias. The distance still comes from the
    encoders: 1 % too long either way."""
    nominal = RobotParams(wheel_radius=1.01 * PARAMS.wheel_radius)
    wheels = odometry_run(0, nominal, (0.3, 2.0))
    theta = np.asarray(wheels.state[:, 2])
    np.testing.assert_allclose(wheels.logs["odom_etheta"], 0.01 * theta, rtol=1e-9, atol=1e-15)
    exact = gyro_run(nominal, 0.0, 0.0)
    np.testing.assert_allclose(exact.logs["odom_etheta"], 0.0, atol=1e-12)
    assert theta[-1] > 3.5  # past pi: the turn of each period is taken the short way round
    bias = 1e-3
    biased = gyro_run(nominal, 0.0, bias)
    np.testing.assert_allclose(biased.logs["odom_etheta"], bias * T * np.arange(len(theta)), atol=1e-12)
    np.testing.assert_allclose(biased.plant_state["odom_omega"][1:], 2.0 + bias, rtol=1e-9)
    np.testing.assert_allclose(biased.plant_state["odom_v"][1:], 1.01 * 0.3, rtol=1e-9)


def test_a_noisy_gyro_heading_walks_randomly_with_its_density():
    """White rate noise of density N integrates to a heading error of variance N^2 t, each seed its own walk."""
    density, runs = 0.05, 300
    keys = jax.random.split(jax.random.PRNGKey(11), runs)
    final = np.array([float(gyro_run(PARAMS, density, 0.0, key).logs["odom_etheta"][-1]) for key in keys])
    elapsed = T * (N - 1)
    assert np.var(final) == pytest.approx(density**2 * elapsed, rel=0.25)  # 300 runs: the variance to 8 %
    assert abs(np.mean(final)) < 4 * density * math.sqrt(elapsed / runs)
    assert len(set(final.tolist())) == runs


@pytest.mark.slow
def test_odometry_on_a_plant_with_its_own_integrator_follows_the_same_wheels():
    """A plant that brings its own ``advance`` gets its wheel angles by the trapezoid rule, step by step; on the
    paper's robot (an ODE plant, integrated with its state) the two agree closely."""

    @pytree_dataclass
    class OwnStepper:
        inner: DynamicPlant
        state_layout: ClassVar = DynamicPlant.state_layout
        input_layout: ClassVar = DynamicPlant.input_layout
        logged_layout: ClassVar = DynamicPlant.logged_layout
        input_kind: ClassVar[str] = "torque"

        def init(self, body):
            return body

        def saturate(self, u):
            return self.inner.saturate(u)

        def advance(self, x, u, d, period, solver):
            return self.inner.advance(x, u, d, period, solver)

        def observe(self, x):
            return x

        def logged(self, x, u):
            return self.inner.logged(x, u)

    @pytree_dataclass
    class WithAngles(DynamicPlant):
        """The paper's robot with its wheel angles as states of its own (as the example plugin's plant has)."""

        state_layout: ClassVar = Layout((*BODY.names, "phi_r", "phi_l"), (*BODY.units, "rad", "rad"))

        def init(self, body):
            return jnp.concatenate([body, jnp.zeros(2)])

        def observe(self, x):
            return x[:5]

        def derivative(self, x, u, d):
            return jnp.concatenate([super().derivative(x[:5], u, d), wheel_speeds(self.params, x[3:5])])

    ode = run(sensed(DynamicPlant(PARAMS), odometry=True))
    own = run(sensed(OwnStepper(DynamicPlant(PARAMS)), odometry=True))
    np.testing.assert_allclose(own.plant_state["phi_r"], ode.plant_state["phi_r"], rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(own.logs["odom_ex"], ode.logs["odom_ex"], atol=1e-6)
    angles = sensed(WithAngles(PARAMS), odometry=True)
    assert angles.state_layout.names.count("phi_r") == 1  # odometry reads the plant's own angles
    with_angles = run(angles)
    np.testing.assert_allclose(with_angles.plant_state["phi_r"], ode.plant_state["phi_r"], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(with_angles.logs["odom_ex"], ode.logs["odom_ex"], rtol=1e-9, atol=1e-15)


def test_a_sensed_plant_is_a_plant_with_named_states():
    plant = sensed(DynamicPlant(PARAMS), delay=1.5 * T, measurement=2 * T, odometry=True)
    assert isinstance(plant, SensedPlant) and plant.input_kind == "torque"
    names = plant.state_layout.names
    # the inner state, the wheel angles, the estimate, the command queue (1.5 periods: 2 commands, padded to the
    # queue's least capacity), the measurement line (2 periods: 2 readings, padded to the same least capacity)
    assert names[:5] == ("x", "y", "theta", "v", "omega") and len(names) == 5 + 2 + 5 + QUEUE_BUCKET * (2 + 5)
    assert plant.recorded_layout.names == names[:12]
    x0 = plant.init(jnp.asarray([1.0, 2.0, 0.5, 0.0, 0.0]))
    assert x0.shape == (len(names),)
    np.testing.assert_array_equal(plant.measure(x0), plant.observe(x0))  # the estimate starts at the truth


# --- scenarios ---------------------------------------------------------------------------------------------------

BURGER = SCENARIOS / "burger_cmd_vel_figure8.toml"
#: the shipped scenario, short and on the unicycle (its motors' plant is pinned by tests/test_golden.py): compiles fast
SHORT = ["simulation.duration=4", "simulation.metric_window=[0, 4]", "plant.model=unicycle"]


@pytest.mark.slow
def test_a_run_with_odometry_scores_the_true_pose_and_records_the_estimate_error(cli, tmp_path):
    out = tmp_path / "run"
    code, _, err = cli("run", BURGER, *[a for s in SHORT for a in ("--set", s)], "--out", out)
    assert code == 0, err
    metrics = json.loads((out / "metrics.json").read_text())
    columns = pq.read_table(out / "timeseries.parquet").to_pydict()
    columns = {name: np.asarray(values, dtype=float) for name, values in columns.items()}
    assert not any(name.startswith(("queued", "delayed")) for name in columns)
    # the errors and e_tr are against the true pose; the estimate is its own column, off the truth
    np.testing.assert_allclose(columns["e_tr"], np.hypot(columns["e_x"], columns["e_y"]))
    np.testing.assert_allclose(columns["odom_ex"], columns["odom_x"] - columns["x"], atol=1e-12)
    np.testing.assert_allclose(columns["odom_etheta"], columns["odom_theta"] - columns["theta"], atol=1e-12)
    assert np.max(np.abs(columns["odom_ex"])) > 1e-4  # the 1 % radius error shows
    position = np.hypot(columns["odom_ex"], columns["odom_ey"])
    assert metrics["odom_error_final"] == pytest.approx(position[-1])
    assert metrics["odom_error_max"] == pytest.approx(position.max())
    assert metrics["status"] == "ok" and metrics["e_tr_max"] < 0.1


@pytest.mark.parametrize(
    ("override", "field"),
    [
        ("sensing.actuation_delay=-0.01", "sensing.actuation_delay"),
        ("sensing.actuation_delay=60", "sensing.actuation_delay"),
        ("sensing.measurement_delay=0.07", "sensing.measurement_delay"),
        ("sensing.encoder_counts=-1", "sensing.encoder_counts"),
        ("sensing.fix_period=0.125", "sensing.fix_period"),
        ("sensing.fix_gain=0", "sensing.fix_gain"),
        ("sensing.measurement_delay=50.05", "sensing.measurement_delay"),  # 1001 periods: over the limit
    ],
)
def test_bad_sensing_keys_are_refused_naming_the_field(cli, tmp_path, override, field):
    with pytest.raises(ConfigError) as refused:
        ddtrack.load_scenario(BURGER, overrides=[override])
    assert refused.value.field == field
    code, _, err = cli("validate", BURGER, "--set", override)
    assert code == 2 and field in err


@pytest.mark.parametrize("override", ["sensing.encoder_counts=1024", "sensing.fix_period=1", "sensing.heading=gyro"])
def test_encoders_or_a_fix_without_odometry_are_refused(override):
    with pytest.raises(ConfigError) as refused:
        ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=[override])
    assert refused.value.field == override.split("=")[0] and "odometry" in refused.value.suggestion


def test_odometry_turns_as_the_robot_s_own_does_and_a_gyro_without_numbers_is_refused(cli):
    """A TurtleBot3 preset's odometry takes its heading from the OpenCR's gyro (use_imu), with the datasheet's noise;
    ``sensing.heading`` overrides it; a gyro on a robot with no preset gyro must be given its numbers."""
    from ddtrack.robots import OPENCR_MPU9250

    chain = build(ddtrack.load_scenario(BURGER)).sensing
    assert chain.gyro and (chain.gyro_noise_density, chain.gyro_bias) == (
        OPENCR_MPU9250.noise_density,
        OPENCR_MPU9250.bias,
    )
    assert not build(ddtrack.load_scenario(BURGER, overrides=["sensing.heading=encoders"])).sensing.gyro
    given = ["sensing.gyro_noise_density=0.001", "sensing.gyro_bias=-0.002"]
    chain = build(ddtrack.load_scenario(BURGER, overrides=given)).sensing
    assert (chain.gyro_noise_density, chain.gyro_bias) == (0.001, -0.002)
    line = ["sensing.odometry=true", "sensing.heading=gyro"]
    with pytest.raises(ConfigError) as refused:
        ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=line)
    assert refused.value.field == "sensing.gyro_noise_density" and "0 for an ideal gyro" in refused.value.suggestion
    code, _, err = cli("validate", SCENARIOS / "paper_line.toml", *(a for o in line for a in ("--set", o)))
    assert code == 2 and "sensing.gyro_noise_density" in err and "Traceback" not in err
    ideal = ddtrack.load_scenario(
        SCENARIOS / "paper_line.toml", overrides=[*line, "sensing.gyro_noise_density=0", "sensing.gyro_bias=0"]
    )
    assert build(ideal).sensing.gyro


def test_each_seed_draws_its_own_gyro_noise():
    """The Burger scenario draws nothing else at random, so two seeds differ only by the gyro's noise (a fixed key
    for every seed once made them the same run)."""
    from ddtrack.runner import run as run_scenario

    gyro = ["sensing.gyro_noise_density=0.01", "sensing.gyro_bias=0"]
    scenario = ddtrack.load_scenario(BURGER, overrides=[*SHORT, *gyro])
    first, second, again = (np.asarray(run_scenario(scenario, seed=s).logs["odom_etheta"]) for s in (0, 1, 0))
    assert not np.array_equal(first, second) and np.array_equal(first, again)
    assert np.abs(first).max() > 1e-3  # the noise shows: 0.01 rad/sqrt(s) over 4 s walks about 0.02 rad


@pytest.mark.slow
def test_a_batch_and_the_environment_see_the_sensing_chain():
    from ddtrack.envs import DiffDriveTrackingEnv
    from ddtrack.runner import row, run_batch
    from ddtrack.runner import run as run_scenario
    from ddtrack.studies.batches import monte_carlo

    fix = ["sensing.fix_period=0.5", "sensing.fix_position_std=0.01", "sensing.fix_heading_std=0.01"]
    scenario = ddtrack.load_scenario(BURGER, overrides=[*SHORT, *fix])
    rows = monte_carlo(scenario, [0, 1], chunk_size=2)
    assert all(row["status"] == "ok" and row["odom_error_max"] > 0 for row in rows)
    assert rows[0]["odom_error_final"] != rows[1]["odom_error_final"]  # each seed draws its own fixes
    alone, batch = run_scenario(scenario, seed=1), row(run_batch(scenario, [0, 1]), 1)
    for a, b in zip(jax.tree_util.tree_leaves(alone), jax.tree_util.tree_leaves(batch), strict=True):
        np.testing.assert_array_equal(a, b)  # a batch's row is the run alone, bit for bit
    env = DiffDriveTrackingEnv(scenario, action_mode="gains")
    env.reset(seed=0)
    assert isinstance(env._episode.loop.plant, SensedPlant)
    _, _, terminated, _, _ = env.step(np.zeros(3))
    assert not terminated


def test_a_delay_given_directly_gets_a_queue_that_holds_it():
    # built without the [sensing] section (as a user's script may), a delay of 2 periods still delays: the queue
    # it needs (16 commands, padded) comes with it; a queue given too short for its delay is refused
    plant = SensedPlant(DynamicPlant(PARAMS), 0.033, 0.08, 0.033, 0.08, command_periods=2)
    assert plant.queue_length == QUEUE_BUCKET
    x = plant.init(jnp.zeros(5))
    acting = []
    for k in range(4):  # period k sends (k + 1, k + 1); what acts was sent 2 periods before (the queue starts at 0)
        u = jnp.full(2, k + 1.0)
        acting.append(float(plant.stretches(x, u)[1][0][0][0]))
        x = plant.advance(x, u, jnp.zeros(2), T, RK4(2))
    assert acting == [0.0, 0.0, 1.0, 2.0]
    with pytest.raises(ValueError, match="cannot hold a delay of 3 periods"):
        SensedPlant(DynamicPlant(PARAMS), 0.033, 0.08, 0.033, 0.08, command_periods=3, queue_capacity=2)
