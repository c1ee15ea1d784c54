"""A run whose numbers may not mean what they seem says so: `warnings` in metrics.json, printed by `run` on
stderr, counted by `mc` (and by `sweep`/`bench` through the same records)."""

from __future__ import annotations

import json

import pyarrow.parquet as pq
import pytest
from conftest import SCENARIOS

from ddtrack.metrics import warning_counts

# a Burger whose emulator barely trains (1 s of data, 1 epoch): identification fails, as it did silently before
FAILED_IDENTIFICATION = (
    "--set",
    "controller.identification_duration=1",
    "--set",
    "controller.epochs=1",
    "--set",
    "simulation.duration=4",
    "--set",
    "simulation.metric_window=[0, 4]",
)


def test_run_reports_a_failed_identification(tmp_path, cli):
    out = tmp_path / "run"
    code, stdout, stderr = cli("run", SCENARIOS / "burger_sized_20hz.toml", *FAILED_IDENTIFICATION, "--out", out)
    assert code == 0  # the run itself is whole; what it means is qualified
    warnings = json.loads((out / "metrics.json").read_text())["warnings"]
    assert "identification_failed" in {w["code"] for w in warnings}
    assert "warning: the emulator's identification failed" in stderr and "[identification_failed]" in stderr
    assert "warning" not in stdout


def test_a_clean_run_has_an_empty_warnings_list(tmp_path, cli):
    out = tmp_path / "run"
    # a gentle circle (the paper's line approach needs more grip than any floor, and says so)
    code, _, stderr = cli(
        "run",
        SCENARIOS / "circle.toml",
        "--set",
        "simulation.duration=2",
        "--set",
        "simulation.metric_window=[0, 2]",
        "--set",
        "plant.floor_friction=3",
        "--out",
        out,
    )
    assert code == 0 and "warning" not in stderr
    assert json.loads((out / "metrics.json").read_text())["warnings"] == []


def test_warning_counts_count_runs_once_per_code():
    runs = [
        {"warnings": [{"code": "a", "message": ""}, {"code": "a", "message": ""}]},
        {"warnings": [{"code": "b", "message": ""}]},
        {"warnings": []},
    ]
    assert warning_counts(runs) == {"a": 1, "b": 1}


@pytest.mark.slow  # compiles the NN-adaptive batch
def test_mc_counts_warnings_per_controller(tmp_path, cli):
    out = tmp_path / "mc"
    code, stdout, _ = cli(
        "mc",
        SCENARIOS / "burger_sized_20hz.toml",
        "-n",
        "2",
        "--controllers",
        "nn_adaptive_backstepping",
        *FAILED_IDENTIFICATION[:4],
        "--set",
        "simulation.duration=2",
        "--set",
        "simulation.metric_window=[0, 2]",
        "--out",
        out,
    )
    assert code == 0
    assert "warnings: identification_failed x 2" in stdout  # (and the rims' speed, on this Burger-sized robot)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["controllers"]["nn_adaptive_backstepping"]["warnings"]["identification_failed"] == 2
    codes = pq.read_table(out / "runs.parquet").column("warning_codes").to_pylist()
    assert sum("identification_failed" in code for code in codes) == 2
