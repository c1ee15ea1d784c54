"""``ddtrack bench --scenario``: the user's own scenarios as leaderboard entries. Two files that differ in gains and
a registered controller added on their robot run on common random numbers through the sweep runner, the board is
computed from the runs (the paired improvement recomputed here from results.parquet), a rerun reuses every run, and
unfair or bad input is refused before anything is written. A run folder (``ddtrack run``'s, and a real ``ddtrack
robot`` run driven by a plain Cyclone DDS node) ranks as a recorded entry: its one run, not simulated again. Short
runs of the paper's robot on one worker keep it fast."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from ddtrack.cli import main
from ddtrack.metrics import pooled_improvement
from ddtrack.outdir import write_marker
from ddtrack.robots import PRESETS
from ddtrack.studies.scenario_suite import bench_entries, board_markdown, leaderboard, plan_entries
from ddtrack.studies.sweep import read_records

SCENARIO = """name = "{name}"
description = "{name} gains"
[simulation]
duration = 3.0
metric_window = [1.0, 3.0]
[robot]
preset = "paper"
[plant]
mass = {mass}
[randomize]
mass = {{ distribution = "uniform", relative = 0.1 }}
[disturbance]
kind = "gaussian"
mean = [0.03, 0.0]
std = [0.05, 0.05]
[trajectory]
kind = "circle"
center = [0.0, 0.0]
radius = 3.0
speed = 0.5
start_angle = -1.5707963267948966
[initial]
pose = [0.0, -2.9, 0.0]
[controller]
kind = "backstepping"
gains = {gains}
"""
SEEDS = 3


def write(folder, stem, *, gains=(1.0, 55.0, 15.0), mass=12.0, name=None):
    folder.mkdir(exist_ok=True)
    path = folder / f"{stem}.toml"
    path.write_text(SCENARIO.format(name=name or stem, gains=list(gains), mass=mass))
    return path


#: a run's metrics.json, as much of it as the board reads
METRICS = {"status": "ok", "window": [1.0, 3.0], "e_tr_mean": 0.02, "e_tr_rms": 0.025, "e_tr_max": 0.05}
METRICS |= {"effort": 0.4, "saturation_fraction": 0.0, "warnings": []}


def run_folder(folder, name, metrics=METRICS, *, mass=12.0, command="run"):
    """A run folder as ``ddtrack run`` or ``ddtrack robot`` leaves it, as far as bench reads it (no simulation):
    ``scenario.toml`` of this file's experiment, ``metrics``, and the marker of ``command`` (None: no marker)."""
    path = folder / name
    path.mkdir(parents=True)
    (path / "scenario.toml").write_text(SCENARIO.format(name=name, gains=[1.0, 55.0, 15.0], mass=mass))
    (path / "metrics.json").write_text(json.dumps(metrics))
    if command is not None:
        write_marker(path, command=command)
    return path


def bench(*args):
    """``ddtrack bench ARGS`` in-process: (exit code, stdout)."""
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(["bench", *map(str, args)])
    return code, stdout.getvalue()


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    from ddtrack.cluster import local_cluster

    folder = tmp_path_factory.mktemp("mine")
    files = [write(folder, "default"), write(folder, "tuned", gains=(2.0, 80.0, 20.0), name="other")]
    out = folder / "bench"
    args = [a for f in files for a in ("--scenario", f)] + ["--controllers", "ltv_lqr", "--seeds", SEEDS]
    with local_cluster(1) as cluster:
        address = cluster.scheduler_address
        first = bench(*args, "--out", out, "--scheduler", address)
        summary = json.loads((out / "leaderboard.json").read_text())
        again = bench(*args, "--out", out, "--scheduler", address)
    return files, out, first, summary, again


