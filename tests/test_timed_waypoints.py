"""Waypoint files with t, yaw and v columns: the timed path (ddtrack.trajectories.timed_path), its stops and held
headings, repeated points dropped with a warning, and the resolved scenario's round trip."""

from __future__ import annotations

import tomllib

import jax
import numpy as np
import pytest
import tomli_w

import ddtrack
from ddtrack import feasibility
from ddtrack.errors import ConfigError
from ddtrack.scenario import to_toml_dict, validate_scenario
from ddtrack.scenario.waypoint_rows import WaypointRows, read_waypoint_rows, tidy_rows
from ddtrack.trajectories import timed_path, trapezoid_times

# a path with a curve, a 2 s stop at (2, 1) (rows 2..4), and a last stretch; knots at TIMES
TIMES = np.array([0.0, 1.0, 2.0, 3.0, 5.0, 6.0, 7.5, 9.0])
POINTS = np.array([(0.0, 0.0), (1.0, 0.2), (2.0, 1.0), (2.0, 1.0), (2.0, 1.0), (3.0, 2.5), (4.5, 3.0), (6.0, 3.5)])
PATH = timed_path(TIMES, POINTS)
YAWS = np.array([0.1, 0.2, 0.7, -2.0, 0.9, 1.0, 0.3, 0.25])
YAWED = timed_path(TIMES, POINTS, yaws=YAWS)
EVALUATE = jax.jit(lambda path, t: jax.vmap(path)(t))  # one program for both paths (same shapes)


def sample(path, t) -> dict[str, np.ndarray]:
    return {k: np.asarray(v) for k, v in EVALUATE(path, np.asarray(t, dtype=float))._asdict().items()}


