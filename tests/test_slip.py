"""The traction-and-slip plant (docs/model.md §1.10): its no-slip limit, the grip limit on acceleration, the forces
of a steady turn, its integration rule and its scenario wiring."""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import SCENARIOS

import ddtrack
from ddtrack.integrators import RK4
from ddtrack.model import DynamicPlant, RobotParams, SlipPlant, slip_plant, slip_plant_model
from ddtrack.model.slip import GRAVITY, choose_integration, contact_stiffness
from ddtrack.model.traction import contact_forces
from ddtrack.robots import preset

PERIOD = 0.01  #: control period [s]
#: the paper's robot with geared wheels (J_w = 0.005 kg m^2) and a caster 0.3 m ahead of the axle
GEARED = RobotParams(wheel_inertia=0.005)
CASTER = 0.3


@partial(jax.jit, static_argnames=("substeps",))
def rollout(plant, x0, torques, substeps):
    """The plant's states after each period under the held wheel torques ``torques`` (n, 2), no disturbance."""

    def period(x, tau):
        x_next = plant.advance(x, plant.saturate(tau), jnp.zeros(2), PERIOD, RK4(substeps))
        return x_next, x_next

    return jax.lax.scan(period, x0, torques)[1]


def wavy_torques(n):
    """Smooth torques within any reasonable grip [N m], (n, 2)."""
    t = np.arange(n) * PERIOD
    return jnp.asarray(np.stack([1.0 + 0.5 * np.sin(2.0 * t), 0.6 + 0.5 * np.cos(3.0 * t)], axis=1))


@pytest.fixture(scope="module")
def no_slip_limit():
    """(no-slip states, {eps_s: slip states}) over 2 s of wavy torques on a floor of mu = 5, one compilation of
    the slip plant (Rosenbrock, 20 sub-steps) shared by both slip speeds."""
    torques, body0 = wavy_torques(200), jnp.zeros(5)
    reference = rollout(DynamicPlant(GEARED), body0, torques, 20)
    runs = {}
    for eps in (1e-2, 1e-3):
        plant = slip_plant(GEARED, friction=5.0, slip_speed=eps, scheme="rosenbrock", substeps=20)
        assert (plant.scheme, int(plant.substeps)) == ("rosenbrock", 20)
        runs[eps] = (plant, rollout(plant, plant.init(body0), torques, 20))
    return reference, runs


def test_the_slip_plant_converges_to_the_no_slip_plant_in_proportion_to_the_slip_speed(no_slip_limit):
    reference, runs = no_slip_limit
    gaps = {eps: float(np.max(np.hypot(*(states[:, :2] - reference[:, :2]).T))) for eps, (_, states) in runs.items()}
    assert float(np.max(np.abs(reference[:, 3]))) > 0.3  # it went somewhere
    assert gaps[1e-3] < 1e-3  # over about 9 m of travel
    assert 7.0 < gaps[1e-2] / gaps[1e-3] < 13.0  # the gap is proportional to eps_s


def test_its_contact_forces_in_the_no_slip_limit_are_the_recorded_motions(no_slip_limit):
    """model.traction.contact_forces reads the forces off (v, omega); the slip plant computes them from its slips."""
    _, runs = no_slip_limit
    plant, states = runs[1e-3]
    f_rx, f_ry, f_lx, f_ly = jax.vmap(plant.forces)(states)
    p = GEARED
    t = np.arange(len(states)) * PERIOD
    right, left, lateral = contact_forces(
        t,
        states[:, 3],
        states[:, 5],
        mass=p.mass,
        inertia_axle=p.inertia_axle,
        com_offset=p.com_offset,
        half_axle=p.half_axle,
    )

    def midpoint(f):  # the forward differences give a period's mean force
        return (np.asarray(f)[:-1] + np.asarray(f)[1:]) / 2.0

    for mine, theirs in ((f_rx, right), (f_lx, left), (f_ry + f_ly, lateral)):
        scale = float(np.max(np.abs(theirs)))
        assert scale > 1.0
        assert np.max(np.abs(midpoint(mine) - theirs[:-1])) < 0.01 * scale


