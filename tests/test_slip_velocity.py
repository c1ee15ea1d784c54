"""The velocity-commanded robot on a floor of finite grip (docs/model.md §1.10, the velocity-driven variant): its
no-slip limit is the ``motor_velocity`` plant, grip bounds its acceleration while the PI loop spins the wheels and
its integrals stay bounded, a batch row is the run alone, a preset without a motor is refused, and odometry drifts
more on a slippery floor."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack.integrators import RK4
from ddtrack.model import RobotParams, VelocityDriver, motor_from_datasheet
from ddtrack.model.slip import GRAVITY, load_fraction
from ddtrack.model.slip_velocity import SlipVelocityPlant, slip_velocity_model
from ddtrack.robots import preset
from ddtrack.runner import prepare, prepare_batch, run_setup

DURATION = 2.0  #: [s] of each closed-loop run
#: a TurtleBot3 Burger (its motors, wheel inertia and caster) over cmd_vel, the centre of mass on the caster's side
BURGER = [
    'robot.preset="turtlebot3_burger"',
    "plant.com_offset=-0.01",
    f"simulation.duration={DURATION}",
    f"simulation.metric_window=[0, {DURATION}]",
]
GRIP = ["plant.model=slip_velocity", "plant.floor_friction=3", "plant.slip_speed=0.01"]  #: the schema's top mu


def burger_scenario(*overrides: str):
    return ddtrack.load_scenario(
        SCENARIOS / "burger_sized_20hz.toml", overrides=[*BURGER, *overrides], controller="kinematic_backstepping"
    )


@pytest.fixture(scope="module")
def high_grip():
    """(scenario, setup, run) of the Burger on a floor of mu = 3 under kinematic backstepping."""
    scenario = burger_scenario(*GRIP)
    setup, draws = prepare(scenario)
    return scenario, setup, run_setup(scenario, setup, draws)


def test_with_high_grip_it_is_the_motor_velocity_plant(high_grip):
    """In the creep regime a wheel transmits F with the slip s = eps_s rho / sqrt(1 - rho^2), rho = |F| / (mu N):
    the body runs ahead or behind its wheels' rolling by s while the PI loop holds the spin. The position gap to
    the no-slip plant is then at most the integral of s, eps_s T rho_max / sqrt(1 - rho_max^2) (the controller
    acts on the pose and only shrinks it)."""
    _, setup, slipping = high_grip
    assert isinstance(setup.plant, SlipVelocityPlant)
    reference_scenario = burger_scenario("plant.model=motor_velocity")
    reference = run_setup(reference_scenario, *prepare(reference_scenario))
    columns = ddtrack.timeseries(slipping)
    params = setup.plant_params
    normal = float(params.mass * GRAVITY * load_fraction(params, setup.plant.slip.caster)) / 2.0
    rho = float(np.max(np.abs(np.stack([columns["force_rx"], columns["force_lx"]])))) / (3.0 * normal)
    assert 0.0 < rho < 0.5
    bound = 0.01 * DURATION * rho / np.sqrt(1.0 - rho**2)
    ours, theirs = np.asarray(slipping.state), np.asarray(reference.state)
    gap = float(np.max(np.hypot(*(ours[:, :2] - theirs[:, :2]).T)))
    assert float(np.max(np.abs(theirs[:, 3]))) > 0.1  # it went somewhere
    assert gap < bound
    # the loop's integrals track the no-slip plant's
    for name in ("pi_r", "pi_l"):
        scale = float(np.max(np.abs(reference.plant_state[name])))
        assert np.max(np.abs(np.asarray(slipping.plant_state[name]) - reference.plant_state[name])) < 0.02 * scale


def test_a_batch_row_is_the_run_alone(high_grip):
    scenario, _, alone = high_grip
    batch_setup, draws = prepare_batch(scenario, [0, 1])
    batch = run_setup(scenario, batch_setup, draws, batched=True)
    np.testing.assert_allclose(np.asarray(batch.state)[0], np.asarray(alone.state), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(batch.logs["slip_r"])[0], np.asarray(alone.logs["slip_r"]), atol=1e-12)


def step_response(driver: VelocityDriver, command: float, periods: int = 50, period: float = 0.01):
    """(plant, states, logged) of a Burger on mu = 0.4 from rest under the held straight command (command, 0)."""
    burger = preset("turtlebot3_burger")
    params = RobotParams(**burger.params, wheel_inertia=burger.wheel_inertia)
    plant = slip_velocity_model(params, driver, friction=0.4, caster=burger.caster_position, period=period)(params)
    u = jnp.asarray([command, 0.0])

    def one(x, _):
        x_next = plant.advance(x, u, jnp.zeros(2), period, RK4(int(plant.substeps)))
        return x_next, x_next

    x0 = plant.init(jnp.zeros(5))
    states = jnp.vstack([x0[None], jax.lax.scan(one, x0, None, length=periods)[1]])
    logged = jax.vmap(lambda x: plant.logged(x, u))(states)
    return plant, np.asarray(states), {k: np.asarray(v) for k, v in logged.items()}


def test_a_step_beyond_grip_slips_at_the_traction_limit_and_the_integrals_stay_bounded():
    """A 0.3 m/s step (beyond the Burger's 0.197 m/s no-load speed, so the voltage saturates throughout): the PI
    loop spins the wheels up at once, they slip, the body accelerates at most at mu g (1 - d / l_c); the integrals
    freeze on the voltage limit, where without anti-windup they wind up with the standing speed error."""
    burger = preset("turtlebot3_burger")
    motor = motor_from_datasheet(burger.motor)
    plant, states, logged = step_response(VelocityDriver(motor, 2.0, 50.0), 0.3)
    params = plant.params
    limit = 0.4 * GRAVITY * float(load_fraction(params, burger.caster_position))
    acceleration = np.diff(states[:, 3]) / 0.01
    assert np.all(acceleration <= limit * (1.0 + 1e-9))
    assert acceleration[0] > 0.9 * limit  # grip, not the motor, limits the start
    assert np.min(logged["slip_r"]) < -5.0 * float(plant.slip.slip_speed)  # the tyre slides back: the wheel spins
    assert np.allclose(logged["slip_r"], logged["slip_l"]) and np.max(np.abs(states[:, 4:6])) < 1e-12
    held = 1.01 * float(motor.supply_voltage) / 50.0  # k_i z stops at the supply voltage
    assert np.max(np.abs(states[:, 8:10])) < held
    _, wound, _ = step_response(VelocityDriver(motor, 2.0, 50.0, anti_windup=False), 0.3)
    assert np.max(np.abs(wound[:, 8:10])) > 2.0 * held


def test_a_preset_without_a_motor_exits_2_naming_plant_model_and_writes_nothing(tmp_path, cli):
    out = tmp_path / "run"
    sets = ['robot.preset="paper"', "plant.model=slip_velocity", "plant.wheel_inertia=0.005"]
    args = (arg for key in sets for arg in ("--set", key))
    code, _, stderr = cli(
        "run", SCENARIOS / "burger_sized_20hz.toml", "--controller", "kinematic_backstepping", *args, "--out", out
    )
    assert code == 2 and stderr.startswith("error: plant.model") and "'slip_velocity' needs the robot's motor" in stderr
    assert "turtlebot3_burger" in stderr  # the fix names the presets with motors
    assert not out.exists()


def test_under_the_sensing_chain_odometry_drifts_more_on_a_slippery_floor():
    """The wheels' encoders count their spin; the body's motion differs from it by the slip, which the smaller mu
    makes larger (mu N / eps_s is the creep's stiffness), so dead reckoning drifts more. Both floors take the
    sub-steps mu = 3 needs, so the two runs share one compilation."""
    drift = {}
    for mu in (3.0, 0.4):
        scenario = burger_scenario(
            *GRIP,
            f"plant.floor_friction={mu}",
            "sensing.actuation_delay=0.05",
            "sensing.odometry=true",
            "simulation.substeps=130",
        )
        setup, draws = prepare(scenario)
        result = run_setup(scenario, setup, draws)
        assert result.status_name == "ok"
        columns = ddtrack.timeseries(result)
        drift[mu] = float(np.max(np.hypot(columns["odom_ex"], columns["odom_ey"])))
        assert int(setup.plant.inner.substeps) == 130
    assert drift[0.4] > 3.0 * drift[3.0] > 0.0
