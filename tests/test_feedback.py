"""A long lone run shows what it is doing on a terminal (an NN identification takes seconds), and nothing extra
when its output goes to a pipe or a file."""

from __future__ import annotations

import sys

from conftest import SCENARIOS

NN = (
    "--controller",
    "nn_adaptive_backstepping",
    "--set",
    "controller.epochs=1",
    "--set",
    "controller.identification_duration=1",
    "--set",
    "simulation.duration=1",
    "--set",
    "simulation.metric_window=[0, 1]",
)


def test_a_terminal_sees_the_phases_of_a_run(tmp_path, cli, monkeypatch):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    code, stdout, stderr = cli("run", SCENARIOS / "paper_line.toml", *NN, "--out", tmp_path / "run")
    assert code == 0
    phases = [part.strip(" .") for part in stderr.split("\r\033[K") if part.strip(" .") and "warning" not in part]
    assert phases[:3] == [
        "identifying the robot: the NN emulator's pre-training run",
        "simulating 1 s",
        "writing the run folder and its figures",
    ]
    assert "\r" not in stdout  # the results stay plain


def test_a_pipe_sees_no_status_line(tmp_path, cli):
    code, _, stderr = cli("run", SCENARIOS / "paper_line.toml", *NN, "--out", tmp_path / "run")
    assert code == 0 and "\r" not in stderr and "identifying" not in stderr


def test_report_names_what_it_accepts_for_a_sweep_folder(tmp_path, cli):
    sweep = tmp_path / "sweep"
    (sweep / "records").mkdir(parents=True)
    (sweep / "results.parquet").write_bytes(b"PAR1")
    code, _, stderr = cli("report", sweep)
    assert code == 2 and "is a sweep folder" in stderr and "run, reproduce, mc and bench" in stderr
    assert "results.csv" in stderr and "Traceback" not in stderr
