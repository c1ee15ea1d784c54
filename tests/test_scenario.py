"""Scenario validation: every malformed file ends with exit code 2, a message naming the field, and no output."""

from __future__ import annotations

import math
import re
import subprocess
import sys
import tomllib

import pytest
import tomli_w
from conftest import SCENARIOS

from ddtrack import ConfigError, load_scenario
from ddtrack.scenario import Scenario, apply_override, to_toml_dict, validate_scenario

PAPER_LINE = tomllib.loads((SCENARIOS / "paper_line.toml").read_text())


def _mutate(path: tuple[str, ...], value):
    data = tomllib.loads((SCENARIOS / "paper_line.toml").read_text())
    node = data
    for key in path[:-1]:
        node = node.setdefault(key, {})
    if value is _DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return data


_DELETE = object()

# (case id, mutation path, new value, field the message must name, a word the message must hold)
MALFORMED = [
    ("misspelt key", ("robot", "mas"), 10.0, "robot.mas", "did you mean 'mass'"),
    ("unknown section", ("robott",), {"mass": 1.0}, "robott", "did you mean 'robot'"),
    ("negative mass", ("robot", "mass"), -1.0, "robot.mass", "greater than 0"),
    ("zero inertia", ("plant", "inertia"), 0.0, "plant.inertia", "greater than 0"),
    ("zero wheel radius", ("robot", "wheel_radius"), 0.0, "robot.wheel_radius", "greater than 0"),
    ("nan", ("robot", "inertia"), math.nan, "robot.inertia", "finite"),
    ("inf", ("simulation", "duration"), math.inf, "simulation.duration", "finite"),
    ("string for number", ("simulation", "duration"), "long", "simulation.duration", "valid number"),
    ("bool for number", ("robot", "mass"), True, "robot.mass", "valid number"),
    ("zero time step", ("simulation", "control_period"), 0.0, "simulation.control_period", "greater than 0"),
    ("window outside run", ("simulation", "metric_window"), [20.0, 50.0], "simulation.metric_window", "duration"),
    ("duration not a multiple", ("simulation", "control_period"), 0.03, "simulation.duration", "multiple"),
    ("huge duration", ("simulation", "duration"), 1e300, "simulation.duration", "limit"),
    ("zero gain", ("controller", "gains"), [1.0, 0.0, 15.0], "controller.gains", "greater than 0"),
    ("two gains", ("controller", "gains"), [1.0, 55.0], "controller.gains", ""),
    ("unknown trajectory", ("trajectory", "kind"), "lin", "trajectory.kind", "did you mean 'line'"),
    ("unknown disturbance", ("disturbance", "kind"), "sinus", "disturbance.kind", "did you mean 'sinusoid'"),
    ("unknown inner loop", ("controller", "inner"), "computed_torq", "controller.inner", "computed_torque"),
    ("unknown controller", ("controller", "kind"), "backstep", "controller.kind", "backstepping"),
    ("missing required", ("disturbance", "frequency"), _DELETE, "disturbance.frequency", "required"),
    ("missing trajectory", ("trajectory",), _DELETE, "trajectory", "required"),
    ("negative speed", ("trajectory", "speed"), -0.5, "trajectory.speed", "greater than 0"),
    ("strict with pd", ("controller", "inner"), "pd", "controller.strict", "computed_torque"),
    (
        "waypoints times not increasing",
        ("trajectory",),
        {"kind": "waypoints", "points": [[0, 0], [1, 1], [2, 1]], "times": [0, 2, 2]},
        "trajectory.times",
        "point 2: t = 2 s is not after 2 s",
    ),
    (
        "waypoints missing file",
        ("trajectory",),
        {"kind": "waypoints", "file": "nope.csv"},
        "trajectory.file",
        "does not exist",
    ),
    (
        "randomize non-physical",
        ("randomize",),
        {"mass": {"distribution": "normal", "relative": 0.5}},
        "randomize.mass",
        "non-physical",
    ),
]


@pytest.mark.parametrize(("case", "path", "value", "field", "word"), MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_scenario_exits_2_naming_the_field(tmp_path, cli, case, path, value, field, word):
    data = _mutate(path, value)
    if case == "strict with pd":
        data["controller"]["strict"] = True
    scenario = tmp_path / "bad.toml"
    scenario.write_text(tomli_w.dumps(data) if not _has_nonfinite(data) else _dump_nonfinite(data))
    out = tmp_path / "out"
    code, _stdout, stderr = cli("run", scenario, "--out", out)
    assert code == 2
    assert re.match(rf"error: {re.escape(field)}(\[\d+\])*: ", stderr), stderr
    assert word in stderr
    assert len(stderr.strip().splitlines()) <= 2 and "Traceback" not in stderr
    assert not out.exists()  # nothing written, not even the folder


def _has_nonfinite(data) -> bool:
    return any(isinstance(v, float) and not math.isfinite(v) for v in _values(data))


def _values(node):
    if isinstance(node, dict):
        for v in node.values():
            yield from _values(v)
    else:
        yield node


def _dump_nonfinite(data) -> str:
    # tomli_w refuses nan/inf; TOML itself spells them nan and inf
    return tomli_w.dumps(_replace_nonfinite(data)).replace('"__nan__"', "nan").replace('"__inf__"', "inf")


def _replace_nonfinite(node):
    if isinstance(node, dict):
        return {k: _replace_nonfinite(v) for k, v in node.items()}
    if isinstance(node, float) and math.isnan(node):
        return "__nan__"
    if isinstance(node, float) and math.isinf(node):
        return "__inf__"
    return node


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        (b"name = \n", "not valid TOML"),
        (b"name = 'x'\n\xff\xfe[robot]\n", "not UTF-8"),
        (b"", "name: is required"),
    ],
)
def test_unreadable_files_exit_2(tmp_path, cli, content, needle):
    scenario = tmp_path / "bad.toml"
    scenario.write_bytes(content)
    code, _, stderr = cli("validate", scenario)
    assert code == 2 and needle in stderr and "Traceback" not in stderr


