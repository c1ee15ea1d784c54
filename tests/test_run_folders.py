"""An output folder holds exactly one command's output: a rerun replaces it whole (nothing of the earlier run
left behind), another command's output needs --overwrite, a folder ddtrack did not write is never touched, and a
refusal comes before any simulation (exit code 2)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import SCENARIOS

import ddtrack.runner
import ddtrack.studies.mc
from ddtrack import outdir
from ddtrack.errors import RunError

SHORT = ("--set", "simulation.duration=1.0", "--set", "simulation.metric_window=[0.0, 1.0]")
NN_SHORT = (
    "--controller",
    "nn_adaptive_backstepping",
    "--set",
    "controller.epochs=1",
    "--set",
    "controller.identification_duration=1",
)


def snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {
        str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def refuse_to_simulate(*args, **kwargs):
    raise AssertionError("simulated although the output folder was refused")


def test_a_rerun_leaves_nothing_of_the_earlier_run(tmp_path, cli):
    out = tmp_path / "run"
    code, _, _ = cli("run", SCENARIOS / "paper_line.toml", *SHORT, *NN_SHORT, "--out", out)
    assert code == 0 and (out / "identification.json").is_file()
    (out / "animation.gif").write_bytes(b"GIF89a")  # as `ddtrack animate` leaves it
    (out / "report.html").write_text("<html>the NN run's report</html>")  # as `ddtrack report` leaves it
    code, _, _ = cli("run", SCENARIOS / "paper_line.toml", *SHORT, "--out", out)
    assert code == 0
    names = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    assert not {"identification.json", "figures/gains.png", "report.html", "animation.gif"} & set(names)
    assert json.loads((out / "ddtrack.json").read_text())["command"] == "run"
    assert "nn_adaptive" not in (out / "scenario.toml").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no staging or old folder left beside it


def test_another_commands_output_is_refused_without_overwrite(tmp_path, cli, monkeypatch):
    out = tmp_path / "out"
    assert cli("run", SCENARIOS / "paper_line.toml", *SHORT, "--out", out)[0] == 0
    before = snapshot(out)
    monkeypatch.setattr(ddtrack.studies.mc, "run_specs", refuse_to_simulate)
    code, _, stderr = cli("mc", SCENARIOS / "paper_line.toml", "-n", "2", *SHORT, "--out", out)
    assert code == 2 and "Traceback" not in stderr
    assert "`ddtrack run`" in stderr and "--overwrite" in stderr and str(out) in stderr
    assert snapshot(out) == before  # nothing touched, not even a timestamp


@pytest.mark.slow  # compiles the Monte Carlo batch
def test_overwrite_replaces_another_commands_output_whole(tmp_path, cli):
    out = tmp_path / "out"
    assert cli("run", SCENARIOS / "paper_line.toml", *SHORT, "--out", out)[0] == 0
    code, _, _ = cli("mc", SCENARIOS / "paper_line.toml", "-n", "2", *SHORT, "--out", out, "--overwrite")
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == ["ddtrack.json", "runs.csv", "runs.parquet", "summary.json"]


@pytest.mark.parametrize("overwrite", [(), ("--overwrite",)])
def test_a_folder_ddtrack_did_not_write_is_never_touched(tmp_path, cli, monkeypatch, overwrite):
    monkeypatch.setattr(ddtrack.runner, "run_setup", refuse_to_simulate)
    out = tmp_path / "thesis"
    (out / "chapter1").mkdir(parents=True)
    (out / "chapter1" / "draft.tex").write_text("months of work")
    before = snapshot(out)
    code, _, stderr = cli("run", SCENARIOS / "paper_line.toml", *SHORT, "--out", out, *overwrite)
    assert code == 2 and "did not write" in stderr and "Traceback" not in stderr
    assert snapshot(out) == before


def test_a_folder_from_before_the_marker_is_known_by_its_files(tmp_path):
    old_run = tmp_path / "old"
    old_run.mkdir()
    (old_run / "metrics.json").write_text("{}")
    assert outdir.check_output(old_run, command="run", overwrite=False) is False  # replaced, not refused
    with pytest.raises(RunError, match="`ddtrack run`.*--overwrite"):
        outdir.check_output(old_run, command="mc", overwrite=False)


def test_sweep_and_bench_resume_only_their_own_study(tmp_path):
    out = tmp_path / "sweep"
    assert outdir.check_output(out, command="sweep", overwrite=False, study="a") is False
    outdir.start_resumable(out, command="sweep", study="a", resume=False)
    (out / "records").mkdir()
    (out / "records" / "k.json").write_text("{}")
    assert outdir.check_output(out, command="sweep", overwrite=False, study="a") is True  # resume
    with pytest.raises(RunError, match="another `ddtrack sweep` study.*--overwrite"):
        outdir.check_output(out, command="sweep", overwrite=False, study="b")
    assert outdir.check_output(out, command="sweep", overwrite=True, study="b") is False
    outdir.start_resumable(out, command="sweep", study="b", resume=False)
    assert sorted(p.name for p in out.iterdir()) == ["ddtrack.json"]  # the other study's records are gone
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sweep"]


def test_a_sweep_into_another_sweeps_folder_is_refused_before_any_cluster(tmp_path, cli):
    sweep_file = tmp_path / "s.toml"
    sweep_file.write_text(
        f'scenario = "{SCENARIOS / "figure_eight.toml"}"\ncontrollers = ["backstepping"]\n'
        'seeds = 1\n[grid]\n"robot.mass" = [9.0, 10.0]\n'
    )
    out = tmp_path / "out"
    outdir.start_resumable(out, command="sweep", study="some other plan", resume=False)
    before = snapshot(out)
    code, _, stderr = cli("sweep", sweep_file, "--out", out, "--workers", "1")
    assert code == 2 and "another `ddtrack sweep` study" in stderr, stderr
    assert snapshot(out) == before


def test_staged_folder_failing_midway_keeps_the_old_output(tmp_path):
    out = tmp_path / "out"
    with outdir.staged_folder(out, command="tune") as stage:
        (stage / "tune.json").write_text("old")
    with pytest.raises(ZeroDivisionError), outdir.staged_folder(out, command="tune") as stage:
        (stage / "tune.json").write_text("new, half done")
        raise ZeroDivisionError("a failure midway")
    assert (out / "tune.json").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