def test_two_files_and_an_added_controller_make_one_board_from_the_runs(finished):
    _files, out, (code, stdout), summary, _ = finished
    assert code == 0, stdout
    assert summary["entries"] == ["default", "tuned", "ltv_lqr"] and summary["reference"] == "default"
    assert summary["runs"] == 3 * SEEDS and summary["errors"] == 0 and summary["reused"] == 0
    runs = pq.read_table(out / "results.parquet").to_pylist()
    board = {e["entry"]: e for e in summary["leaderboard"]}
    for label in summary["entries"]:
        mine = [r for r in runs if r["controller"] == label]
        assert sorted(r["seed"] for r in mine) == list(range(SEEDS))
        assert board[label]["ok"] == SEEDS and board[label]["diverged"] == 0
        assert board[label]["e_tr_mean"]["mean"] == pytest.approx(np.mean([r["e_tr_mean"] for r in mine]))
    assert board["ltv_lqr"]["controller"] == "ltv_lqr" and board["tuned"]["controller"] == "backstepping"
    # the paired improvement over the first file's entry, recomputed from the per-seed results
    default = {r["seed"]: r["e_tr_mean"] for r in runs if r["controller"] == "default"}
    for label in ("tuned", "ltv_lqr"):
        mine = sorted((r for r in runs if r["controller"] == label), key=lambda r: r["seed"])
        by_hand = pooled_improvement([default[r["seed"]] for r in mine], [r["e_tr_mean"] for r in mine])
        assert board[label]["improvement"] == pytest.approx(by_hand)
        assert board[label]["improvement"]["n"] == SEEDS
    assert board["default"]["improvement"] is None
    means = [e["e_tr_mean"]["mean"] for e in summary["leaderboard"]]
    assert means == sorted(means)  # ranked by mean tracking error
    table = pq.read_table(out / "leaderboard.parquet")
    assert table.column("entry").to_pylist() == [e["entry"] for e in summary["leaderboard"]]
    assert "improvement_ci_low" in table.column_names and (out / "leaderboard.csv").is_file()
    text = (out / "leaderboard.md").read_text()
    assert "| tuned | backstepping |" in text and "vs default [%]" in text and "seed 2" in text
    assert text in stdout
    assert (out / "entries.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_board_says_when_every_seed_gave_the_same_run(finished):
    *_, summary, _ = finished
    assert "draws nothing at random" not in board_markdown(summary["leaderboard"], "default")  # mass and noise drawn
    same = [e | {"e_tr_mean_by_seed": dict.fromkeys(e["e_tr_mean_by_seed"], 0.01)} for e in summary["leaderboard"]]
    assert "draws nothing at random" in board_markdown(same, "default")


def test_a_rerun_reuses_every_run(finished):
    _files, out, _, summary, (code, stdout) = finished
    assert code == 0 and f"{3 * SEEDS} runs ({3 * SEEDS} reused)" in stdout
    assert json.loads((out / "leaderboard.json").read_text())["leaderboard"] == summary["leaderboard"]


def test_report_says_it_does_not_show_a_scenario_bench_yet(finished, cli, tmp_path):
    _files, out, *_ = finished
    code, _, stderr = cli("report", out, "--out", tmp_path / "report.html")
    assert code == 2 and "bench --scenario" in stderr and "leaderboard.md" in stderr
    assert not (tmp_path / "report.html").exists()


def test_entries_meet_the_same_experiment_and_pair_by_seed(finished):
    files, *_ = finished
    entries = bench_entries(files, ["ltv_lqr"])
    plan = plan_entries(entries, SEEDS)
    experiments = [c.scenario.model_dump(exclude={"controller", "name", "description"}) for c in plan.configurations]
    assert all(e == experiments[0] for e in experiments)
    assert sorted(seed for index, seed in plan.runs.values() if index == 2) == list(range(SEEDS))
    assert entries[2].source["controller"]["kind"] == "ltv_lqr"  # the defaults, not the file's gains


def test_an_added_controller_takes_the_presets_clamps(tmp_path):
    text = SCENARIO.format(name="burger", gains=[1.0, 55.0, 15.0], mass=1.0)
    text = text.replace('preset = "paper"', 'preset = "turtlebot3_burger"').replace("radius = 3.0", "radius = 0.5")
    text = text.replace("speed = 0.5", "speed = 0.1").replace("-2.9", "-0.5").replace("mass = 1.0", "")
    text = text.replace('kind = "backstepping"', 'kind = "backstepping"\ninner = "none"').replace("[plant]\n", "")
    path = tmp_path / "burger.toml"
    path.write_text(text.replace("[randomize]", '[plant]\nmodel = "slip_velocity"\n[randomize]'))
    (_, added) = bench_entries([path], ["kinematic_backstepping"])
    burger = PRESETS["turtlebot3_burger"]
    assert added.scenario.controller.max_velocity == burger.max_speed
    assert added.scenario.controller.max_yaw_rate == burger.max_yaw_rate
    assert added.scenario.plant.model == "slip_velocity"


@pytest.mark.parametrize(
    "case, field, words",
    [
        ("differs", "--scenario", "tuned.toml differs from default.toml in plant.mass (13.0 vs 12.0)"),
        ("same stem", "--scenario", "have the same label 'default'"),
        ("same name", "--scenario", "have the same label 'default'"),
        ("no marker", "--scenario", "ddtrack did not write this folder (no ddtrack.json)"),
        ("not a run", "--scenario", "a ddtrack mc folder, not a run folder"),
        ("no metrics", "--scenario", "no metrics.json: not a whole run folder"),
        ("measured", "--scenario", "a ddtrack drive run: its e_tr is what the robot's odometry believed"),
        ("folder differs", "--scenario", "nav2 differs from default.toml in plant.mass (13.0 vs 12.0)"),
        ("cut short", "--scenario", "the run was cut short (Ctrl-C or SIGTERM, after 40 periods)"),
        ("collision", "--controllers", "'backstepping' is also the label of a --scenario file"),
        ("unknown", "--controllers", "unknown controller 'ltv_lq'"),
        ("plant", "--controllers", "kinematic_backstepping outputs velocity commands, but the plant"),
        ("missing", "--scenario", "does not exist"),
        ("invalid", "--scenario", "plant.mass"),
        ("suite", "--scenario", "cannot be combined with --suite"),
        ("seeds", "--seeds", "the suites fix their own"),
    ],
)
def test_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, cli, case, field, words):
    default = write(tmp_path, "default")
    other = {  # each case writes only its own files
        "differs": lambda: ["--scenario", write(tmp_path, "tuned", mass=13.0)],
        "same stem": lambda: ["--scenario", write(tmp_path.joinpath("sub"), "default")],
        "same name": lambda: ["--scenario", run_folder(tmp_path / "sub", "default")],
        "no marker": lambda: ["--scenario", run_folder(tmp_path, "nav2", command=None)],
        "not a run": lambda: ["--scenario", run_folder(tmp_path, "nav2", command="mc")],
        "no metrics": lambda: ["--scenario", _without(run_folder(tmp_path, "nav2"), "metrics.json")],
        "measured": lambda: ["--scenario", run_folder(tmp_path, "nav2", METRICS | {"warnings": [MEASURED]})],
        "folder differs": lambda: ["--scenario", run_folder(tmp_path, "nav2", mass=13.0)],
        "cut short": lambda: ["--scenario", run_folder(tmp_path, "nav2", METRICS | {"driven_by": STOPPED})],
        "collision": lambda: ["--scenario", write(tmp_path, "backstepping"), "--controllers", "backstepping"],
        "unknown": lambda: ["--controllers", "ltv_lq"],
        "plant": lambda: ["--controllers", "kinematic_backstepping"],
        "missing": lambda: ["--scenario", tmp_path / "nope.toml"],
        "invalid": lambda: ["--scenario", write(tmp_path, "bad", mass=-1.0)],
        "suite": lambda: ["--suite", "quick"],
    }
    args = ["--suite", "quick", "--seeds", "3"] if case == "seeds" else ["--scenario", default, *other[case]()]
    code, _, stderr = cli("bench", *args, "--out", tmp_path / "out")
    assert code == 2 and stderr.startswith(f"error: {field}") and words in stderr, stderr
    assert len(stderr.strip().splitlines()) <= 2 and "Traceback" not in stderr  # the error, and a hint
    assert not (tmp_path / "out").exists()


