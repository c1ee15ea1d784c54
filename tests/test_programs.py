"""One compiled program per structure: a study's runs that differ only in numbers (a robot's substep count, the
length of its command delay, its mass, a controller's gains, the trajectory it follows) share the simulation
program and one batched call; only structure (the plant's kind and sensing chain, the controller's kind) adds one
(docs/benchmarks.md, "What a study compiles")."""

from __future__ import annotations

import dataclasses

import jax
import pytest
from conftest import SCENARIOS
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


EXPORTED_RUNS = """
import hashlib, json, sys
import jax
import numpy as np
import ddtrack
from ddtrack import compilations, runner
from ddtrack.studies import batches

ddtrack.enable_float64()
compilations.enable_compilation_cache()  # in $DDTRACK_CACHE_DIR, as the ddtrack command and a study's workers do
if sys.argv[1] == "again":  # a later process: the program is read back, never exported again
    jax.export.export = lambda *args, **kwargs: sys.exit("exported again")
scenario = ddtrack.load_scenario(sys.argv[2], overrides=sys.argv[3:])


def single_run():  # every column of a run as the hash of its bytes (a NaN torque column included)
    columns = ddtrack.timeseries(ddtrack.run(scenario, seed=1))
    return {name: hashlib.sha256(np.ascontiguousarray(value).tobytes()).hexdigest() for name, value in columns.items()}


rows = {"exported": batches.monte_carlo(scenario, [0, 1, 2, 3], chunk_size=4), "run exported": single_run()}
compilations.exported = lambda *args: None  # the plain jit of the same functions
jax.clear_caches()
rows |= {"jit": batches.monte_carlo(scenario, [0, 1, 2, 3], chunk_size=4), "run jit": single_run()}
print(json.dumps(rows))
"""