def test_beyond_grip_the_robot_accelerates_at_most_mu_g_times_the_drive_wheels_load_share():
    """From rest, straight, both wheels at 3, 5 and 10 N m (grip ends near 2.3 N m): the along-track acceleration
    stays below mu g (1 - d / l_c) and approaches it as the torque rises."""
    mu = 0.8
    plant = slip_plant(GEARED, friction=mu, caster=CASTER, period=PERIOD, substeps=10)
    assert plant.scheme == "rk4"
    levels = jnp.asarray([3.0, 5.0, 10.0])
    torques = levels[:, None, None] * jnp.ones((1, 50, 2))
    states = jax.vmap(lambda tau: rollout(plant, plant.init(jnp.zeros(5)), tau, int(plant.substeps)))(torques)
    limit = mu * GRAVITY * (1.0 - GEARED.com_offset / CASTER)
    speed = np.asarray(states[:, :, 3])
    acceleration = np.diff(speed, axis=1) / PERIOD
    assert np.all(acceleration <= limit * (1.0 + 1e-9))
    late = acceleration[:, -10:].mean(axis=1)
    assert late[0] < late[1] < late[2]
    assert late[2] > 0.99 * limit
    assert np.all(np.abs(np.asarray(states[:, :, 4:6])) < 1e-12)  # straight: no lateral speed, no yaw


TURNING = RobotParams(wheel_inertia=0.005, viscous_friction=0.05)  #: held on a circle against viscous wheel drag


def steady_turn(height: float = 0.0):
    """(plant, final state, held torques) of :data:`TURNING` after 4 s on a circle at v = 0.5 m/s, omega = 1 rad/s,
    held by the no-slip torques: wheel drag plus B_bar^-1 V_bar nu."""
    params, v, omega = TURNING, 0.5, 1.0
    plant = slip_plant(params, friction=0.8, caster=CASTER, period=PERIOD, substeps=10, com_height=height)
    m, d, half, radius = params.mass, params.com_offset, params.half_axle, params.wheel_radius
    coriolis = np.array([-m * d * omega**2, m * d * omega * v])
    held = 0.05 * np.array([v + half * omega, v - half * omega]) / radius
    held += radius / 2.0 * np.array([[1.0, 1.0 / half], [1.0, -1.0 / half]]) @ coriolis
    torques = jnp.broadcast_to(jnp.asarray(held), (400, 2))
    final = rollout(plant, plant.init(jnp.asarray([0.0, 0.0, 0.0, v, omega])), torques, int(plant.substeps))[-1]
    return plant, final, held


def test_a_steady_turn_loads_the_wheels_as_the_closed_forms_say():
    """A steady circle (v = 0.5 m/s, omega = 1 rad/s held against viscous wheel drag): the floor's lateral force is
    m v omega, and with d != 0 the wheels are loaded longitudinally by F_Rx = m d omega (v - L omega) / (2 L),
    F_Lx = -m d omega (v + L omega) / (2 L)."""
    plant, final, held = steady_turn()
    params, v, omega = TURNING, 0.5, 1.0
    m, d, half = params.mass, params.com_offset, params.half_axle
    u, r = float(final[3]), float(final[5])
    assert u == pytest.approx(v, rel=0.02) and r == pytest.approx(omega, rel=0.02)
    assert float(jnp.max(jnp.abs(plant.derivative(final, jnp.asarray(held), jnp.zeros(2))[3:]))) < 1e-3  # steady
    f_rx, f_ry, f_lx, f_ly = (float(f) for f in plant.forces(final))
    assert f_ry + f_ly == pytest.approx(m * u * r, abs=1e-3)
    # exactly, with the small lateral creep w the side force needs: F_Rx + F_Lx = -m (r w + d r^2), and the yaw
    # balance L (F_Rx - F_Lx) = d (F_Ry + F_Ly)
    assert f_rx + f_lx == pytest.approx(-m * (r * float(final[4]) + d * r**2), abs=1e-3)
    assert f_rx - f_lx == pytest.approx(d * m * u * r / half, abs=1e-3)
    # the no-slip closed forms, within the O(eps_s) creep
    assert f_rx == pytest.approx(m * d * r * (u - half * r) / (2.0 * half), rel=0.03)
    assert f_lx == pytest.approx(-m * d * r * (u + half * r) / (2.0 * half), rel=0.03)