def test_the_reference_passes_through_every_row_at_its_time():
    ref = sample(PATH, TIMES)
    np.testing.assert_allclose(ref["x"], POINTS[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ref["y"], POINTS[:, 1], rtol=0, atol=1e-12)


def test_speeds_and_rates_are_the_derivatives_of_the_position():
    # away from knots, inside the moving stretches
    t = np.concatenate([np.linspace(0.1, 1.9, 7), np.linspace(5.1, 8.9, 9)])
    t = t[np.min(np.abs(t[:, None] - TIMES[None, :]), axis=1) > 0.05]
    h = 1e-5
    ref, ahead, behind = sample(PATH, t), sample(PATH, t + h), sample(PATH, t - h)
    dx, dy = (ahead["x"] - behind["x"]) / (2 * h), (ahead["y"] - behind["y"]) / (2 * h)
    np.testing.assert_allclose(ref["v"], np.hypot(dx, dy), rtol=1e-7)
    np.testing.assert_allclose(ref["theta"], np.arctan2(dy, dx), atol=1e-7)
    turned = np.angle(np.exp(1j * (ahead["theta"] - behind["theta"])))
    np.testing.assert_allclose(ref["omega"], turned / (2 * h), atol=1e-6)
    np.testing.assert_allclose(ref["v_dot"], (ahead["v"] - behind["v"]) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(ref["omega_dot"], (ahead["omega"] - behind["omega"]) / (2 * h), atol=1e-5)
    assert np.all(ref["v"] > 0.1)  # the checks above are not on a held reference


def test_a_stop_stands_exactly_still_holding_the_heading_of_motion():
    t = np.linspace(2.0, 5.0, 13)
    ref = sample(PATH, t)
    assert np.all(ref["x"] == 2.0) and np.all(ref["y"] == 1.0)
    for name in ("v", "omega", "v_dot", "omega_dot"):
        assert np.all(ref[name] == 0.0), name
    arriving = sample(PATH, [2.0 - 1e-4])["theta"][0]
    assert np.all(ref["theta"][:-1] == ref["theta"][0]) and ref["theta"][0] == pytest.approx(arriving, abs=1e-3)
    leaving = sample(PATH, [5.0 + 1e-4])["theta"][0]
    assert ref["theta"][-1] == pytest.approx(leaving, abs=1e-3)  # at t = 5 s the reference sets off


def test_a_stop_holds_the_yaw_column_where_given():
    ref = sample(YAWED, [2.0, 2.5, 3.0, 4.5])
    np.testing.assert_allclose(ref["theta"], [0.7, 0.7, -2.0, -2.0], rtol=0, atol=1e-15)  # each row's yaw to the next
    assert np.all(ref["v"] == 0.0) and np.all(ref["omega"] == 0.0)


def test_before_the_first_and_after_the_last_time_the_pose_is_held():
    ref = sample(PATH, [-5.0, -1e-3, 9.0, 9.5, 100.0])
    np.testing.assert_array_equal(ref["x"], [0.0, 0.0, 6.0, 6.0, 6.0])
    np.testing.assert_array_equal(ref["y"], [0.0, 0.0, 3.5, 3.5, 3.5])
    for name in ("v", "omega", "v_dot", "omega_dot"):
        assert np.all(ref[name] == 0.0), name
    first, last = sample(PATH, [1e-4, 9.0 - 1e-4])["theta"]
    assert ref["theta"][0] == ref["theta"][1] == pytest.approx(first, abs=1e-3)
    assert ref["theta"][2] == ref["theta"][4] == pytest.approx(last, abs=1e-3)
    yawed = sample(YAWED, [-1.0, 10.0])["theta"]
    np.testing.assert_allclose(yawed, [0.1, 0.25], rtol=0, atol=1e-15)  # wrapped to (-pi, pi]


def test_speeds_give_the_end_velocities_of_each_stretch():
    path = timed_path([0.0, 1.0, 2.0], [(0.0, 0.0), (1.0, 0.0), (2.0, 0.0)], speeds=[1.0, 1.0, 1.0])
    ref = sample(path, [0.0, 0.5, 1.0, 1.999999])
    np.testing.assert_allclose(ref["v"], 1.0, rtol=1e-5)  # a straight line at 1 m/s is the spline itself
    np.testing.assert_allclose(ref["x"][:3], [0.0, 0.5, 1.0], atol=1e-12)


def test_v_without_t_gives_the_trapezoid_times():
    times = trapezoid_times([(0, 0), (2, 0), (2, 3), (2, 5)], [0.0, 1.0, 2.0, 0.5])
    np.testing.assert_allclose(times, [0.0, 4.0, 4.0 + 2.0, 6.0 + 4.0 / 2.5])
    with pytest.raises(ValueError, match="point 2: the leg from point 1 has v = 0 at both ends"):
        trapezoid_times([(0, 0), (1, 0), (2, 0)], [1.0, 0.0, 0.0])


def write(tmp_path, text: str, name: str = "w.csv"):
    (tmp_path / name).write_text(text)
    return tmp_path / name


def scenario_of(tmp_path, trajectory: dict, duration: float = 6.0):
    data = {"name": "timed", "simulation": {"duration": duration}, "trajectory": {"kind": "waypoints", **trajectory}}
    return validate_scenario(data, base_dir=tmp_path)


def test_a_header_names_the_columns_in_any_order(tmp_path):
    path = write(tmp_path, "# recorded\nyaw, y ,x,t\n\n0.5,0,0,0\n# a comment\n0.25,1,2,1.5\n")
    rows = read_waypoint_rows(path)
    assert rows.points == [(0.0, 0.0), (2.0, 1.0)] and rows.times == [0.0, 1.5] and rows.yaws == [0.5, 0.25]
    assert rows.speeds is None and rows.numbers == (4, 6)


@pytest.mark.parametrize(
    "text, match",
    [
        ("t,x,y\n0,0,0\n1,1,0\n1,2,0\n", "line 4: t = 1 s is not after 1 s"),
        ("t,x,y\n0,0,0\n2,1,0\n1,2,0\n", "line 4: t = 1 s is not after 2 s"),
        ("x,y,heading\n0,0,0\n", "line 1: unknown column 'heading'"),
        ("t,x,yaw\n0,0,0\n", "line 1: the header has no 'y' column"),
        ("x,y\n0,0\nnan,1\n", "line 3: 'nan,1' holds NaN or inf"),
        ("x,y,v\n0,0,1\n1,0,inf\n", "line 3: '1,0,inf' holds NaN or inf"),
        ("t,x,y\n0,0,0\n1,one,0\n", "line 3: expected 3 numbers 't,x,y'"),
        ("x,x,y\n0,0,0\n", "line 1: column 'x' is named twice"),
    ],
)
def test_a_bad_file_is_refused_naming_the_line(tmp_path, text, match):
    write(tmp_path, text)
    with pytest.raises(ConfigError, match=match) as info:
        scenario_of(tmp_path, {"file": "w.csv"})
    assert info.value.field == "trajectory.file" and "w.csv" in str(info.value)


def test_repeated_points_of_an_untimed_file_are_dropped_with_a_warning(tmp_path):
    write(tmp_path, "x,y\n0,0\n1,0\n1,0\n2,1\n# a comment\n2,1\n2,1\n3,1\n")
    scenario = scenario_of(tmp_path, {"file": "w.csv"})
    assert scenario.trajectory.points == [(0.0, 0.0), (1.0, 0.0), (2.0, 1.0), (3.0, 1.0)]
    warnings = [w for w in feasibility.check(scenario) if w["code"] == "waypoints_repeated"]
    assert warnings == [
        {
            "code": "waypoints_repeated",
            "message": "waypoints file 'w.csv': dropped 3 repeated points (lines 4, 7, 8)",
        }
    ]
    inline = scenario_of(tmp_path, {"points": [[0, 0], [1, 0], [1, 0], [2, 0]]})
    assert inline.trajectory.points == [(0.0, 0.0), (1.0, 0.0), (2.0, 0.0)]
    assert "dropped 1 repeated point (point 2)" in inline.trajectory.load_warnings[0]["message"]
    assert scenario_of(tmp_path, {"points": [[0, 0], [1, 0]]}).trajectory.load_warnings == []


def test_a_timed_file_keeps_a_stop_and_drops_only_exact_duplicate_rows():
    rows = WaypointRows([(0, 0), (1, 0), (1, 0), (1, 0), (2, 0)], times=[0, 1, 1, 3, 4], numbers=(2, 3, 4, 5, 6))
    kept, note = tidy_rows(rows, "w.csv")
    assert kept.times == [0, 1, 3, 4] and kept.points == [(0, 0), (1, 0), (1, 0), (2, 0)]
    assert note == "w.csv: dropped 1 repeated point (point 4)"


def test_timing_options_that_do_not_apply_are_refused(tmp_path):
    write(tmp_path, "t,x,y\n0,0,0\n1,1,0\n")
    with pytest.raises(ConfigError, match="no fillets") as info:
        scenario_of(tmp_path, {"file": "w.csv", "corner_radius": 0.5})
    assert info.value.field == "trajectory.corner_radius"
    with pytest.raises(ConfigError, match="does not repeat"):
        scenario_of(tmp_path, {"file": "w.csv", "loop": True})
    with pytest.raises(ConfigError, match="2 values for 3 points") as info:
        scenario_of(tmp_path, {"points": [[0, 0], [1, 0], [2, 0]], "times": [0, 1]})
    assert info.value.field == "trajectory.times"


def test_a_v_column_times_the_file(tmp_path):
    write(tmp_path, "x,y,v\n0,0,0\n2,0,1\n2,0,1\n2,3,2\n")
    trajectory = scenario_of(tmp_path, {"file": "w.csv"}).trajectory
    assert trajectory.times == [0.0, 4.0, 6.0] and trajectory.speeds == [0.0, 1.0, 2.0]
    assert trajectory.load_warnings[0]["message"].endswith("(line 4)")


def test_a_timed_scenario_runs_and_its_resolved_form_reloads_to_the_same_reference(tmp_path):
    write(tmp_path, "t,x,y,yaw\n0,0,0,0\n1,0.2,0,0\n2,0.4,0.05,0.1\n3,0.4,0.05,0.5\n4,0.6,0.2,0.6\n")
    scenario = scenario_of(tmp_path, {"file": "w.csv"}, duration=5.0)
    result = ddtrack.run(scenario)
    assert int(result.n_valid) == len(result.t) and np.all(np.isfinite(np.asarray(result.state)))
    resolved = tomli_w.dumps(to_toml_dict(scenario))
    assert "times" in resolved and "file" not in resolved
    again = validate_scenario(tomllib.loads(resolved), base_dir=tmp_path / "elsewhere")
    assert again == scenario
    t = np.array([0.0, 0.5, 2.5, 3.7, 9.0])
    before, after = sample(scenario.trajectory.build(), t), sample(again.trajectory.build(), t)
    for name in before:
        np.testing.assert_array_equal(before[name], after[name], err_msg=name)
    np.testing.assert_array_equal(np.asarray(ddtrack.run(again).state), np.asarray(result.state))