MEASURED = {"code": "measured_pose", "message": "the pose is the robot's odometry"}  # ddtrack drive's warning
STOPPED = {"command": "ddtrack robot", "mode": "realtime", "topic": "/cmd_vel", "ended": "stopped", "periods": 40}


def _without(folder, name):
    (folder / name).unlink()
    return folder


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """``ddtrack run`` of default.toml at seed 1 into a folder, then benched after default.toml over seeds 0, 1."""
    folder = tmp_path_factory.mktemp("recorded")
    default = write(folder, "default")
    run = folder / "by_hand"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["run", str(default), "--seed", "1", "--out", str(run)]) == 0
    out = folder / "bench"
    code, stdout = bench("--scenario", default, "--scenario", run, "--seeds", 2, "--workers", 1, "--out", out)
    return run, out, code, stdout, json.loads((out / "leaderboard.json").read_text())


def test_a_run_folder_ranks_as_its_one_recorded_run(recorded):
    run, out, code, stdout, summary = recorded
    assert code == 0, stdout
    assert summary["entries"] == ["default", "by_hand"] and summary["recorded"] == [str(run)]
    runs = pq.read_table(out / "results.parquet").to_pylist()
    assert summary["runs"] == 2 and sorted((r["controller"], r["seed"]) for r in runs) == [
        ("default", 0),
        ("default", 1),
    ]
    metrics = json.loads((run / "metrics.json").read_text())
    board = {e["entry"]: e for e in summary["leaderboard"]}
    mine = board["by_hand"]
    assert mine["controller"] == "backstepping" and mine["runs"] == mine["ok"] == 1
    for key in ("e_tr_mean", "e_tr_rms", "e_tr_max", "effort"):  # as its metrics.json has them, with no interval
        assert mine[key] == {"mean": metrics[key], "ci_low": None, "ci_high": None, "n": 1, "missing": 0}, key
    assert mine["e_tr_mean_by_seed"] == {"1": metrics["e_tr_mean"]}
    assert mine["recorded"] == {"run": str(run), "seed": 1, "reproducible": True}
    default = {r["seed"]: r["e_tr_mean"] for r in runs}
    assert mine["improvement"] == pooled_improvement([default[1]], [metrics["e_tr_mean"]])
    assert mine["improvement"]["n"] == 1 and mine["improvement"]["ci_low"] is None
    # common random numbers: bench's seed 1 of the same file is the run made with --seed 1
    assert default[1] == pytest.approx(metrics["e_tr_mean"], rel=1e-9)
    text = (out / "leaderboard.md").read_text()
    assert "| by_hand | backstepping |" in text and f"by_hand: recorded in {run}" in text and text in stdout
    assert "2 runs (0 reused) and 1 recorded" in stdout and (out / "entries.png").is_file()