def test_the_light_wheel_takes_the_rosenbrock_step_and_it_matches_fine_rk4():
    """The paper's 0.1 kg wheel (J_w = 1.25e-4 kg m^2) is too stiff for a few RK4 steps: the rule picks the
    Rosenbrock step, whose 20 sub-steps agree with 400 RK4 sub-steps per period within a micrometre."""
    params = RobotParams(wheel_inertia=0.5 * 0.1 * 0.05**2)
    plant = slip_plant(params, period=PERIOD, substeps=10)
    assert (plant.scheme, int(plant.substeps)) == ("rosenbrock", 20)
    torques, x0 = wavy_torques(50) * 0.5, plant.init(jnp.zeros(5))
    implicit = rollout(plant, x0, torques, int(plant.substeps))
    fine = rollout(SlipPlant(params, 0.8, 1e-2, jnp.inf, None, scheme="rk4", substeps=400), x0, torques, 400)
    assert float(jnp.max(jnp.abs(implicit[:, :2] - fine[:, :2]))) < 1e-6


def test_the_integration_rule_from_the_nominal_stiffness():
    burger = preset("turtlebot3_burger")
    params = RobotParams(**burger.params, wheel_inertia=burger.wheel_inertia)
    stiff = contact_stiffness(params, 0.8, 1e-2, burger.caster_position)
    scheme, steps = choose_integration(stiff, PERIOD, 10)
    assert scheme == "rk4" and steps == max(10, int(np.ceil(PERIOD * stiff / 2.0)))
    assert choose_integration(1e6, PERIOD, 10) == ("rosenbrock", 20)
    assert choose_integration(10.0, PERIOD, 10) == ("rk4", 10)


def test_the_slip_plant_needs_wheel_inertia_and_a_caster_beyond_the_centre_of_mass():
    with pytest.raises(ValueError, match="wheel_inertia J_w > 0"):
        slip_plant(RobotParams())
    with pytest.raises(ValueError, match="beyond the centre of mass"):
        slip_plant(GEARED, caster=-0.2)
    drawn = RobotParams(wheel_inertia=0.005, com_offset=0.4)  # a drawn robot past the nominal's caster
    with pytest.raises(ValueError, match="beyond the centre of mass"):
        slip_plant_model(GEARED, caster=CASTER)(drawn)


def test_init_and_observe_are_the_body_state_rolling_without_slip():
    plant = slip_plant(GEARED)
    x = plant.init(jnp.asarray([1.0, 2.0, 0.3, 0.5, 1.0]))
    assert np.allclose(x, [1.0, 2.0, 0.3, 0.5, 0.0, 1.0, 15.0, 5.0])
    assert np.allclose(plant.observe(x), [1.0, 2.0, 0.3, 0.5, 1.0])
    assert np.allclose(plant.slips(x), 0.0)


BURGER = [
    'robot.preset="turtlebot3_burger"',
    "plant.model=slip",
    "plant.com_offset=-0.01",  # the preset's caster is behind the axle: the centre of mass must be too
    "simulation.duration=1",
    "simulation.metric_window=[0, 1]",
]


