"""One compiled program per structure: a study's runs that differ only in numbers (a robot's substep count, the
length of its command delay, its mass, a controller's gains, the trajectory it follows) share the simulation
program and one batched call; only structure (the plant's kind and sensing chain, the controller's kind) adds one
(docs/benchmarks.md, "What a study compiles")."""

from __future__ import annotations

import dataclasses

import jax
import pytest
from distributed import Client, LocalCluster

from ddtrack.compilations import counting_programs
from ddtrack.studies.batches import monte_carlo
from ddtrack.studies.cells import planned_key
from ddtrack.studies.robot_suite import RobotSuite, plan_robot_suite
from ddtrack.studies.suite import BASELINE, SUITES, TUNED, plan_suite
from ddtrack.studies.sweep import read_records, run_sweep
from ddtrack.studies.tasks import finite, plan_tasks

SHORT = ("simulation.duration=1.0", "simulation.metric_window=[0.0, 1.0]")
SIMULATION = "jit(_metric_series)"  #: the batch program a study's tasks run (studies.cells.cells_rows)
#: the robots suite's conditions by what they add to the loop's structure: a command queue, odometry, or nothing
SENSING = {"latency_50ms": "queue", "latency_150ms": "queue", "odometry": "odometry"}


def run_study(plan, out):
    """(simulation programs lowered, programs the study said it needs, its records) running ``plan`` as ``ddtrack
    bench`` does (run_sweep: its cells' keys, its tasks batched across cells), on a worker thread in this process
    (so the count sees its compilations), from an empty in-memory cache (each structure counts once, whatever the
    tests before compiled)."""
    jax.clear_caches()
    said = []
    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster,
        Client(cluster) as client,
        counting_programs() as counts,
    ):
        run_sweep(plan, out, client, on_programs=lambda needed, held: said.append(needed))
    return counts[SIMULATION], said[0], read_records(out)


@pytest.mark.slow
def test_the_robots_suite_compiles_one_program_per_structure(tmp_path):
    # the Burger's nominal, 0.4-grip and payload cells need 157, 73 and 162 substeps, its delays queues of 1 and 3
    # commands, its paths a square and a figure eight: numbers, one program; its odometry and its delays are structure
    suite = RobotSuite(robots=("turtlebot3_burger",), seeds=2, overrides=SHORT)
    plan = plan_robot_suite(suite, ["backstepping", "kinematic_backstepping"])
    structures = {(c.labels["robot"], c.controller, SENSING.get(c.labels["condition"])) for c in plan.configurations}
    assert {c.labels["trajectory"] for c in plan.configurations} == {"square", "figure_eight"}
    assert len(plan.configurations) == 24 and len(structures) == 6
    programs, needed, records = run_study(plan, tmp_path / "robots")
    assert programs == needed == len(structures)
    assert len(records) == 48 and all(r["status"] == "ok" for r in records.values())


@pytest.mark.slow
def test_the_quick_suite_runs_its_cells_as_one_batch_with_each_cells_bits(tmp_path):
    # the robustness map's masses and frictions, the tuned gains of backstepping and the paths are numbers
    suite = dataclasses.replace(SUITES["quick"], overrides=SHORT)
    plan = plan_suite(suite, [BASELINE, TUNED], tuned_gains=[2.0, 300.0, 20.0])
    kinds = {TUNED: BASELINE}
    structures = {kinds.get(c.controller, c.controller) for c in plan.configurations}
    assert len({c.scenario.trajectory.kind for c in plan.configurations}) > 1
    assert len(plan.configurations) == 14 and len(structures) == 1
    programs, needed, records = run_study(plan, tmp_path / "quick")
    assert programs == needed == len(structures)
    # its 28 runs are two tasks of 14, each batching seven cells
    frame = plan.trajectory_frame()
    keys = {i: planned_key(c.scenario, frame) for i, c in enumerate(plan.configurations)}
    missing: dict[int, list] = {}
    for key, (index, seed) in plan.runs.items():
        missing.setdefault(index, []).append((key, seed))
    tasks = plan_tasks(plan.configurations, plan.chunk, missing, keys)
    assert [(len(cells), size) for cells, size, _ in tasks] == [(7, 14), (7, 14)]
    # a batch of 14 runs across cells gives each run the bits of its cell's own batch (below 16 runs a batch)
    for index in (0, 5, 13):
        configuration = plan.configurations[index]
        alone = monte_carlo(configuration.scenario, [0, 1], chunk_size=2, frame=frame)
        for row in alone:
            (record,) = [r for r in records.values() if r["configuration"] == configuration.describe() and
                         r["seed"] == row["seed"]]  # fmt: skip
            assert record["metrics"] == finite({k: v for k, v in row.items() if k != "seed"})

