"""Batches kept as metrics only, and Monte Carlo over seeds.

The batched program records only the series the metrics read (XLA drops the rest: states, references, controls),
each run's metrics are computed from them as :func:`ddtrack.runner.run_metrics` computes a single run's, and
:func:`monte_carlo` runs one scenario over seeds in chunks of one shape.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import jax
import numpy as np
from jax import Array

from ..compilations import bucketed_length, call_exported
from ..model.sensed import ODOMETRY_ERROR
from ..plausibility import traction_columns
from ..runner import failure_within, loading_warnings, prepare_batch, run_length, run_metrics, simulation_args
from ..scenario import Scenario, Setup
from ..sim import STATUS_NAMES, ClosedLoop, Draws, simulate_batch
from ..sim.batch import in_shares
from ..sim.result import finished_columns, recorded_columns
from ..trajectories.switched import TrajectoryFrame

#: the recorded columns metrics and warnings read: the error, the speeds (for the grip the run needed), the logs,
#: a slip plant's wheel spin speeds (at which the motor's curve is checked: :func:`traction_columns`)
METRIC_COLUMNS = ("t", "e_x", "e_y", "v", "omega", "tau_r", "tau_l", "saturated", "kx", "ky", "ktheta", "gate",
                  "slip_r", "slip_l", "slip_lateral", *ODOMETRY_ERROR.names, "phidot_r", "phidot_l")  # fmt: skip


@partial(jax.jit, static_argnames=("n_steps",))
def _metric_series(loop: ClosedLoop, x0: Array, draws: Draws, *, n_steps: int) -> tuple[dict, Array, Array]:
    """:func:`simulate_batch` returning only the series the metrics read: XLA then drops the rest of the
    recording (states, references, controls), which nearly doubles batch throughput (docs/benchmarks.md).
    Each run has its own numbers in ``loop`` (bounds, control period), so runs of different scenarios can share it."""
    result = simulate_batch(loop, x0, draws, n_steps=n_steps)
    return recorded_columns(result, METRIC_COLUMNS), result.status, result.failure_index


def metric_series(runs: tuple, n_steps: int) -> tuple[dict, np.ndarray, np.ndarray]:
    """(series, status, failure index) of a batch of ``runs`` (:func:`~ddtrack.runner.simulation_args` padded to
    ``n_steps``, a :func:`~ddtrack.runner.run_length`, or several scenarios' runs of one structure joined along the
    run axis), split over the devices (:func:`~ddtrack.sim.batch.in_shares`), as NumPy arrays, over ``n_steps``
    periods: :func:`series_metrics` cuts each run to its scenario's periods."""

    def share_series(*share: Any) -> Any:  # a share of the runs
        return call_exported("_metric_series", _metric_series, share, {}, {"n_steps": n_steps})

    return jax.tree_util.tree_map(np.asarray, in_shares(share_series, *runs))


def batch_metrics(scenario: Scenario, setup: Setup, draws: Draws) -> list[dict]:
    """The metrics (:func:`ddtrack.summarize`) of each run of a prepared batch, without keeping its time series."""
    length = run_length(scenario)
    return series_metrics(scenario, setup, *metric_series(simulation_args(scenario, setup, draws, length), length))


def series_metrics(
    scenario: Scenario, setup: Setup, series: dict, status: np.ndarray, failure_index: np.ndarray
) -> list[dict]:
    """The metrics of each run of a batch from its :func:`metric_series` (the rows of ``setup``'s runs)."""
    sim = scenario.simulation
    nmse = None if setup.identification is None else np.asarray(setup.identification.nmse)
    lost_path_error = scenario.lost_path_distance()  # the reference is every run's: sampled once
    loaded = loading_warnings(scenario)  # and what loading found (22 ms a scenario)
    status, failure_index = failure_within(status, failure_index, sim.n_steps)  # simulated over the run length
    metrics = []
    for i in range(len(status)):
        k = int(failure_index[i])
        valid = slice(0, sim.n_steps if k < 0 else k + 1)
        columns = finished_columns({name: np.asarray(value[i][valid], dtype=float) for name, value in series.items()})
        columns |= traction_columns(
            jax.tree_util.tree_map(lambda p, i=i: np.asarray(p)[i], setup.plant_params), columns, scenario
        )
        metrics.append(
            run_metrics(
                scenario,
                columns,
                status=STATUS_NAMES[int(status[i])],
                failure_time=None if k < 0 else float(series["t"][i][k]),
                nmse=None if nmse is None else nmse[i],
                lost_path_error=lost_path_error,
                loaded=loaded,
            )
        )
    return metrics


def batch_size(runs: int, chunk_size: int) -> int:
    """The runs of each batch of :func:`monte_carlo` for ``runs`` runs in chunks of at most ``chunk_size``: the chunk
    size, or for fewer runs their number rounded up to a quarter octave and to an even number (so that counts of
    runs share a few programs and split over two devices), at most ``chunk_size``. Rows of batches of 16 runs and
    more may differ in the last bits between batch sizes (docs/reliability.md)."""
    if runs >= chunk_size:
        return chunk_size
    size = bucketed_length(runs)
    return min(chunk_size, size + size % 2 if size > 1 else size)


def drawn_plant(scenario: Scenario, setup: Setup, i: int) -> dict[str, float]:
    """``plant_<field>`` of run ``i`` of a prepared batch, for each ``[randomize]`` draw (in its unit)."""
    drawn = [field for field, draw in scenario.randomize if draw is not None]
    return {f"plant_{field}": float(getattr(setup.plant_params, field)[i]) for field in drawn}


def monte_carlo(
    scenario: Scenario,
    seeds: Sequence[int],
    *,
    chunk_size: int = 64,
    on_chunk: Callable[[int], None] = lambda done: None,
    frame: TrajectoryFrame | None = None,
) -> list[dict]:
    """Run ``scenario`` once per seed, in vmapped chunks of ``chunk_size`` (memory stays bounded: only
    the metrics are kept); return one row per run: seed, drawn plant values, metrics (``summarize``).

    Every chunk is padded with repeats of its first seed to one :func:`batch_size`, so it compiles once.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario; its ``[randomize]`` draws differ per seed.
    seeds : sequence of int
        One run per seed.
    chunk_size : int
        Runs per vmapped batch.
    on_chunk : callable
        Called with the number of runs done after each chunk (a progress bar).
    frame : TrajectoryFrame, optional
        A study's trajectory kinds (:func:`~ddtrack.trajectories.switched.trajectory_frame`): its cells on
        different trajectories then share one program.

    Returns
    -------
    list of dict
        Per seed: ``seed``, ``plant_<field>`` for each drawn plant parameter (in its unit), and the
        :func:`ddtrack.summarize` metrics.
    """
    rows: list[dict] = []
    size = batch_size(len(seeds), chunk_size)
    for start in range(0, len(seeds), chunk_size):
        chunk = list(seeds[start : start + chunk_size])
        padded = chunk + [chunk[0]] * (size - len(chunk))
        setup, draws = prepare_batch(scenario, padded, frame=frame)
        for i, (seed, metrics) in enumerate(zip(chunk, batch_metrics(scenario, setup, draws), strict=False)):
            rows.append({"seed": seed, **drawn_plant(scenario, setup, i), **metrics})
        on_chunk(len(rows))
    return rows