def test_a_recorded_reference_pairs_the_others_on_its_one_seed(recorded):
    run, out, *_ = recorded
    entries = bench_entries([run, out.parent / "default.toml"])
    board = {e["entry"]: e for e in leaderboard(read_records(out), entries)}
    assert board["by_hand"]["improvement"] is None
    assert board["default"]["improvement"]["n"] == 1 and board["default"]["improvement"]["missing"] == 1
    text = board_markdown(list(board.values()), "by_hand")
    assert "(by_hand is a recorded run: the others pair on its one seed, 1)" in text
    assert "nothing pairs with it" not in text
    seed_0 = {k: r for k, r in read_records(out).items() if r["seed"] == 0}  # a bench of --seeds 1
    unpaired = board_markdown(leaderboard(seed_0, entries), "by_hand")
    assert "No other entry ran seed 1, so nothing pairs with it: give --seeds 2 or more." in unpaired


def test_a_failed_and_a_realtime_run_rank_without_simulating(tmp_path, cli):
    live = METRICS | {"driven_by": {"command": "ddtrack robot", "mode": "realtime", "topic": "/cmd_vel"}}
    failed = METRICS | {"status": "diverged", "e_tr_mean": None, "e_tr_rms": None, "e_tr_max": None}
    folders = [run_folder(tmp_path, "nav2", live), run_folder(tmp_path, "crashed", failed)]
    given = [a for f in folders for a in ("--scenario", f)]
    code, stdout, stderr = cli("bench", *given, "--workers", 1, "--out", tmp_path / "out")
    assert code == 0, stderr
    board = {e["entry"]: e for e in json.loads((tmp_path / "out" / "leaderboard.json").read_text())["leaderboard"]}
    assert board["nav2"]["controller"] == "ddtrack robot/realtime" and board["nav2"]["e_tr_mean"]["mean"] == 0.02
    assert board["crashed"]["diverged"] == 1 and board["crashed"]["e_tr_mean"]["mean"] is None
    assert board["crashed"]["improvement"] == pooled_improvement([0.02], [None])
    assert (
        "A realtime run: the wall clock timed its commands" in stdout and "0 runs (0 reused) and 2 recorded" in stdout
    )
    assert ".json, entries.png" in stdout and not (tmp_path / "out" / "results.parquet").exists()  # nothing ran


@pytest.mark.slow
def test_a_foreign_controller_s_robot_run_ranks_beside_a_scenario(tmp_path):
    from test_live_robot import _drive  # ddtrack robot --mode lockstep, driven by a plain Cyclone DDS node

    _, _, robot = _drive(tmp_path, "nav2", 11)
    twin = tmp_path / "figure8.toml"
    twin.write_text((robot / "scenario.toml").read_text())  # the same experiment, under the scenario's own controller
    code, stdout = bench("--scenario", robot, "--scenario", twin, "--seeds", 1, "--workers", 1, "--out", tmp_path / "b")
    assert code == 0, stdout
    board = {e["entry"]: e for e in json.loads((tmp_path / "b" / "leaderboard.json").read_text())["leaderboard"]}
    metrics = json.loads((robot / "metrics.json").read_text())
    assert metrics["driven_by"] == {
        "command": "ddtrack robot",
        "mode": "lockstep",
        "topic": "/cmd_vel",
        "ended": "done",
        "periods": 30,  # 1.5 s at 20 Hz, to the end
    }
    assert board["nav2"]["controller"] == "ddtrack robot/lockstep" and board["nav2"]["recorded"]["reproducible"]
    assert board["nav2"]["e_tr_mean"]["mean"] == metrics["e_tr_mean"] and board["nav2"]["runs"] == 1
    assert board["figure8"]["improvement"]["n"] == 1  # paired on the robot's seed, 0
    assert "| nav2 | ddtrack robot/lockstep |" in stdout and "the others pair on its one seed, 0" in stdout
