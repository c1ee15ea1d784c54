"""``ddtrack bench``: the leaderboard is computed from the runs (paired by cell and seed), resumes, and refuses bad
input. A tiny suite (short runs, one worker on 127.0.0.1) keeps it fast; the real suites are in docs/benchmarks.md."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from ddtrack.studies.suite import TUNED, Suite, plan_suite, run_suite

SHORT = ("simulation.duration=4", "simulation.metric_window=[1, 4]")
TINY = Suite(
    trajectories=("line", "sinusoid"),
    levels=("paper", "severe"),
    seeds=2,
    robustness_mass=(1.0, 1.5),
    robustness_friction=(1.0,),
    tune_steps=1,
    overrides=SHORT,
)
CONTROLLERS = ["backstepping", "ltv_lqr", TUNED]


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    from distributed import Client

    from ddtrack.cluster import local_cluster

    out = tmp_path_factory.mktemp("bench")
    (out / "tuned.toml").write_text('[controller]\nkind = "backstepping"\ngains = [2.0, 80.0, 20.0]\n')  # no tuning
    with local_cluster(1) as cluster, Client(cluster) as client:
        first = run_suite(TINY, CONTROLLERS, out, client)
        again = run_suite(TINY, CONTROLLERS, out, client)
    return out, first, again


def test_every_cell_runs_once_and_a_rerun_reuses_them(finished):
    _out, first, again = finished
    cells = len(CONTROLLERS) * (2 * 2 + 2 * 1) * 2  # controllers x (trajectories x levels + map cells) x seeds
    assert first["runs"] == cells and first["reused"] == 0 and first["errors"] == 0
    assert again["reused"] == cells and again["leaderboard"] == first["leaderboard"]
    assert first["tuned_gains"] == [2.0, 80.0, 20.0]  # taken from out/tuned.toml


def test_leaderboard_is_computed_from_the_runs(finished):
    out, first, _ = finished
    runs = pq.read_table(out / "results.parquet").to_pylist()
    board = {e["controller"]: e for e in first["leaderboard"]}
    leaderboard_runs = [r for r in runs if r["label.study"] == "leaderboard"]

    def tracked(r):  # neither failed nor ended off its path: only these are averaged
        return r["status"] == "ok" and not r["lost_path"]

    for name in CONTROLLERS:
        mine = [r for r in leaderboard_runs if r["controller"] == name]
        assert board[name]["runs"] == 2 * 2 * 2
        assert board[name]["lost"] == sum(r["status"] == "ok" and r["lost_path"] for r in mine)
        expected = np.mean([r["e_tr_mean"] for r in mine if tracked(r)])
        assert board[name]["e_tr_mean"]["mean"] == pytest.approx(expected)

    # the paired improvement over backstepping, by (trajectory, level, seed), over the pairs where both tracked
    def cell(r):
        return r["label.trajectory"], r["label.level"], r["seed"]

    baseline = {cell(r): r for r in leaderboard_runs if r["controller"] == "backstepping"}
    pairs = [(baseline[cell(r)], r) for r in leaderboard_runs if r["controller"] == "ltv_lqr"]
    both = [(b["e_tr_mean"], r["e_tr_mean"]) for b, r in pairs if tracked(b) and tracked(r)]
    pooled = 100 * (1 - sum(r for _, r in both) / sum(b for b, _ in both))
    assert board["ltv_lqr"]["improvement_over_backstepping"]["mean"] == pytest.approx(pooled)
    assert board["ltv_lqr"]["improvement_over_backstepping"]["n"] == len(both)
    means = [e["e_tr_mean"]["mean"] for e in first["leaderboard"]]
    assert means == sorted(means)  # ranked by mean tracking error
    table = pq.read_table(out / "leaderboard.parquet")
    assert table.column("controller").to_pylist() == [e["controller"] for e in first["leaderboard"]]
    text = (out / "leaderboard.md").read_text()
    assert "| ltv_lqr |" in text and "sinusoid / severe" in text
    for figure in ("robustness.png", "boxplots.png"):
        assert (out / figure).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((out / "leaderboard.json").read_text())["controllers"] == CONTROLLERS


def test_common_random_numbers_across_controllers(finished):
    out, _, _ = finished
    runs = pq.read_table(out / "results.parquet").to_pylist()
    # within a cell the controllers' scenarios differ only in [controller], and the seeds pair up: a run's draws
    # come from its seed alone (runner.streams), so every controller meets the same plant, disturbance and noise
    severe = [r for r in runs if r.get("label.level") == "severe"]
    assert {r["seed"] for r in severe} == {0, 1}
    plan = plan_suite(TINY, CONTROLLERS, [2.0, 80.0, 20.0])
    by_cell = {}
    for configuration in plan.configurations:
        key = tuple(sorted(configuration.labels.items()))
        scenario = configuration.scenario.model_dump(exclude={"controller"})
        by_cell.setdefault(key, []).append(scenario)
    for scenarios in by_cell.values():
        assert len(scenarios) == len(CONTROLLERS) and all(s == scenarios[0] for s in scenarios)


@pytest.mark.parametrize(
    "args, field",
    [
        (["--controllers", "backstepping,nope"], "--controllers"),
        (["--controllers", "ltv_lqr,ltv_lqr"], "--controllers"),
        (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--workers"),
    ],
)
def test_bench_bad_input_exits_2_and_writes_nothing(tmp_path, cli, args, field):
    code, _, stderr = cli("bench", *args, "--out", tmp_path / "bench")
    assert code == 2 and stderr.startswith(f"error: {field}"), stderr
    assert not (tmp_path / "bench").exists()


@pytest.mark.parametrize("name", ["quick", "standard"])
def test_every_suite_plans_with_its_default_controllers(name):
    """``bench --suite quick`` and ``standard`` without ``--controllers`` rank every kind that tracks a reference in
    closed loop: every cell of every one resolves (a kind that needs a plan, replay, once made both exit 2)."""
    from ddtrack.scenario import tracking_kinds
    from ddtrack.studies.suite import SUITES, controller_names

    names = controller_names(None)
    assert names == [*tracking_kinds(), TUNED] and "replay" not in names
    plan = plan_suite(SUITES[name], names, (1.0, 55.0, 15.0))
    suite = SUITES[name]
    cells = len(suite.trajectories) * len(suite.levels) + len(suite.robustness_mass) * len(suite.robustness_friction)
    assert len(plan.configurations) == len(names) * cells
    assert {c.controller for c in plan.configurations} == set(names)
