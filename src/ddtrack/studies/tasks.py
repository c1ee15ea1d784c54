"""A study's tasks: the runs of cells that share a simulation program, grouped into batches of one size, and what a
task returns (a record per run, an error record for a run whose cell or batch raised)."""

from __future__ import annotations

import math
import traceback
from collections.abc import Sequence
from typing import Any

from ..compilations import release_compilations
from ..runner import prepare_batch
from ..scenario import Scenario
from ..trajectories.switched import TrajectoryFrame
from .cells import cells_rows, planned_key, task_size

ERROR = "error"  #: status of a run whose task raised; such runs are retried when the study restarts


def error_record(key: str, configuration: dict[str, Any], seed: int, text: str) -> dict:
    """The record of a run that raised: status ``error``, no metrics, the error's ``text``."""
    return {"key": key, "configuration": configuration, "seed": seed, "status": ERROR, "metrics": None, "error": text}


def finite(value: Any) -> Any:
    """NaN and inf become None, so records are strict JSON."""
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


Task = list[tuple[Scenario, dict[str, Any], list[tuple[str, int]]]]  #: per cell: scenario, configuration, (key, seed)s


def run_cells(cells: Task, size: int, frame: TrajectoryFrame | None = None) -> list[dict]:
    """The task: simulate the runs of ``cells`` (each a scenario, its configuration and its (key, seed) pairs), those
    that share a simulation program in batches of ``size`` (:func:`ddtrack.studies.cells.cells_rows`), the
    trajectory in the study's ``frame``; return one record per run. A cell that cannot be prepared, or a batch that
    raises, becomes error records, not a lost task."""
    release_compilations()  # a worker compiles every structure it runs: stay clear of the mapping limit
    records: list[dict] = []
    ready = []
    for scenario, configuration, runs in cells:
        seeds = [seed for _, seed in runs]
        try:
            setup, draws = prepare_batch(scenario, seeds, frame=frame)
        except Exception as exc:
            records += error_records(exc, configuration, runs)
            continue
        ready.append(((scenario, setup, draws), seeds, configuration, runs))
    try:
        rows = cells_rows([(prepared, seeds) for prepared, seeds, _, _ in ready], size)
    except Exception as exc:
        return records + [
            record for *_, configuration, runs in ready for record in error_records(exc, configuration, runs)
        ]
    for (_, _, configuration, runs), cell_rows in zip(ready, rows, strict=True):
        for (key, seed), row in zip(runs, cell_rows, strict=True):
            metrics = {k: v for k, v in row.items() if k != "seed"}
            records.append(
                {
                    "key": key,
                    "configuration": configuration,
                    "seed": seed,
                    "status": metrics["status"],
                    "metrics": finite(metrics),
                    "error": None,
                }
            )
    return records


def error_records(exc: BaseException, configuration: dict[str, Any], runs: Sequence[tuple[str, int]]) -> list[dict]:
    """:func:`error_record` for each of ``runs`` ((key, seed) pairs), ``exc`` the reason."""
    text = "".join(traceback.format_exception_only(exc)).strip()
    return [error_record(key, configuration, seed, text) for key, seed in runs]


def _planned_key(scenario: Scenario, frame: TrajectoryFrame | None) -> str | None:
    try:
        return planned_key(scenario, frame)
    except Exception:
        return None  # its task records why


def planned_keys(
    client: Any, configurations: Sequence[Any], indices: Sequence[int], frame: TrajectoryFrame | None
) -> dict[int, str]:
    """The program key (:func:`~ddtrack.studies.cells.planned_key`) of each configuration in ``indices``, computed on
    ``client``'s workers (which build what their tasks will build anyway); a configuration that cannot be prepared
    gets a key of its own, so that its task records why."""
    scenarios = [configurations[i].scenario for i in indices]
    planned = client.gather(client.map(_planned_key, scenarios, frame=frame, pure=False))
    return {index: key or f"unprepared {index}" for index, key in zip(indices, planned, strict=True)}


def plan_tasks(
    configurations: Sequence[Any], chunk: int, missing: dict[int, list[tuple[str, int]]], keys: dict[int, str]
) -> list[tuple[Task, int, str]]:
    """The tasks (cells, batch size, program key) that run ``missing`` (configuration index -> its (key, seed)s),
    the runs of configurations with equal program ``keys`` batched together, at most ``chunk`` a task, every task of
    one structure the same size (:func:`~ddtrack.studies.cells.task_size`): one program per structure."""
    groups: dict[str, list[tuple[int, tuple[str, int]]]] = {}
    for index in sorted(missing):
        groups.setdefault(keys[index], []).extend((index, pair) for pair in sorted(missing[index], key=lambda p: p[1]))
    tasks = []
    for key, runs in groups.items():
        size = task_size(len(runs), chunk)
        for start in range(0, len(runs), size):
            cells: dict[int, list[tuple[str, int]]] = {}
            for index, pair in runs[start : start + size]:
                cells.setdefault(index, []).append(pair)
            task = [(configurations[i].scenario, configurations[i].describe(), pairs) for i, pairs in cells.items()]
            tasks.append((task, size, key))
    return tasks
