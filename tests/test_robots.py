"""Presets of real robots (ddtrack.robots): each builds a valid model, its derived numbers follow from its sources,
and docs/robots.md shows the numbers the code holds."""

from __future__ import annotations

import dataclasses
import math

import pytest
from conftest import ROOT

from ddtrack import robots
from ddtrack.errors import ConfigError
from ddtrack.model import RobotParams

FIELDS = {f.name for f in dataclasses.fields(RobotParams)}
POSITIVE = ("mass", "inertia", "wheel_radius", "half_axle", "max_torque")


@pytest.mark.parametrize("name", sorted(robots.PRESETS))
def test_every_preset_builds_a_valid_robot(name):
    p = robots.preset(name)
    assert p.name == name
    params = RobotParams(**{k: v for k, v in p.params.items() if k in FIELDS})
    for field in POSITIVE:
        assert getattr(params, field) > 0.0, field
    assert params.viscous_friction >= 0.0 and params.coulomb_friction >= 0.0
    built = p.robot_params()
    assert all(getattr(built, k) == v for k, v in p.params.items() if k in FIELDS)
    assert p.wheel_inertia >= 0.0 and p.input in ("torque", "voltage", "velocity")
    if p.caster_position is not None:  # same side as the centre of mass, further out: 0 <= d / l_c < 1
        assert 0.0 <= p.params["com_offset"] / p.caster_position < 1.0
    if p.lag is not None:
        assert len(p.lag) == 6 and p.lag[0] > 0.0 and p.lag[1] > 0.0


@pytest.mark.parametrize("name", sorted(robots.PRESETS))
def test_every_number_has_a_source_or_a_reason(name):
    p = robots.preset(name)
    fields = list(p.values())
    assert {*p.params, "wheel_inertia", "max_speed", "motor", "lag", "odometry_heading"} <= set(fields)
    missing = [f for f in fields if not (p.sources.get(f) or p.assumptions.get(f))]
    assert missing == []
    assert set(p.sources) | set(p.assumptions) <= set(fields)  # no note on a field that does not exist


def test_the_paper_preset_is_the_model_default():
    assert robots.preset("paper").robot_params() == RobotParams()


def test_the_paper_robot_needs_a_floor_friction_of_about_4_at_its_torque_limit():
    # 10 N m on R = 0.05 m is 200 N per wheel; each wheel carries half of 10 kg
    mu = robots.preset("paper").friction_at_torque_limit()
    assert mu == pytest.approx(200.0 / (10.0 * 9.80665 / 2.0), rel=1e-12)
    assert 4.0 < mu < 4.2


def test_the_burger_top_speed_is_its_motor_no_load_speed():
    burger = robots.preset("turtlebot3_burger")
    from_datasheet = 57.0 * 2.0 * math.pi / 60.0 * 0.033  # 57 rpm at 11.1 V on a 33 mm wheel
    assert from_datasheet == pytest.approx(0.19698, abs=1e-5)
    assert burger.motor is not None
    assert burger.motor.no_load_speed * burger.params["wheel_radius"] == pytest.approx(from_datasheet, rel=1e-12)
    assert burger.max_speed == pytest.approx(from_datasheet, rel=1e-12)
    # ROBOTIS quotes 0.22 m/s: 10.5 % more than the motor reaches at 11.1 V, and more than at 12 V (61 rpm)
    assert 0.88 < burger.max_speed / 0.22 < 0.92
    assert 61.0 * 2.0 * math.pi / 60.0 * 0.033 < 0.22


def test_the_waffle_pi_is_bound_by_its_motor_below_the_quoted_speed():
    waffle = robots.preset("turtlebot3_waffle_pi")
    from_datasheet = 70.0 * 2.0 * math.pi / 60.0 * 0.033  # XM430-W210: 70 rpm at 11.1 V
    assert waffle.max_speed == pytest.approx(from_datasheet, rel=1e-12)
    assert waffle.max_speed < 0.26
    assert waffle.max_yaw_rate == pytest.approx(from_datasheet / (0.287 / 2.0), rel=1e-12)


def test_the_burger_yaw_inertia_is_the_parallel_axis_sum_of_its_urdf_links():
    # turtlebot3_burger.urdf: base_link at the axle midpoint, wheels at y = +-0.08 (yaw inertia = their iyy),
    # caster (5 g) at x = -0.081 and laser (114 g) at x = -0.032 as point masses
    m_base, i_base = 0.82573504, 2.0064271e-03
    m_wheel, i_wheel = 0.02849894, 1.1192413e-05
    m_caster, x_caster = 0.005, -0.081
    m_scan, x_scan = 0.114, -0.032
    m = m_base + 2 * m_wheel + m_caster + m_scan
    xc = (m_caster * x_caster + m_scan * x_scan) / m
    inertia = (
        i_base
        + m_base * xc**2
        + 2 * (i_wheel + m_wheel * (xc**2 + 0.08**2))
        + m_caster * (x_caster - xc) ** 2
        + m_scan * (x_scan - xc) ** 2
    )
    burger = robots.preset("turtlebot3_burger")
    assert burger.params["mass"] == pytest.approx(m, rel=1e-12)
    assert burger.params["mass"] == pytest.approx(1.0, rel=0.01)  # ROBOTIS: 1 kg
    assert burger.params["com_offset"] == pytest.approx(xc, rel=1e-12)
    assert burger.params["inertia"] == pytest.approx(inertia, rel=1e-12)
    assert burger.params["half_axle"] == 0.080 and burger.caster_position == -0.081


