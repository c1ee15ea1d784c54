"""A study's cells batched by structure: the runs of every cell that shares a simulation program, in one call.

A study (a sweep, a ``bench`` suite) has cells that differ in numbers: a robot's mass or grip, a controller's gains,
its delay, the trajectory it follows in the study's frame, its duration. Runs whose simulation program is the same
(:func:`program_key`: the pytree structure of plant, controller, trajectory, noise and draws, each leaf's shape and
type, the run's length rounded up to one of a few (:func:`~ddtrack.runner.run_length`), the substeps) are joined
along the run axis, each with its own numbers (divergence bound, control period), and simulated in one batched call;
each cell's rows then become its metrics under its own scenario (:func:`~ddtrack.studies.batches.series_metrics`).
A ledger beside JAX's persistent compilation cache (:func:`ddtrack.compilations.compiled_programs`) records the
programs studies compiled into it, so a study says at its start how many programs it needs and how many the cache
already holds.
"""

from __future__ import annotations

import os
from collections.abc import Collection, Sequence
from typing import Any

import jax
import numpy as np

from ..compilations import compiled_programs, ledger_entry, record_compiled
from ..runner import prepare_batch, run_length, simulation_args
from ..scenario import Scenario, Setup
from ..sim import Draws
from ..trajectories.switched import TrajectoryFrame
from .batches import drawn_plant, metric_series, series_metrics

#: the most runs a ``bench`` suite's task batches across its cells: below 16 runs a batch, every row is its single
#: run's bits (docs/reliability.md), and two shares of 7 keep both cores busy
SUITE_TASK = 14

Prepared = tuple[Scenario, Setup, Draws]  #: a cell's scenario and its runs, prepared (runner.prepare_batch)


def program_key(scenario: Scenario, setup: Setup, draws: Draws) -> str:
    """What the simulation program of a prepared batch's runs depends on, as text: the runs' pytree structure (static
    fields, the substeps among them, included), each leaf's shape without the run axis and its type, and the run's
    length. Equal keys: the runs can share one batched call."""
    length = run_length(scenario)
    leaves, structure = jax.tree_util.tree_flatten(simulation_args(scenario, setup, draws, length))
    shapes = [(tuple(np.shape(leaf))[1:], str(getattr(leaf, "dtype", type(leaf).__name__))) for leaf in leaves]
    return f"{structure} {shapes} n_steps={length}"


def planned_key(scenario: Scenario, frame: TrajectoryFrame | None) -> str:
    """:func:`program_key` of ``scenario``'s runs in the study's ``frame``, before anything is identified or run."""
    return program_key(scenario, *prepare_batch(scenario, [scenario.simulation.seed], frame=frame, identify=False))


def task_size(runs: int, most: int) -> int:
    """Runs per task for ``runs`` of one structure, at most ``most`` a task: the tasks as even as they can be (so
    each structure compiles one program, for one batch size), rounded up to an even size (so a batch splits evenly
    over two devices)."""
    tasks = -(-runs // most)
    size = -(-runs // tasks)
    even = size + size % 2
    return even if even <= max(most, 2) else size


def batch_program(key: str, size: int, *, whole: bool = False) -> str:
    """The ledger's name of the program of ``key``'s runs in batches of ``size``: the metrics program
    (:func:`.batches.metric_series`), or with ``whole`` the one that records every series
    (:func:`ddtrack.runner.run_setup`)."""
    return f"{key} size={size}" + (" whole" if whole else "")


def programs_held(programs: Collection[str]) -> int:
    """How many of the distinct ``programs`` (:func:`batch_program`) the persistent cache holds, by its ledger."""
    compiled = compiled_programs()
    return sum(ledger_entry(program) in compiled for program in set(programs))


def _rows(tree: Any, rows: slice) -> Any:
    return jax.tree_util.tree_map(lambda leaf: leaf[rows], tree)


def _padded(tree: Any, size: int) -> Any:
    """``tree``'s runs followed by copies of its first, ``size`` in all."""
    return jax.tree_util.tree_map(lambda leaf: np.concatenate([leaf, np.repeat(leaf[:1], size - len(leaf), 0)]), tree)


def cells_rows(cells: Sequence[tuple[Prepared, Sequence[int]]], size: int) -> list[list[dict]]:
    """Each cell's rows (as :func:`.batches.monte_carlo` gives them: ``seed``, the plant's drawn values, the
    metrics), the runs of the cells that share a :func:`program_key` simulated together in batches of ``size`` (the
    last padded with copies of its first run, so every batch of a structure is one program). ``cells``: each cell's
    prepared runs and their seeds. A batch's rows are the bits a batch of ``size`` gives them."""
    keys = [program_key(*prepared) for prepared, _ in cells]
    results: list[list[dict]] = [[] for _ in cells]
    for key in dict.fromkeys(keys):
        members = [i for i, k in enumerate(keys) if k == key]
        length = run_length(cells[members[0]][0][0])  # the same for every member: part of the key
        runs = [jax.tree_util.tree_map(np.asarray, simulation_args(*cells[i][0], length)) for i in members]
        joined = jax.tree_util.tree_map(lambda *leaves: np.concatenate(leaves), *runs)
        total, outputs = sum(len(cells[i][1]) for i in members), []
        for start in range(0, total, size):
            part = _rows(joined, slice(start, start + size))
            used = min(size, total - start)
            outputs.append(_rows(metric_series(_padded(part, size), length), slice(0, used)))
        record_compiled([ledger_entry(batch_program(key, size))])
        series = jax.tree_util.tree_map(lambda *leaves: np.concatenate(leaves), *outputs)
        start = 0
        for i in members:
            (scenario, setup, _), seeds = cells[i]
            rows = _rows(series, slice(start, start + len(seeds)))
            start += len(seeds)
            metrics = series_metrics(scenario, setup, *rows)
            results[i] = [
                {"seed": seed, **drawn_plant(scenario, setup, j), **row}
                for j, (seed, row) in enumerate(zip(seeds, metrics, strict=True))
            ]
    return results


def cache_on_every_worker(client: Any) -> None:
    """float64 (:func:`ddtrack.enable_float64`) and JAX's persistent compilation cache
    (:func:`ddtrack.compilations.enable_compilation_cache`) on every worker process of ``client``'s cluster, now and as
    workers join or restart: set once by the driver, as a worker plugin, so that a task never changes its worker's
    settings. A threaded worker in the driver's own process is left alone: that process is its caller's."""
    from distributed import WorkerPlugin

    class CompilationCache(WorkerPlugin):
        name = "ddtrack-compilation-cache"

        def __init__(self, driver_pid: int) -> None:
            self.driver_pid = driver_pid

        def setup(self, worker: Any) -> None:
            if os.getpid() != self.driver_pid:
                from ddtrack.compilations import enable_compilation_cache
                from ddtrack.precision import enable_float64

                enable_float64()
                enable_compilation_cache()

    client.register_plugin(CompilationCache(os.getpid()))
