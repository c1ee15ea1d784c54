"""One compiled program per structure: a study's runs that differ only in numbers (a robot's substep count, the
length of its command delay, its mass, a controller's gains, the trajectory it follows) share the simulation
program; only structure (the plant's kind and sensing chain, the controller's kind) adds one (docs/benchmarks.md)."""

from __future__ import annotations

import dataclasses

import jax
import pytest

from ddtrack.compilations import counting_programs
from ddtrack.robot_suite import RobotSuite, plan_robot_suite
from ddtrack.runner import monte_carlo
from ddtrack.suite import BASELINE, SUITES, TUNED, plan_suite

SHORT = ("simulation.duration=1.0", "simulation.metric_window=[0.0, 1.0]")
SIMULATION = "jit(_metric_series)"  #: the batch program a study's cell runs (runner.batch_metrics)
#: the robots suite's conditions by what they add to the loop's structure: a command queue, odometry, or nothing
SENSING = {"latency_50ms": "queue", "latency_150ms": "queue", "odometry": "odometry"}


def simulation_programs(plan, seeds=(0, 1)) -> int:
    """The simulation programs lowered running every cell of ``plan`` as the sweep's task does (in the study's
    trajectory frame), from an empty in-memory cache (so each structure counts once, whatever the tests before
    compiled)."""
    frame = plan.trajectory_frame()
    jax.clear_caches()
    with counting_programs() as counts:
        for configuration in plan.configurations:
            monte_carlo(configuration.scenario, list(seeds), chunk_size=len(seeds), frame=frame)
    return counts[SIMULATION]


@pytest.mark.slow
def test_the_robots_suite_compiles_one_program_per_structure():
    # the Burger's nominal, 0.4-grip and payload cells need 157, 73 and 162 substeps, its delays queues of 1 and 3
    # commands, its paths a square and a figure eight: numbers, one program; its odometry and its delays are structure
    suite = RobotSuite(robots=("turtlebot3_burger",), seeds=2, overrides=SHORT)
    plan = plan_robot_suite(suite, ["backstepping", "kinematic_backstepping"])
    structures = {(c.labels["robot"], c.controller, SENSING.get(c.labels["condition"])) for c in plan.configurations}
    assert {c.labels["trajectory"] for c in plan.configurations} == {"square", "figure_eight"}
    assert len(plan.configurations) == 24 and len(structures) == 6
    assert simulation_programs(plan) == len(structures)


@pytest.mark.slow
def test_the_quick_suite_compiles_one_program_per_controller_kind():
    # the robustness map's masses and frictions, the tuned gains of backstepping and the paths are numbers
    suite = dataclasses.replace(SUITES["quick"], overrides=SHORT)
    plan = plan_suite(suite, [BASELINE, TUNED], tuned_gains=[2.0, 300.0, 20.0])
    kinds = {TUNED: BASELINE}
    structures = {kinds.get(c.controller, c.controller) for c in plan.configurations}
    assert len({c.scenario.trajectory.kind for c in plan.configurations}) > 1
    assert len(plan.configurations) == 14 and len(structures) == 1
    assert simulation_programs(plan) == len(structures)
