"""What every ``ddtrack bench`` leaderboard shares (the suites' :mod:`.suite`, :mod:`.robot_board` and
the user's own scenarios' :mod:`.scenario_suite`): the statistics of a set of runs with their intervals, the
plausibility flags, the flat table's interval columns, and the files a board is written to."""

from __future__ import annotations

import io
import json
from collections.abc import Mapping, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.csv
import pyarrow.parquet as pq

from ..metrics import METRIC_DOMAINS, mean_ci, rate_ci
from ..outdir import atomic_write

#: the per-run statistics a leaderboard gives a mean and a 95 % interval of
STATISTICS = ("e_tr_mean", "e_tr_rms", "e_tr_max", "effort", "saturation_fraction")
#: warnings that say a run asked the floor for more grip than it has
GRIP = ("friction_exceeds_floor", "friction_beyond_any_floor")
#: warnings that say a run asked the motors for more speed or torque than their curve gives
MOTOR = ("wheel_speed_beyond_motor", "torque_beyond_motor")
#: warnings that say a run asked for something the real robot cannot give
IMPLAUSIBLE = GRIP + MOTOR
#: the columns :func:`interval_columns` gives each summary
INTERVAL_STATS = ("mean", "ci_low", "ci_high")


def warning_codes(metrics: Mapping[str, Any] | None) -> set[str]:
    """The codes of a run's warnings (``metrics.json``'s ``warnings``); none for a run that raised."""
    return {w["code"] for w in (metrics or {}).get("warnings") or []}


def lost(run: Mapping[str, Any]) -> bool:
    """Whether a run (a flat row with ``status`` and its metrics) ran to its end off its path (``lost_path``,
    :func:`ddtrack.metrics.lost_path_time`)."""
    return run["status"] == "ok" and bool(run.get("lost_path"))


def tracks(run: Mapping[str, Any]) -> bool:
    """Whether a run (a flat row with ``status`` and its metrics) tracked its reference to the end: it neither
    failed nor lost the path (``lost_path``, :func:`ddtrack.metrics.lost_path_time`)."""
    return run["status"] == "ok" and not lost(run)


def tracking_value(run: Mapping[str, Any], key: str = "e_tr_mean") -> Any:
    """A run's ``key`` where it tracked, else None: a run that lost the path or failed is counted apart, never
    averaged with the rest (its error grows without bound, and the last bit decides it)."""
    return run.get(key) if tracks(run) else None


def run_statistics(runs: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """``runs``, ``failures`` (status not ok), ``lost`` (ran to the end off the path) with ``lost_rate`` (a
    fraction with its Wilson 95 % interval), and the mean [95 % CI] of each of :data:`STATISTICS` over the runs
    that tracked (flat rows with ``status`` and the metrics), in its domain; the others count as missing."""
    off = sum(map(lost, runs))
    summary: dict[str, Any] = {
        "runs": len(runs),
        "failures": sum(r["status"] != "ok" for r in runs),
        "lost": off,
        "lost_rate": rate_ci(off, len(runs)),
    }
    for key in STATISTICS:
        summary[key] = mean_ci([tracking_value(r, key) for r in runs], domain=METRIC_DOMAINS[key])
    return summary


def interval_columns(key: str, summary: Mapping[str, Any] | None) -> dict[str, Any]:
    """``key_mean``, ``key_ci_low``, ``key_ci_high`` of a :func:`~ddtrack.metrics.mean_ci` summary (None where it
    is missing): one flat row per board entry, for CSV and Parquet."""
    return {f"{key}_{stat}": (summary or {}).get(stat) for stat in INTERVAL_STATS}


def write_board(out: Path, markdown: str, table: pa.Table, figures: Mapping[str, Any], summary: dict) -> None:
    """``leaderboard.md``, ``.parquet``, ``.csv``, ``.json`` and the ``figures`` (name -> Matplotlib figure, closed
    once written) into ``out``, each file atomically."""
    import matplotlib.pyplot as plt

    atomic_write(out / "leaderboard.md", lambda f: f.write(markdown.encode()))
    atomic_write(out / "leaderboard.parquet", lambda f: pq.write_table(table, f))
    buffer = io.BytesIO()
    pa.csv.write_csv(table, buffer)
    atomic_write(out / "leaderboard.csv", lambda f: f.write(buffer.getvalue()))
    for name, fig in figures.items():
        atomic_write(out / name, partial(fig.savefig, format="png", dpi=110))
        plt.close(fig)
    atomic_write(out / "leaderboard.json", lambda f: f.write((json.dumps(summary, indent=2) + "\n").encode()))