def test_the_waffle_pi_inertia_counts_both_casters_off_the_centre_line():
    links = robots.WAFFLE_PI_LINKS
    inertia = robots.composite_body(links)[2]
    on_axis = robots.composite_body(tuple(dataclasses.replace(link, y=0.0) for link in links))[2]
    wheels_and_casters = 2 * 0.02849894 * 0.144**2 + 2 * 0.005 * 0.064**2
    assert inertia - on_axis == pytest.approx(wheels_and_casters, rel=1e-9)
    assert robots.preset("turtlebot3_waffle_pi").params["inertia"] == inertia


def test_a_geared_servo_wheel_spins_several_times_the_robot_per_wheel():
    burger = robots.preset("turtlebot3_burger")
    per_wheel = burger.params["mass"] * burger.params["wheel_radius"] ** 2 / 2.0
    assert 3.0 < burger.wheel_inertia / per_wheel < 5.0


def test_the_pioneer_runs_the_identified_lag_model():
    pioneer = robots.preset("pioneer_3dx")
    assert pioneer.input == "velocity" and pioneer.lag == (0.2604, 0.2509, -0.0005, 0.9965, 0.0026, 1.0768)
    lag_v, lag_w = pioneer.lag[0] / pioneer.lag[3], pioneer.lag[1] / pioneer.lag[5]
    assert 0.2 < lag_v < 0.3 and 0.2 < lag_w < 0.3  # first-order lags of a quarter of a second
    assert pioneer.max_yaw_rate == pytest.approx(300.0 * math.pi / 180.0)


def test_a_misspelt_preset_name_says_which_was_meant():
    with pytest.raises(ConfigError, match="did you mean 'turtlebot3_burger'") as caught:
        robots.preset("turtlebot3_burgr")
    assert caught.value.field == "robot.preset"
    with pytest.raises(ConfigError, match="valid: "):
        robots.preset("roomba")


@pytest.mark.parametrize("name", sorted(robots.PRESETS))
def test_the_documentation_shows_the_numbers_the_code_holds(name):
    page = (ROOT / "docs" / "robots.md").read_text()
    assert robots.markdown_table(robots.preset(name)) in page


@pytest.mark.parametrize(
    ("name", "static", "needed"), [("turtlebot3_burger", 1.93, 7.33), ("turtlebot3_waffle_pi", 1.63, 1.99)]
)
def test_the_grip_needed_at_stall_counts_the_wheels_spin_inertia_and_the_load_moved(name, static, needed):
    """From rest at full torque, part of each wheel's torque spins the wheel itself up: the floor's push is the
    body's m a / 2 under the Lagrangian model (which carries the wheels' spin inertia), not tau / R. The TurtleBots'
    geared servos reflect 3.7 and 5.8 times the body's mass at the wheels, so over the static loads they need 1.93 and
    1.63, not the 9.09 and 11.1 that tau / R over the load gave. Accelerating at 18 and 15 m/s^2 moves load from the
    drive wheels onto the casters behind them (centre of mass 3.1 and 2.0 cm up): 7.33 and 1.99."""
    import jax.numpy as jnp

    from ddtrack.model.dynamics import body_acceleration

    found = robots.preset(name)
    params = dataclasses.replace(found.robot_params(), coulomb_friction=0.0)  # the torque itself, all of it
    stall = jnp.full(2, found.params["max_torque"])
    v_dot, omega_dot = body_acceleration(params, jnp.zeros(2), stall, jnp.zeros(2))
    push = found.params["mass"] * float(v_dot) / 2.0  # each wheel's share of m a
    assert abs(float(omega_dot)) < 1e-12  # straight ahead
    assert push / found.wheel_load() == pytest.approx(static, abs=0.005)
    # the slip plant's own loads: at rest the static share, and N_0 + h F_x / (2 l_c) with F_x = 2 push
    from ddtrack.model import slip_plant

    plant = slip_plant(params, caster=found.caster_position, com_height=found.com_height)
    assert float(plant.normals(plant.init(jnp.zeros(5)))[0]) == pytest.approx(found.wheel_load(), rel=1e-12)
    moved = found.wheel_load() + found.com_height * 2.0 * push / (2.0 * found.caster_position)
    assert found.accelerating_load(push) == pytest.approx(moved, rel=1e-12) and moved < found.wheel_load()
    assert found.friction_at_torque_limit() == pytest.approx(push / found.accelerating_load(push), rel=1e-12)
    assert found.friction_at_torque_limit() == pytest.approx(needed, abs=0.005)