@pytest.mark.parametrize("name", ["burger_cmd_vel_figure8", "paper_square"])
def test_an_exported_program_gives_the_jitted_bits(name, tmp_path):
    """A study's batch program and a single run's, exported beside the persistent cache (compilations.exported), then
    read back by a later process instead of traced again, give every metric and every column of the plain jitted
    programs to the bit: a sensed,
    motor-driven Burger (whose control period reaches the program as a traced argument, as it does in the jit;
    as a constant XLA folded it and moved the bits) and the paper's torque-driven square."""
    import json
    import os
    import subprocess
    import sys

    environment = os.environ | {"DDTRACK_CACHE_DIR": str(tmp_path), "JAX_PLATFORMS": "cpu"}
    command = [sys.executable, "-c", EXPORTED_RUNS]
    scenario = [str(SCENARIOS / f"{name}.toml"), *SHORT]
    outputs = []
    for stage in ("first", "again"):
        run = [*command, stage, *scenario]
        done = subprocess.run(run, env=environment, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        outputs.append(json.loads(done.stdout))
    assert len(list((tmp_path / "jax" / "ddtrack-exported").glob("*.bin"))) == 2  # the batch's and the run's
    first, again = outputs
    assert first["exported"] == first["jit"] == again["exported"] == again["jit"]
    assert all(row["status"] == "ok" for row in first["jit"])
    assert first["run exported"] == first["run jit"] == again["run exported"] == again["run jit"]
    assert len(first["run jit"]) >= 19  # every documented column


def test_only_a_structure_its_key_can_name_is_exported():
    """The key of an exported program names every node's type and static values: a type from outside ddtrack (a
    plugin's, whose code may change under the same name) or a static value that is not plain data (a function) is
    never exported, two static values give two keys, and numbers (leaves) give one."""
    from ddtrack._pytree import pytree_dataclass
    from ddtrack.compilations import _structure_text
    from ddtrack.integrators import RK4
    from ddtrack.sim.simulate import ClosedLoop

    @pytree_dataclass
    class Plugin:
        gain: float = 1.0

    def text(value):
        return _structure_text(jax.tree_util.tree_structure(value))

    def loop(substeps):
        return ClosedLoop(None, None, None, control_period=0.01, divergence_error=1.0, solver=RK4(substeps))

    assert "ClosedLoop" in text(loop(10)) and "WheelDisturbance" in text((loop(10), 1.0))
    assert text(loop(10)) != text(loop(20))  # a static value: another program
    assert text(loop(10)) == text(dataclasses.replace(loop(10), control_period=0.05))  # a number: the same one
    assert text((loop(10), Plugin())) is None and text([{"a": Plugin()}]) is None
    assert text(loop(len)) is None  # a function as a static value: its name would not say what it does


def test_mc_and_reproduce_say_the_programs_they_compile(tmp_path, monkeypatch):
    """``mc`` and ``reproduce`` say first how many simulation programs they need (as ``sweep`` and ``bench`` do):
    the number they then lower. ``mc``: one per controller (every chunk has one size); ``reproduce``: one per variant
    and case, the paper's line and square being different trajectories."""
    import ddtrack
    import ddtrack.studies.reproduce as reproduce_module
    from ddtrack.studies.mc import run_specs

    specs = {
        name: ddtrack.load_scenario(SCENARIOS / "paper_line.toml", overrides=SHORT, controller=name)
        for name in ("backstepping", "ltv_lqr")
    }
    said = []
    jax.clear_caches()
    with counting_programs() as counts:
        rows = run_specs(specs, n=3, chunk_size=2, on_programs=lambda needed, held: said.append((needed, held)))
    assert said == [(2, 0)] and counts[SIMULATION] == 2  # two controllers; three seeds in two chunks of two
    assert [len(runs) for runs in rows.values()] == [3, 3]

    variants = {"backstepping": ["controller.kind=backstepping", *SHORT], "nn_adaptive": [*reproduce_module.NN, *SHORT]}
    variants["nn_adaptive"] += ["controller.epochs=1", "controller.identification_duration=1"]
    monkeypatch.setattr(reproduce_module, "VARIANTS", variants)
    said.clear()
    jax.clear_caches()
    with counting_programs() as counts:
        reproduce_module.reproduce(tmp_path, seeds=1, on_programs=lambda needed, held: said.append((needed, held)))
    assert said == [(4, 0)] and counts["jit(simulate_batch)"] == 4


def test_a_second_mc_finds_its_programs_in_the_cache(tmp_path):
    """The ``ddtrack mc`` command's first line counts the programs the persistent cache holds, by the ledger its
    first run wrote: none, then both."""
    import os
    import subprocess
    import sys

    environment = os.environ | {"DDTRACK_CACHE_DIR": str(tmp_path / "cache"), "JAX_PLATFORMS": "cpu"}
    command = [sys.executable, "-m", "ddtrack", "mc", str(SCENARIOS / "paper_line.toml"), "-n", "2", "--overwrite"]
    command += ["--controllers", "backstepping,ltv_lqr", "--out", str(tmp_path / "mc")]
    command += [argument for override in SHORT for argument in ("--set", override)]
    lines = []
    for _ in range(2):
        done = subprocess.run(command, env=environment, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        lines.append(done.stderr.splitlines()[0])
    assert lines == [
        "2 simulation programs to run (one per structure); 0 already compiled in the cache",
        "2 simulation programs to run (one per structure); 2 already compiled in the cache",
    ]


def test_switches_are_selects_in_one_program():
    """A circle's direction and backstepping's strict cross term are numbers of the program (selects), not its
    structure: the four cells that combine them share one key and one batched call, and each cell's rows are the
    bits of its own batch."""
    import ddtrack
    from ddtrack.runner import prepare_batch
    from ddtrack.studies.cells import cells_rows, program_key

    cells = []
    for clockwise in ("false", "true"):
        for strict in ("false", "true"):
            overrides = (*SHORT, f"trajectory.clockwise={clockwise}", f"controller.strict={strict}")
            scenario = ddtrack.load_scenario(SCENARIOS / "circle.toml", overrides=overrides)
            cells.append(((scenario, *prepare_batch(scenario, [0, 1])), [0, 1]))
    assert len({program_key(*prepared) for prepared, _ in cells}) == 1
    jax.clear_caches()
    with counting_programs() as counts:
        rows = cells_rows(cells, 8)
    assert counts[SIMULATION] == 1
    alone = [monte_carlo(prepared[0], [0, 1], chunk_size=2) for prepared, _ in cells]
    assert rows == alone
    assert len({row["e_tr_mean"] for cell in rows for row in cell[:1]}) == 4  # each switch changes the run


def test_sensing_delays_and_fix_periods_are_numbers_of_one_program():
    """The measurement delay (an index into a line padded to 16 readings, as the actuation delay's queue) and the
    absolute fix's period (the modulus of its schedule) are traced: cells with delays of 1 and 3 periods and fixes
    every 10 and 25 periods share one program and one batched call, each cell's rows the bits of its own batch.
    Whether a fix exists at all stays structure (its clock and draws are states)."""
    import ddtrack
    from ddtrack.runner import prepare_batch
    from ddtrack.studies.cells import cells_rows, program_key

    cells = []
    for delay in (0.01, 0.03):  # circle.toml's control period is 0.01 s
        for fix in (0.1, 0.25):
            sensing = (f"sensing.measurement_delay={delay}", "sensing.odometry=true", f"sensing.fix_period={fix}")
            scenario = ddtrack.load_scenario(SCENARIOS / "circle.toml", overrides=(*SHORT, *sensing))
            cells.append(((scenario, *prepare_batch(scenario, [0, 1])), [0, 1]))
    assert len({program_key(*prepared) for prepared, _ in cells}) == 1
    no_fix = ddtrack.load_scenario(SCENARIOS / "circle.toml", overrides=(*SHORT, "sensing.odometry=true"))
    assert program_key(no_fix, *prepare_batch(no_fix, [0])) != program_key(*cells[0][0])
    jax.clear_caches()
    with counting_programs() as counts:
        rows = cells_rows(cells, 8)
    assert counts[SIMULATION] == 1
    assert rows == [monte_carlo(prepared[0], [0, 1], chunk_size=2) for prepared, _ in cells]
    assert len({row["e_tr_mean"] for cell in rows for row in cell[:1]}) == 4  # each delay and fix changes the run


def test_runs_of_different_lengths_share_a_program_and_keep_their_own_length():
    """A run is simulated over its length rounded up to a quarter octave (201 and 211 periods both over 216) and cut
    to its own: two durations share one program and one batched call, each run's rows are the bits of its own batch
    and its series have its own length; a failure in the periods past the run's end does not count."""
    import numpy as np

    import ddtrack
    from ddtrack.compilations import bucketed_length
    from ddtrack.runner import prepare_batch, run_length, within_run
    from ddtrack.studies.cells import cells_rows, program_key

    cells = []
    for duration in (2.0, 2.1):
        window = (f"simulation.duration={duration}", f"simulation.metric_window=[0.0, {duration}]")
        scenario = ddtrack.load_scenario(SCENARIOS / "circle.toml", overrides=window)
        cells.append(((scenario, *prepare_batch(scenario, [0, 1])), [0, 1]))
    assert [run_length(prepared[0]) for prepared, _ in cells] == [216, 216] == [bucketed_length(n) for n in (201, 211)]
    assert len({program_key(*prepared) for prepared, _ in cells}) == 1
    jax.clear_caches()
    with counting_programs() as counts:
        rows = cells_rows(cells, 4)
    assert counts[SIMULATION] == 1
    assert rows == [monte_carlo(prepared[0], [0, 1], chunk_size=2) for prepared, _ in cells]
    for (scenario, *_), _ in cells:
        assert len(ddtrack.timeseries(ddtrack.run(scenario))["t"]) == scenario.simulation.n_steps

    run = ddtrack.run(cells[0][0][0])
    padded = run._replace(status=np.asarray(1), failure_index=np.asarray(210))  # diverged at period 210 of 216
    assert within_run(padded, 201).status_name == "ok" and within_run(padded, 201).failure_time is None
    assert within_run(padded._replace(failure_index=np.asarray(150)), 201).status_name == "diverged"


def test_cells_of_different_control_periods_share_a_program():
    """The control period is a per-run number of the batch (each run's ``ClosedLoop`` carries its own): cells at
    0.01 s and 0.0125 s over the same number of periods share one key and one batched call, and each cell's rows are
    the bits of its own batch."""
    import ddtrack
    from ddtrack.runner import prepare_batch
    from ddtrack.studies.cells import cells_rows, program_key

    cells = []
    for period, duration in ((0.01, 2.0), (0.0125, 2.5)):  # 200 periods each
        timing = (f"simulation.control_period={period}", f"simulation.duration={duration}")
        scenario = ddtrack.load_scenario(
            SCENARIOS / "circle.toml", overrides=(*timing, f"simulation.metric_window=[0, {duration}]")
        )
        cells.append(((scenario, *prepare_batch(scenario, [0, 1])), [0, 1]))
    assert len({program_key(*prepared) for prepared, _ in cells}) == 1
    jax.clear_caches()
    with counting_programs() as counts:
        rows = cells_rows(cells, 4)
    assert counts[SIMULATION] == 1
    assert rows == [monte_carlo(prepared[0], [0, 1], chunk_size=2) for prepared, _ in cells]
    assert rows[0][0]["e_tr_mean"] != rows[1][0]["e_tr_mean"]  # the period changes the run
