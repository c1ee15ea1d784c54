"""Presets by name in a scenario (``[robot] preset``): the preset's numbers fill [robot], a key the file gives wins,
the resolved scenario reads back the same, a misspelt name is a ConfigError, and ``ddtrack list robots`` shows them."""

from __future__ import annotations

import tomllib

import pytest
import tomli_w
from conftest import SCENARIOS
from test_schema import schema_errors

import ddtrack
from ddtrack import robots
from ddtrack.errors import ConfigError
from ddtrack.feasibility import check
from ddtrack.scenario import to_toml_dict, validate_scenario
from ddtrack.schema import scenario_schema

MINIMAL = {"name": "p", "trajectory": {"kind": "line", "speed": 0.1}, "controller": {"max_velocity": 0.22}}


def with_robot(**robot: object) -> dict:
    return {**MINIMAL, "robot": robot}


@pytest.mark.parametrize("name", sorted(robots.PRESETS))
def test_a_preset_gives_exactly_its_numbers(name):
    found = robots.preset(name)
    scenario = validate_scenario(with_robot(preset=name))
    assert scenario.robot.preset == name
    assert scenario.robot.params() == found.robot_params()  # every field the preset has, the rest default
    assert scenario.robot.wheel_inertia == found.wheel_inertia
    assert scenario.plant_params() == found.robot_params()  # [plant] takes the [robot] values


def test_a_key_given_in_the_file_wins_and_the_plant_still_overrides():
    burger = robots.TURTLEBOT3_BURGER
    scenario = validate_scenario({**with_robot(preset=burger.name, mass=1.5), "plant": {"inertia": 0.003}})
    assert scenario.robot.mass == 1.5
    assert scenario.robot.inertia == burger.params["inertia"] and scenario.robot.half_axle == 0.08
    assert scenario.plant_params().mass == 1.5 and scenario.plant_params().inertia == 0.003


@pytest.mark.parametrize("robot", [{"preset": "pioneer_3dx"}, {"preset": "turtlebot3_burger", "max_torque": 1.0}])
def test_the_resolved_scenario_reads_back_the_same(robot, tmp_path):
    scenario = validate_scenario(with_robot(**robot))
    resolved = to_toml_dict(scenario)
    assert resolved["robot"]["preset"] == robot["preset"]  # where the numbers came from
    assert resolved["robot"]["mass"] == robots.preset(robot["preset"]).params["mass"]  # and the numbers
    assert schema_errors(scenario_schema(), scenario_schema(), resolved) == []
    path = tmp_path / "scenario.toml"
    path.write_text(tomli_w.dumps(resolved))  # as `ddtrack run` writes it
    assert ddtrack.load_scenario(path) == scenario


def test_a_misspelt_preset_names_the_field_and_the_closest_name():
    with pytest.raises(ConfigError) as caught:
        validate_scenario(with_robot(preset="turtlebot3_burgr"))
    assert caught.value.field == "robot.preset"
    assert "unknown robot preset 'turtlebot3_burgr'" in caught.value.message
    assert caught.value.suggestion == "did you mean 'turtlebot3_burger'?"
    with pytest.raises(ConfigError, match="robot.preset"):
        validate_scenario(with_robot(preset=3))


def test_a_misspelt_preset_exits_2_and_writes_nothing(cli, tmp_path):
    out = tmp_path / "run"
    code, stdout, stderr = cli("run", SCENARIOS / "circle.toml", "--set", "robot.preset=pioner_3dx", "--out", out)
    assert code == 2 and stdout == "" and "Traceback" not in stderr
    assert "robot.preset: unknown robot preset 'pioner_3dx'" in stderr and "did you mean 'pioneer_3dx'?" in stderr
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_a_preset_can_be_set_on_the_command_line():
    scenario = ddtrack.load_scenario(SCENARIOS / "circle.toml", overrides=["robot.preset=pioneer_3dx"])
    assert scenario.robot.params() == robots.PIONEER_3DX.robot_params()
    assert scenario.plant_params().mass == 12.0  # circle.toml's [plant] still overrides


