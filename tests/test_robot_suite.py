"""``ddtrack bench --suite robots``: each preset drives the plant it really has, conditions change what they say,
cells a robot's model cannot express are left out and listed, and the leaderboard, the ranking agreement and the
NN-adaptive law's paired improvement are computed from the runs. A tiny suite (short runs, one worker on 127.0.0.1)
keeps it fast; the real suite and its reading are in docs/benchmarks.md."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

from ddtrack.metrics import pooled_improvement
from ddtrack.robots import PRESETS
from ddtrack.studies.robot_board import agreement_by_path, paired, ranking_agreement, robot_board
from ddtrack.studies.robot_suite import (
    ROBOTS,
    RobotSuite,
    cells,
    default_entries,
    plan_robot_suite,
    run_robot_suite,
)

SHORT = ("simulation.duration=4", "simulation.metric_window=[1, 4]")


def _scenario(plan, robot, controller, condition, trajectory="figure_eight"):
    (found,) = [
        c.scenario
        for c in plan.configurations
        if c.controller == controller
        and c.labels == {"study": "robots", "robot": robot, "trajectory": trajectory, "condition": condition}
    ]
    return found


def test_each_robot_drives_the_plant_it_has_and_each_condition_changes_what_it_says():
    labels = ["backstepping", "kinematic_backstepping"]
    plan = plan_robot_suite(RobotSuite(trajectories=("figure_eight", "square"), seeds=1), labels)
    assert _scenario(plan, "paper", "backstepping", "nominal").plant.model == "dynamic"
    assert _scenario(plan, "turtlebot3_burger", "backstepping", "nominal").plant.model == "slip"
    assert _scenario(plan, "turtlebot3_burger", "kinematic_backstepping", "nominal").plant.model == "slip_velocity"
    assert _scenario(plan, "pioneer_3dx", "kinematic_backstepping", "nominal").plant.model == "lag"
    burger = PRESETS["turtlebot3_burger"]
    nominal = _scenario(plan, "turtlebot3_burger", "kinematic_backstepping", "nominal")
    assert nominal.simulation.control_period == 0.05 and nominal.plant.floor_friction == 1.0
    assert nominal.controller.max_velocity == burger.max_speed  # clamped at what the robot can do
    assert _scenario(plan, "turtlebot3_burger", "backstepping", "latency_150ms").sensing.actuation_delay == 0.15
    assert _scenario(plan, "turtlebot3_burger", "backstepping", "floor_mu_0.4").plant.floor_friction == 0.4
    odometry = _scenario(plan, "turtlebot3_burger", "backstepping", "odometry")
    radius = burger.params["wheel_radius"]
    assert odometry.sensing.odometry and odometry.sensing.encoder_counts == burger.motor.encoder_counts
    assert odometry.robot.params().wheel_radius == pytest.approx(1.01 * radius)  # what odometry believes
    assert odometry.plant_params().wheel_radius == radius  # the true wheel
    payload = _scenario(plan, "turtlebot3_burger", "backstepping", "payload_+50%")
    assert payload.plant_params().mass == pytest.approx(1.5 * burger.params["mass"])
    assert payload.robot.params().mass == burger.params["mass"]  # the controller does not know
    square = _scenario(plan, "pioneer_3dx", "kinematic_backstepping", "nominal", "square")
    assert square.trajectory.speed == ROBOTS["pioneer_3dx"].speed


def test_sliding_mode_gets_a_boundary_layer_that_does_not_chatter_at_the_robots_rate():
    """Its default layer (0.02, 0.04), stable at the paper's 100 Hz, chatters at the TurtleBots' 20 Hz: there the
    suite widens it to what the check advises, so no cell of it warns; on the paper's robot it keeps the default."""
    from ddtrack.feasibility import check_sampled_inner_loop

    plan = plan_robot_suite(RobotSuite(seeds=1), ["sliding_mode_backstepping"])
    default = (0.02, 0.04)
    for configuration in plan.configurations:
        scenario = configuration.scenario
        assert check_sampled_inner_loop(scenario) == [], configuration.labels
        layer = scenario.controller.boundary_layer
        if configuration.labels["robot"] == "paper":
            assert tuple(layer) == default
        else:  # T_c (K_c + K_x + K_s / phi) = 1 on the v channel of the nominal robot (K_s = 1, K_x = 1)
            assert layer[0] == pytest.approx(0.05 * 1.0 / (1.0 - 0.05 * (10.0 + 1.0)), rel=1e-9)
            assert layer[1] > default[1]