@pytest.mark.slow
def test_a_turtlebot_runs_on_the_slip_plant_from_the_command_line(tmp_path, cli):
    out = tmp_path / "run"
    code, _, stderr = cli(
        "run",
        SCENARIOS / "burger_sized_20hz.toml",
        "--controller",
        "backstepping",
        "--out",
        out,
        *(arg for key in BURGER for arg in ("--set", key)),
    )
    assert code == 0, stderr
    import pyarrow.parquet as pq

    columns = pq.read_table(out / "timeseries.parquet").column_names
    assert {"tau_r", "slip_r", "slip_lateral", "force_y", "w", "phidot_r"} <= set(columns)


@pytest.mark.slow
def test_on_a_slip_plant_the_grip_reported_is_what_its_own_contact_forces_used(tmp_path, cli):
    """At mu = 0.01 the wheels slide: the run reports the friction its contact forces used (never above mu) and
    the time it slid, not the no-slip formula's need and its "the wheels would slip"."""
    out = tmp_path / "run"
    sets = (arg for key in [*BURGER, "plant.floor_friction=0.01"] for arg in ("--set", key))
    code, _, stderr = cli(
        "run", SCENARIOS / "burger_sized_20hz.toml", "--controller", "backstepping", *sets, "--out", out
    )
    assert code == 0, stderr
    import json

    import pyarrow.parquet as pq

    metrics = json.loads((out / "metrics.json").read_text())
    assert "mu_required_max" not in metrics and "friction_exceeds_floor" not in stderr
    assert 0.0099 < metrics["mu_used_max"] <= 0.01 and metrics["time_sliding"] > 0.5  # slid most of the 1 s
    table = pq.read_table(out / "timeseries.parquet")
    c = {name: table.column(name).to_numpy() for name in table.column_names}
    assert np.all(c["mu_used"] <= 0.01) and np.mean(c["sliding"]) * 1.0 == pytest.approx(metrics["time_sliding"])
    # the plant's own force on the wheel that slides harder, F_ix = -mu N_i s_ix / sqrt(|s_i|^2 + eps^2), against the
    # reported use: mu_used N_i |s_ix| / |s_i| = |F_ix|, with the wheel's logged load N_i
    slides = np.hypot([c["slip_r"], c["slip_l"]], c["slip_lateral"])
    harder = np.argmax(slides, axis=0)
    along = np.choose(harder, [c["slip_r"], c["slip_l"]])
    force = np.choose(harder, [c["force_rx"], c["force_lx"]])
    normal = np.choose(harder, [c["normal_r"], c["normal_l"]])
    checked = np.abs(along) > 1e-6
    implied = c["mu_used"][checked] * normal[checked] * np.abs(along[checked]) / slides.max(axis=0)[checked]
    assert checked.sum() > 15 and np.abs(force[checked]) == pytest.approx(implied, rel=1e-9)
    # the loads: the static share m g (1 - d / l_c) / 2, moved by the Burger's centre of mass 3 cm up as it brakes
    scenario = ddtrack.load_scenario(SCENARIOS / "burger_sized_20hz.toml", overrides=BURGER, controller="backstepping")
    params = scenario.plant_params()
    from ddtrack.model.slip import load_fraction

    static = params.mass * GRAVITY * float(load_fraction(params, preset("turtlebot3_burger").caster_position)) / 2
    total = c["normal_r"] + c["normal_l"]
    height, caster = preset("turtlebot3_burger").com_height, preset("turtlebot3_burger").caster_position
    moved = height * (c["force_rx"] + c["force_lx"]) / caster  # h F_x / l_c onto both drive wheels
    assert total == pytest.approx(2 * static + moved, rel=1e-9) and np.ptp(total) > 1e-4 * static


@pytest.mark.parametrize(
    ("scenario", "overrides", "field"),
    [
        ("paper_line.toml", ["plant.model=slip"], "plant.wheel_inertia"),
        ("burger_sized_20hz.toml", [*BURGER[:2], "plant.com_offset=0.01"], "plant.caster_position"),
    ],
)
def test_bad_slip_input_exits_2_naming_the_field(tmp_path, cli, scenario, overrides, field):
    sets = (arg for key in overrides for arg in ("--set", key))
    code, _, stderr = cli("run", SCENARIOS / scenario, "--controller", "backstepping", *sets, "--out", tmp_path / "o")
    assert code == 2 and stderr.startswith(f"error: {field}")