def test_list_robots_shows_every_preset(cli):
    code, stdout, _ = cli("list", "robots")
    lines = stdout.splitlines()
    assert code == 0 and lines[0] == "robots:" and len(lines) == 1 + len(robots.PRESETS)
    for line, found in zip(lines[1:], robots.PRESETS.values(), strict=True):
        assert line.split()[0] == found.name and found.description in line
    assert "top speed 0.197 m/s, 2.46 rad/s" in stdout  # the Burger's, from its servo's no-load speed
    code, stdout, _ = cli("list")
    assert code == 0 and "robots:" in stdout and "pioneer_3dx" in stdout and "controllers:" in stdout


def test_a_reference_beyond_the_robot_is_warned_and_nothing_changed():
    faster = with_robot(preset="turtlebot3_burger")
    faster |= {"trajectory": {"kind": "circle", "radius": 0.1, "speed": 0.3}, "controller": {"max_velocity": 1.0}}
    scenario = validate_scenario(faster)
    assert scenario.controller.max_velocity == 1.0  # the controller's clamp stays as the file sets it
    warnings = check(scenario)  # 0.3 m/s against 0.197, 3 rad/s against 2.46
    assert [w["code"] for w in warnings] == ["reference_beyond_robot"] * 2
    assert (
        "0.3 m/s, above the top speed of a turtlebot3_burger (robot.preset), its motors at 11.1 V, 0.197 m/s"
        in warnings[0]["message"]
    )
    assert "3 rad/s, above the top yaw rate" in warnings[1]["message"]
    assert check(validate_scenario(with_robot(preset="turtlebot3_burger"))) == []  # 0.1 m/s is within 0.197
    assert check(validate_scenario({**faster, "robot": {"mass": 1.0, "inertia": 0.004, "half_axle": 0.08}})) == []
    assert check(validate_scenario({**faster, "robot": {"preset": "paper"}})) == []  # no top speed published


def test_a_shipped_scenario_runs_on_a_preset():
    scenario = ddtrack.load_scenario(
        SCENARIOS / "circle.toml",
        overrides=["robot.preset=turtlebot3_burger", "simulation.duration=2", "simulation.metric_window=[0, 2]"],
    )
    assert scenario.robot.params() == robots.TURTLEBOT3_BURGER.robot_params()
    result = ddtrack.run(scenario)
    warnings = check(scenario)
    # circle.toml's 0.5 m/s is more than the Burger's 0.197 m/s: the run goes on, and says so
    assert [w["code"] for w in warnings] == ["reference_beyond_robot"] and "0.5 m/s" in warnings[0]["message"]
    assert result.status_name == "ok"
    assert tomllib.loads(tomli_w.dumps(to_toml_dict(scenario)))["robot"]["preset"] == "turtlebot3_burger"


def test_the_top_speed_is_the_motors_at_the_scenario_s_supply_voltage():
    """The refusal of an open-loop plan and the reference's warning take the motors' no-load speed at
    ``[plant.motor] supply_voltage`` (with ROBOTIS' own limit, 0.22 m/s, above it): at 12.6 V the Burger's XL430s
    reach 0.224 m/s at the wheel, so a 0.21 m/s plan runs (it was refused against 11.1 V's 0.197); at 9 V they reach
    0.1597 m/s, so a 0.19 m/s plan is refused (it was accepted, and the robot reached 0.156)."""
    from ddtrack.model.motor_plants import motor_from_datasheet

    burger = robots.preset("turtlebot3_burger")
    motor = motor_from_datasheet(burger.motor)
    radius = burger.params["wheel_radius"]

    def plan(speed: float, volts: float) -> dict:
        data = with_robot(preset="turtlebot3_burger")
        data["plant"] = {"model": "motor_velocity", "motor": {"supply_voltage": volts}}
        data["controller"] = {"kind": "replay", "times": [0.0, 1.0], "commands": [[speed, 0.0], [0.0, 0.0]]}
        return data

    at_12_6 = validate_scenario(plan(0.21, 12.6))
    top, _, what = at_12_6.top_speeds()
    assert top == pytest.approx(min(0.22, 12.6 / 11.1 * float(motor.no_load_speed) * radius), rel=1e-12)
    assert top == pytest.approx(0.22) and "12.6 V" in what  # ROBOTIS' limit binds above 12.3 V
    with pytest.raises(
        ConfigError, match=r"0\.19 m/s, above the top speed of a turtlebot3_burger .* at 9 V, 0\.1597 m/s"
    ):
        validate_scenario(plan(0.19, 9.0))
    assert validate_scenario(plan(0.15, 9.0)).top_speeds()[0] == pytest.approx(9 / 11.1 * 0.197, rel=1e-2)