def test_missing_file_exits_2(tmp_path, cli):
    code, _, stderr = cli("run", tmp_path / "nope.toml", "--out", tmp_path / "out")
    assert code == 2 and "does not exist" in stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("override", "field"),
    [
        ("robot.mas=3", "robot.mas"),
        ("robot.mass=-3", "robot.mass"),
        ("robot.mass=heavy", "robot.mass"),
        ("robot", "--set"),
        ("name.first=1", "name"),
    ],
)
def test_bad_overrides_exit_2(tmp_path, cli, override, field):
    code, _, stderr = cli("run", SCENARIOS / "paper_line.toml", "--set", override, "--out", tmp_path / "out")
    assert code == 2 and stderr.startswith(f"error: {field}")
    assert not (tmp_path / "out").exists()


def test_console_script_prints_no_traceback(tmp_path):
    scenario = tmp_path / "bad.toml"
    scenario.write_text((SCENARIOS / "paper_line.toml").read_text().replace("mass = 10.0", "mass = -10.0"))
    proc = subprocess.run(
        [sys.executable, "-m", "ddtrack", "run", str(scenario), "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == "error: robot.mass: Input should be greater than 0 (got -10.0)"


def test_overrides_are_read_as_toml_values():
    data: dict = {}
    apply_override(data, "controller.gains=[2, 60, 10]")
    apply_override(data, "controller.inner=pd")
    apply_override(data, "robot.mass=12")
    assert data == {"controller": {"gains": [2, 60, 10], "inner": "pd"}, "robot": {"mass": 12}}


def test_plant_defaults_to_robot_and_overrides_apply():
    scenario = load_scenario(SCENARIOS / "paper_line.toml", overrides=["robot.half_axle=0.3", "plant.mass=15"], seed=7)
    plant = scenario.plant_params()
    assert plant.half_axle == 0.3 and plant.mass == 15.0 and plant.inertia == 0.70
    assert scenario.simulation.seed == 7


def test_resolved_scenario_round_trips(tmp_path):
    for path in sorted(SCENARIOS.glob("*.toml")):
        scenario = load_scenario(path)
        resolved = tomli_w.dumps(to_toml_dict(scenario))
        again = validate_scenario(tomllib.loads(resolved), base_dir=tmp_path)  # no file needed any more
        assert again == scenario, path.name


def test_waypoints_file_is_read_relative_to_the_scenario():
    scenario = load_scenario(SCENARIOS / "waypoints.toml")
    assert scenario.trajectory.file is None
    assert scenario.trajectory.points[0] == (0.0, 0.0) and len(scenario.trajectory.points) == 6


def test_a_waypoints_file_may_carry_comments_and_blank_lines(tmp_path):
    from ddtrack.scenario import read_waypoints

    path = tmp_path / "route.csv"
    path.write_text("# my lab's corridor, measured 2026-11-20\n#\n\nx,y\n0,0\n# the door\n4,0\n\n4,3\n")
    assert read_waypoints(path) == [(0.0, 0.0), (4.0, 0.0), (4.0, 3.0)]
    path.write_text("x,y\n0,0\ny,x\n")  # a second header after the points is an error, naming its line
    with pytest.raises(ValueError, match="line 3"):
        read_waypoints(path)


def test_every_section_rejects_unknown_keys():
    for section, _model in Scenario.model_fields.items():
        if section in ("name", "description", "trajectory", "disturbance", "controller"):
            continue
        with pytest.raises(ConfigError, match=rf"^{section}\.bogus: unknown key"):
            validate_scenario({"name": "x", "trajectory": {"kind": "line"}, section: {"bogus": 1}})


def test_scenario_reference_documents_every_key():
    from conftest import ROOT

    from ddtrack.scenario import (
        CONTROLLERS,
        DISTURBANCES,
        TRAJECTORIES,
        InitialConfig,
        NoiseConfig,
        ParameterDraw,
        RobotConfig,
        SensingConfig,
        SimulationConfig,
    )

    text = (ROOT / "docs" / "scenarios.md").read_text()
    models = [
        SimulationConfig,
        RobotConfig,
        ParameterDraw,
        NoiseConfig,
        SensingConfig,
        InitialConfig,
        *TRAJECTORIES.values(),
        *DISTURBANCES.values(),
        *CONTROLLERS.values(),
    ]
    for model in models:
        for key in model.model_fields:
            assert f"`{key}`" in text or key == "kind", f"{model.__name__}.{key} is not in docs/scenarios.md"
    for kind in [*TRAJECTORIES, *DISTURBANCES, *CONTROLLERS]:
        assert f'kind = "{kind}"' in text