def test_the_scenario_reads_the_floor_and_the_motor():
    scenario = ddtrack.load_scenario(
        SCENARIOS / "burger_sized_20hz.toml",
        overrides=[*BURGER, "plant.floor_friction=0.5", "plant.slip_speed=0.02"],
        controller="backstepping",
    )
    from ddtrack.runner import prepare

    plant = prepare(scenario)[0].plant
    assert isinstance(plant, SlipPlant) and plant.motor is not None
    assert (float(plant.friction), float(plant.slip_speed)) == (0.5, 0.02)
    assert float(plant.caster) == preset("turtlebot3_burger").caster_position


def test_the_rosenbrock_step_is_second_order_and_damps_a_stiff_mode():
    """ROS2 on x_dot = A x: the error over 1 s falls 4x per halving of the step; a mode of rate 1e6 1/s stepped at
    h = 0.1 s decays instead of blowing up; the unrolled factors solve as NumPy does."""
    from ddtrack.integrators import lu_solve_unpivoted, lu_unpivoted, rosenbrock2

    a = jnp.asarray([[-1.0, 0.5], [-0.5, -0.2]])
    exact = jax.scipy.linalg.expm(a) @ jnp.ones(2)
    errors = [float(jnp.max(jnp.abs(rosenbrock2(lambda x: a @ x, jnp.ones(2), 1.0, n) - exact))) for n in (20, 40)]
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.1)
    stiff = rosenbrock2(lambda x: jnp.asarray([-1e6, -1.0]) * x, jnp.ones(2), 1.0, 10, stiff=(0, 1))
    assert abs(float(stiff[0])) < 1e-3 and float(stiff[1]) == pytest.approx(np.exp(-1.0), rel=1e-2)
    matrix = jnp.asarray(np.eye(5) * 3.0 + np.random.default_rng(0).uniform(-0.5, 0.5, (5, 5)))
    b = jnp.arange(5.0)
    assert np.allclose(lu_solve_unpivoted(lu_unpivoted(matrix), b), np.linalg.solve(matrix, b), rtol=1e-12)


# --- load transfer (centre of mass above the floor) ------------------------------------------------------------------

HIGH = 0.2  #: an exaggerated height of the centre of mass [m], so the transfer shows


def test_loads_balance_the_moments_about_the_centre_of_mass():
    """Whatever the motion, the body neither rolls nor pitches: the moments about the centre of mass C = (d, 0, h) of
    the wheels' loads and floor forces and of the caster's load cancel, and the three loads carry the weight. Solved
    here for (N_R, N_L, N_caster) from those three equations, apart from the plant's closed form."""
    plant = slip_plant(GEARED, friction=0.8, caster=CASTER, period=PERIOD, substeps=10, com_height=HIGH)
    states = rollout(plant, plant.init(jnp.zeros(5)), 6.0 * wavy_torques(150), int(plant.substeps))
    m, d, half = GEARED.mass, GEARED.com_offset, GEARED.half_axle
    centre = np.array([d, 0.0, HIGH])
    points = np.array([[0.0, -half, 0.0], [0.0, half, 0.0], [CASTER, 0.0, 0.0]]) - centre  # right, left, caster
    moved = 0.0
    for x in states[::10]:
        f_rx, f_ry, f_lx, f_ly = (float(f) for f in plant.forces(x))
        # moment of (F_x, F_y, N) at r: x component r_y N - r_z F_y, y component r_z F_x - r_x N
        rows = [[1.0, 1.0, 1.0], [p[1] for p in points], [-p[0] for p in points]]
        known = [
            m * GRAVITY,
            points[0][2] * f_ry + points[1][2] * f_ly,
            -(points[0][2] * f_rx + points[1][2] * f_lx),
        ]
        loads = np.linalg.solve(np.array(rows), np.array(known))
        assert [float(n) for n in plant.normals(x)] == pytest.approx(loads[:2], rel=1e-9)
        moved = max(moved, abs(loads[0] - loads[1]) / loads[:2].sum())
    assert moved > 0.05  # the run did move load between the wheels


