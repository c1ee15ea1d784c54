"""The CLI and the run folder (DESIGN 4): files, columns, keys, exit codes, atomic writes."""

from __future__ import annotations

import json
import os
import stat
import tomllib

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import SCENARIOS

from ddtrack import load_scenario
from ddtrack.errors import RunError
from ddtrack.rundir import atomic_write

COLUMNS = [
    "t",
    "x",
    "y",
    "theta",
    "v",
    "omega",
    "x_ref",
    "y_ref",
    "theta_ref",
    "v_ref",
    "omega_ref",
    "e_x",
    "e_y",
    "e_theta",
    "e_tr",
    "v_cmd",
    "omega_cmd",
    "tau_r",
    "tau_l",
]
METRIC_KEYS = {
    "status",
    "window",
    "e_tr_mean",
    "e_tr_rms",
    "e_tr_max",
    "e_tr_final",
    "settling_time",
    "effort",
    "saturation_fraction",
}


@pytest.fixture(scope="module")
def paper_line_run(tmp_path_factory):
    """One `ddtrack run` of the paper's line case, shared by the tests that read its folder."""
    from ddtrack.cli import main

    out = tmp_path_factory.mktemp("run") / "paper_line"
    code = main(["run", str(SCENARIOS / "paper_line.toml"), "--out", str(out)])
    return code, out


def test_run_writes_the_documented_folder(paper_line_run):
    code, out = paper_line_run
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "ddtrack.json",
        "figures",
        "metrics.json",
        "scenario.toml",
        "timeseries.parquet",
    ]
    figures = sorted(p.name for p in (out / "figures").iterdir())
    assert figures == ["errors.png", "path.png", "states.png", "torques.png"]
    for png in (out / "figures").iterdir():
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    mask = os.umask(0)
    os.umask(mask)
    for written in (out / "metrics.json", out / "timeseries.parquet", out / "figures" / "path.png"):
        assert stat.S_IMODE(written.stat().st_mode) == 0o666 & ~mask  # the umask's mode, not mkstemp's 0600


def test_timeseries_columns_and_types(paper_line_run):
    _, out = paper_line_run
    table = pq.read_table(out / "timeseries.parquet")
    assert table.column_names[: len(COLUMNS)] == COLUMNS
    assert {"kx", "ky", "ktheta", "saturated"} <= set(table.column_names)
    assert all(str(field.type) == "double" for field in table.schema)
    t = table.column("t").to_numpy()
    assert len(t) == 4000 and t[0] == 0.0 and np.allclose(np.diff(t), 0.01)
    e_tr = table.column("e_tr").to_numpy()
    assert np.allclose(e_tr, np.hypot(table.column("e_x").to_numpy(), table.column("e_y").to_numpy()))
    assert np.all(np.abs(table.column("tau_r").to_numpy()) <= 10.0)


def test_metrics_json(paper_line_run):
    _, out = paper_line_run
    metrics = json.loads((out / "metrics.json").read_text())
    assert METRIC_KEYS | {
        "final_gains",
        "warnings",
        "mu_required_max",
        "time_above_floor_mu",
        "wheel_speed_max",
        "lost_path",
        "lost_path_time",
        "lost_path_error",
    } == set(metrics)
    assert metrics["status"] == "ok" and metrics["window"] == [20.0, 40.0]
    assert metrics["final_gains"] == [1.0, 55.0, 15.0]
    # SPEC 4.5: under the paper's mismatch, backstepping's steady error is of the order F0/(m k_cv Kx) = 0.046 m
    assert 0.03 < metrics["e_tr_mean"] < 0.06
    assert metrics["e_tr_rms"] >= metrics["e_tr_mean"] and metrics["e_tr_max"] >= metrics["e_tr_rms"]
    assert 0.0 < metrics["settling_time"] < 20.0  # the paper reports about 10 s
    assert 0.0 < metrics["saturation_fraction"] < 0.5  # the 10 m start saturates, the steady state does not


def test_resolved_scenario_reproduces_the_run(paper_line_run, tmp_path, cli):
    _, out = paper_line_run
    resolved = load_scenario(out / "scenario.toml")
    assert resolved == load_scenario(SCENARIOS / "paper_line.toml")
    assert tomllib.loads((out / "scenario.toml").read_text())["robot"]["friction_smoothing"] == 0.01  # defaults
    code, _, _ = cli("run", out / "scenario.toml", "--out", tmp_path / "again")
    assert code == 0
    first = pq.read_table(out / "timeseries.parquet")
    again = pq.read_table(tmp_path / "again" / "timeseries.parquet")
    assert first.equals(again)  # bit for bit
    assert (out / "metrics.json").read_text() == (tmp_path / "again" / "metrics.json").read_text()