def test_cells_a_robot_cannot_express_are_left_out_and_say_why():
    run, left = cells(RobotSuite(trajectories=("figure_eight", "square")), ["backstepping", "kinematic_backstepping"])
    why = {(c["robot"], c["controller"], c["condition"]): c["why"] for c in left}
    assert why[("pioneer_3dx", "backstepping", "nominal")] == "takes no torque commands"
    assert why[("paper", "kinematic_backstepping", "nominal")] == "takes no velocity commands"
    assert why[("pioneer_3dx", "kinematic_backstepping", "payload_+50%")] == "its model has no mass"
    assert why[("paper", "backstepping", "floor_mu_0.4")] == "its model has no floor"
    ran = {(c["robot"], c["controller"], c["condition"]) for c in run}
    assert not ran & set(why)
    assert len(run) == 2 * (2 * 6 * 2 + 5 + 4)  # 2 paths x (Burger, Waffle: 6 conditions x 2 laws; paper 5; Pioneer 4)


def test_bad_controller_names_are_refused_before_anything_runs(tmp_path):
    out = tmp_path / "bench"
    done = subprocess.run(
        [sys.executable, "-m", "ddtrack", "bench", "--suite", "robots", "--controllers", "backsteping"]
        + ["--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2, done.stderr
    assert "--controllers" in done.stderr and "backstepping" in done.stderr and "Traceback" not in done.stderr
    assert not out.exists()


def _run(robot, controller, condition, seed, error, trajectory="figure_eight"):
    return {
        "robot": robot,
        "controller": controller,
        "condition": condition,
        "trajectory": trajectory,
        "seed": seed,
        "status": "ok",
        "e_tr_mean": error,
        "implausible": False,
    }


def test_the_boards_rank_by_the_nominal_condition_and_pair_by_cell():
    runs = [
        _run("r", name, condition, seed, error * factor * (1 + 0.1 * seed))
        for name, error in (("backstepping", 2.0), ("nn_adaptive_backstepping", 1.0), ("mppi", 3.0))
        for condition, factor in (("nominal", 1.0), ("latency_50ms", 5.0))
        for seed in range(3)
    ]
    runs[0]["implausible"] = True
    board = robot_board(runs, "r", ["backstepping", "nn_adaptive_backstepping", "mppi"], ["nominal", "latency_50ms"])
    assert [e["controller"] for e in board] == ["nn_adaptive_backstepping", "backstepping", "mppi"]
    first = {e["controller"]: e for e in board}["backstepping"]
    assert first["implausible"] == 1 and first["runs"] == 6 and first["failures"] == 0
    assert first["nominal"]["mean"] == pytest.approx(np.mean([2.0, 2.2, 2.4]))
    improvement = paired(runs, "r", "backstepping", "nn_adaptive_backstepping")
    mine = [r for r in runs if r["controller"] == "nn_adaptive_backstepping"]
    base = {(r["condition"], r["seed"]): r["e_tr_mean"] for r in runs if r["controller"] == "backstepping"}
    by_hand = pooled_improvement([base[(r["condition"], r["seed"])] for r in mine], [r["e_tr_mean"] for r in mine])
    assert improvement == by_hand and improvement["mean"] == pytest.approx(50.0)
    assert paired(runs, "r", "backstepping", "ltv_lqr") is None  # never ran: no answer, not zero


def test_runs_that_lose_the_path_are_counted_apart_and_never_decide_the_pooled_verdict():
    from ddtrack.studies.robot_board import board_markdown, rows

    def records(lost_error):
        """Two laws on 2 conditions x 4 seeds; at 150 ms the candidate loses the path in seeds 0-2 and the
        baseline in seed 0, with errors ``lost_error`` (what a last-bit difference makes of a lost run)."""
        out = {}
        for name, error in (("backstepping", 0.002), ("nn_adaptive_backstepping", 0.0016)):
            for condition in ("nominal", "latency_150ms"):
                for seed in range(4):
                    lost = condition == "latency_150ms" and (seed == 0 or (name != "backstepping" and seed < 3))
                    labels = {"study": "robots", "robot": "r", "trajectory": "figure_eight", "condition": condition}
                    value = lost_error * (1 + seed) if lost else error * (1 + 0.1 * seed)
                    out[f"{name}{condition}{seed}"] = {
                        "configuration": {"controller": name, "labels": labels},
                        "seed": seed,
                        "status": "ok",
                        "metrics": {"e_tr_mean": value, "lost_path": lost, "warnings": []},
                    }
        return out

    verdicts = []
    for lost_error in (1.4, 1.8, 40.0):
        runs = rows(records(lost_error))
        verdicts.append(paired(runs, "r", "backstepping", "nn_adaptive_backstepping"))
        board = {
            e["controller"]: e
            for e in robot_board(runs, "r", ["backstepping", "nn_adaptive_backstepping"], ["nominal", "latency_150ms"])
        }
        assert (board["nn_adaptive_backstepping"]["lost"], board["backstepping"]["lost"]) == (3, 1)
        assert board["nn_adaptive_backstepping"]["lost_rate"]["mean"] == 3 / 8
        assert board["nn_adaptive_backstepping"]["latency_150ms"]["n"] == 1  # the one seed that tracked
    assert verdicts[0] == verdicts[1] == verdicts[2]  # whatever the lost runs' errors: the same verdict
    assert (verdicts[0]["n"], verdicts[0]["missing"]) == (5, 3)  # 4 nominal pairs and seed 3 at 150 ms
    assert verdicts[0]["mean"] == pytest.approx(20.0)
    summary = {
        "boards": {"r": list(board.values())},
        "ranking_agreement": {},
        "left_out": [],
        "nn_adaptive": {"r": {"nn_adaptive_backstepping vs backstepping": verdicts[0]}},
    }
    text = board_markdown(summary, ["nominal", "latency_150ms"])
    assert "| 5 of 8 |" in text and "| 3: 37.5 [" in text


def test_ranking_agreement_is_kendalls_tau_over_shared_controllers():
    def board(errors):
        return [{"controller": c, "nominal": {"mean": e}} for c, e in errors.items()]

    paper = board({"a": 1.0, "b": 2.0, "c": 3.0, "d": 4.0})
    same, reversed_ = board({"a": 0.1, "b": 0.2, "c": 0.3, "d": 0.4, "x": 0.0}), board({"a": 4, "b": 3, "c": 2, "d": 1})
    agreement = ranking_agreement({"paper": paper, "same": same, "reversed": reversed_})
    assert agreement["same"]["tau"] == pytest.approx(1.0) and agreement["same"]["controllers"] == ["a", "b", "c", "d"]
    assert agreement["reversed"]["tau"] == pytest.approx(-1.0)


def test_each_path_has_its_own_ranking_agreement():
    controllers = {"a": 1.0, "b": 2.0, "c": 3.0}
    runs = [
        _run(robot, name, "nominal", 0, error if robot == "paper" or path == "square" else 4.0 - error, path)
        for robot in ("paper", "r")
        for path in ("figure_eight", "square")
        for name, error in controllers.items()
    ]
    by_path = agreement_by_path(runs, ["paper", "r"], list(controllers), ["nominal"])
    assert by_path["square"]["r"]["tau"] == pytest.approx(1.0)  # same order as the paper robot on the square
    assert by_path["figure_eight"]["r"]["tau"] == pytest.approx(-1.0)  # reversed on the figure eight
    assert (
        agreement_by_path(
            [r for r in runs if r["trajectory"] == "square"], ["paper", "r"], list(controllers), ["nominal"]
        )
        == {}
    )


TINY = RobotSuite(
    robots=("paper", "turtlebot3_burger"),
    trajectories=("figure_eight",),
    conditions=("nominal", "floor_mu_0.4"),
    seeds=2,
    overrides=SHORT,
)
LAWS = ["backstepping", "kinematic_backstepping"]


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    from distributed import Client

    from ddtrack.cluster import local_cluster

    out = tmp_path_factory.mktemp("robots")
    with local_cluster(1) as cluster, Client(cluster) as client:
        first = run_robot_suite(TINY, LAWS, out, client)
        again = run_robot_suite(TINY, LAWS, out, client)
    return out, first, again


@pytest.mark.slow
def test_a_tiny_robots_suite_runs_every_cell_once_and_reports_from_the_runs(finished):
    out, first, again = finished
    # paper: backstepping nominal (no floor, no velocity input); Burger: both laws, both floors; x 2 seeds
    assert first["runs"] == (1 + 2 * 2) * 2 and first["errors"] == 0 and first["not_ok"] == 0
    assert again["reused"] == first["runs"] and again["boards"] == first["boards"]
    runs = pq.read_table(out / "results.parquet").to_pylist()
    burger = {e["controller"]: e for e in first["boards"]["turtlebot3_burger"]}
    for law in LAWS:
        mine = [r["e_tr_mean"] for r in runs if r["controller"] == law and r["label.robot"] == "turtlebot3_burger"]
        assert burger[law]["all"]["mean"] == pytest.approx(np.mean(mine))
        assert burger[law]["runs"] == 4
    text = (out / "leaderboard.md").read_text()
    assert "### turtlebot3_burger" in text and "floor_mu_0.4" in text
    assert "paper takes no velocity commands (kinematic_backstepping)" in text
    assert "paper its model has no floor (floor_mu_0.4)" in text
    assert (out / "robots.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((out / "leaderboard.json").read_text())["controllers"] == LAWS
    assert set(default_entries()) >= set(LAWS)