def test_beyond_grip_load_transfer_raises_the_acceleration_to_its_closed_form():
    """Straight ahead beyond grip with the caster ahead, accelerating moves load onto the drive wheels: m a = mu N_w,
    N_w = m g (1 - d / l_c) + m h a / l_c, so a = mu g (1 - d / l_c) / (1 - mu h / l_c) (h = 0: the static limit)."""
    mu = 0.8
    plant = slip_plant(GEARED, friction=mu, caster=CASTER, period=PERIOD, substeps=10, com_height=HIGH)
    torques = 10.0 * jnp.ones((50, 2))
    speed = np.asarray(rollout(plant, plant.init(jnp.zeros(5)), torques, int(plant.substeps))[:, 3])
    late = (np.diff(speed) / PERIOD)[-10:].mean()
    static = mu * GRAVITY * (1.0 - GEARED.com_offset / CASTER)
    assert late == pytest.approx(static / (1.0 - mu * HIGH / CASTER), rel=0.01)
    assert late > 1.3 * static


def test_a_steady_turn_loads_the_outer_wheel():
    """On a steady circle the side force m u r at height h moves m u r h / (2 L) from the inner (left) wheel to the
    outer (right); with h = 0 the loads are the static share, exactly."""
    m, d, half = TURNING.mass, TURNING.com_offset, TURNING.half_axle
    static = m * GRAVITY * (1.0 - d / CASTER) / 2.0
    for height in (0.0, HIGH):
        plant, final, _ = steady_turn(height)
        right, left = (float(n) for n in plant.normals(final))
        u, r = float(final[3]), float(final[5])
        if height == 0.0:
            assert (right, left) == (static, static)
        else:
            assert right - left == pytest.approx(m * u * r * height / half, rel=0.02)
            assert right > static > left


def test_a_wheel_that_would_lift_carries_nothing():
    """A centre of mass far too high for the turn: the inner wheel's load would go negative; it is held at 0."""
    plant = slip_plant(GEARED, friction=2.0, caster=CASTER, period=PERIOD, substeps=10, com_height=3.0)
    x = plant.init(jnp.asarray([0.0, 0.0, 0.0, 1.0, 0.0]))
    x = x.at[4].set(-0.5)  # sliding sideways at 0.5 m/s: the floor pushes back with up to mu N on each wheel
    right, left = (float(n) for n in plant.normals(x))
    assert min(right, left) == 0.0 and max(right, left) > 0.0
    columns = plant.logged(x, jnp.zeros(2))
    assert float(columns["normal_r"]) == right and float(columns["normal_l"]) == left


def test_the_preset_gives_the_height_and_plant_com_height_replaces_it():
    from ddtrack.scenario.slip_configs import slip_options

    burger = ddtrack.load_scenario(SCENARIOS / "burger_cmd_vel_figure8.toml", overrides=["plant.model=slip_velocity"])
    assert slip_options(burger)["com_height"] == preset("turtlebot3_burger").com_height > 0.02
    overrides = ["plant.model=slip_velocity", "plant.com_height=0.09"]
    given = ddtrack.load_scenario(SCENARIOS / "burger_cmd_vel_figure8.toml", overrides=overrides)
    assert slip_options(given)["com_height"] == 0.09
    paper = ddtrack.load_scenario(
        SCENARIOS / "circle.toml", overrides=["plant.model=slip", "plant.wheel_inertia=0.005"]
    )
    assert slip_options(paper)["com_height"] == 0.0  # no preset, no height: no load transfer