def test_diverged_run_exits_1_with_series_up_to_failure(tmp_path, cli):
    out = tmp_path / "out"
    code, _, stderr = cli(
        "run", SCENARIOS / "paper_line.toml", "--set", "simulation.divergence_error=8", "--out", out
    )  # the run starts 10 m from the reference
    assert code == 1
    assert "diverged at t = 0.00 s" in stderr and "lower the gains" in stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["status"] == "diverged" and metrics["failure_time"] == 0.0 and metrics["e_tr_mean"] is None
    assert pq.read_table(out / "timeseries.parquet").num_rows == 1


def test_seed_and_set_reach_the_run(tmp_path, cli):
    code, stdout, _ = cli(
        "run",
        SCENARIOS / "waypoints.toml",
        "--seed",
        "3",
        "--set",
        "simulation.duration=5",
        "--controller",
        "backstepping",
        "--out",
        tmp_path / "o",
    )
    assert code == 0 and "seed 3" in stdout
    resolved = tomllib.loads((tmp_path / "o" / "scenario.toml").read_text())
    assert resolved["simulation"]["seed"] == 3 and resolved["simulation"]["duration"] == 5.0


def test_unwritable_output_fails_before_simulating(tmp_path, cli):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    code, _, stderr = cli("run", SCENARIOS / "paper_line.toml", "--out", blocker / "run")
    assert code == 2 and "cannot be written" in stderr
    assert blocker.read_text() == "not a folder"


def test_validate_and_list(cli):
    code, stdout, _ = cli("validate", SCENARIOS / "paper_square.toml")
    assert code == 0 and stdout.startswith("ok: paper_square") and "8000 control periods" in stdout
    code, stdout, _ = cli("list")
    assert code == 0
    for name in (
        "controllers:",
        "backstepping",
        "trajectories:",
        "line",
        "square",
        "circle",
        "figure_eight",
        "sinusoid",
        "waypoints",
        "disturbances:",
        "none",
        "constant",
        "gaussian",
    ):
        assert name in stdout
    code, stdout, _ = cli("list", "disturbances")
    assert code == 0 and "line" not in stdout and "gaussian" in stdout


def test_usage_errors_exit_2(cli):
    assert cli("frobnicate")[0] == 2
    assert cli("list", "robot")[0] == 2
    assert cli("run")[0] == 2
    assert cli("run", SCENARIOS / "paper_line.toml", "--seed", "-1")[0] == 2


def test_atomic_write_leaves_no_partial_file(tmp_path):
    target = tmp_path / "metrics.json"
    target.write_text("old")

    def failing(file):
        file.write(b"half of the new cont")
        raise OSError("disk full")

    with pytest.raises(RunError, match=r"metrics\.json.*disk full"):  # a clean error naming the file (exit 2)
        atomic_write(target, failing)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["metrics.json"]  # no temporary left behind


def test_adaptive_run_writes_gains_and_identification(tmp_path, cli):
    out = tmp_path / "nn"
    code, stdout, _ = cli(
        "run",
        SCENARIOS / "paper_line.toml",
        "--controller",
        "nn_adaptive_backstepping",
        "--set",
        "controller.epochs=5",
        "--out",
        out,
    )
    assert code == 0 and "nn_adaptive_backstepping" in stdout
    assert (out / "figures" / "gains.png").stat().st_size > 10_000  # gains that moved get their figure
    # the gains start at the scenario's, stay inside the adaptation's bounds, and end where metrics.json says
    spec = load_scenario(out / "scenario.toml")
    columns = pq.read_table(out / "timeseries.parquet").to_pydict()
    logged = np.column_stack([columns[k] for k in ("kx", "ky", "ktheta")])
    assert np.array_equal(logged[0], spec.controller.gains)
    assert np.all(logged >= np.asarray(spec.controller.gain_min)) and np.all(logged <= spec.controller.gain_max)
    final = json.loads((out / "metrics.json").read_text())["final_gains"]
    assert np.array_equal(logged[-1], final) and not np.array_equal(final, spec.controller.gains)
    found = json.loads((out / "identification.json").read_text())
    assert found["epochs"] == 5 and len(found["epoch_loss"]) == 5 and found["samples"] == 5999
    assert found["epoch_loss"][-1] < found["epoch_loss"][0]  # pre-training learns
    assert found["nmse"]["forward"] < 1e-2 and found["nmse"]["yaw"] < 1e-2
    table = pq.read_table(out / "timeseries.parquet")
    assert {"emulator_loss", "jacobian_v", "jacobian_omega", "gate"} <= set(table.column_names)
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["final_gains"] != [1.0, 55.0, 15.0]  # the gains adapted


@pytest.mark.slow
def test_reproduce_exits_1_when_the_adaptive_controller_loses(tmp_path, cli, monkeypatch):
    import ddtrack.studies.reproduce as reproduce_module

    losing = {
        "seeds": 1,
        "elapsed_s": 0.0,
        "cases": {
            "paper_line": {"improvement": {"nn_adaptive": {"mean": -3.0, "missing": 0}}},
            "paper_square": {"improvement": {"nn_adaptive": {"mean": 12.0, "missing": 0}}},
        },
    }
    monkeypatch.setattr(reproduce_module, "reproduce", lambda out, **_: losing)
    monkeypatch.setattr(reproduce_module, "table_markdown", lambda table: "table")
    code, _, stderr = cli("reproduce", "--out", tmp_path / "r")
    assert code == 1 and "does not beat backstepping on: paper_line" in stderr


def test_an_overlaid_path_keeps_the_title(paper_line_run):
    from ddtrack.plotting import plot_path

    _, out = paper_line_run
    table = pq.read_table(out / "timeseries.parquet")
    columns = {name: table.column(name).to_numpy() for name in table.column_names}
    fig = plot_path(columns, title="Case 1")
    plot_path(columns, ax=fig.axes[0], label="again", reference=False)
    assert fig.get_suptitle() == "Case 1"
    assert [line.get_label() for line in fig.axes[0].lines][-1] == "again"


def test_a_burger_scale_run_prints_its_small_effort_with_significant_digits(tmp_path, cli):
    """A 1 kg robot with 0.5 N m wheels: the effort is ~1e-3 N^2 m^2 s, which fixed decimals printed as 0.0."""
    burger = [
        "robot.mass=1.0",
        "robot.inertia=0.01",
        "robot.com_offset=0.0",
        "robot.wheel_radius=0.033",
        "robot.half_axle=0.08",
        "robot.max_torque=0.5",
        "plant.mass=1.2",
        "plant.inertia=0.012",
        "plant.com_offset=0.01",
        "plant.viscous_friction=0.0005",
        "plant.coulomb_friction=0.002",
        "disturbance.bias=[0.0003, 0.0]",
        "disturbance.amplitude=[0.0005, -0.0005]",
        "trajectory.speed=0.2",
        "initial.pose=[0.0, 0.05, 0.785]",
        "simulation.duration=4",
        "simulation.metric_window=[2.0, 4.0]",
        "controller.max_velocity=0.22",
        "controller.max_yaw_rate=2.8",
    ]
    out = tmp_path / "burger"
    code, stdout, _ = cli(
        "run", SCENARIOS / "paper_line.toml", *(a for s in burger for a in ("--set", s)), "--out", out
    )
    assert code == 0
    effort = json.loads((out / "metrics.json").read_text())["effort"]
    assert 0.0 < effort < 0.01  # the scale that fixed decimals lost
    printed = stdout.split("effort ")[1].split(" N^2")[0]
    assert printed != "0.0" and float(printed) == pytest.approx(effort, rel=5e-3)  # 3 significant digits
    assert len(printed.replace("0.", "", 1).lstrip("0").replace(".", "").split("e")[0]) == 3
    assert "saturated " in stdout and " % of the time" in stdout


def test_run_prints_its_summary_before_it_draws_the_figures(cli, capsys, tmp_path, monkeypatch):
    # the numbers are ready once the run is: a user reads them while the figures are drawn (and a write that then
    # fails leaves no folder behind)
    import ddtrack.rundir

    printed = []

    def write_run(stage, *args, **kwargs):
        printed.append(capsys.readouterr().out)  # what the user has read when the folder starts being written
        raise OSError("disk full")

    monkeypatch.setattr(ddtrack.rundir, "write_run", write_run)
    out = tmp_path / "line"
    short = ["--set", "simulation.duration=2", "--set", "simulation.metric_window=[0, 2]"]
    code, _, err = cli("run", SCENARIOS / "paper_line.toml", "--out", out, *short)
    assert code != 0 and "disk full" in err
    assert printed and printed[0].startswith(f"paper_line: backstepping on line, seed 0, 2 s -> {out}")
    assert "e_tr over [0, 2] s: mean" in printed[0] and not out.exists()
