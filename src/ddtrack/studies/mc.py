"""``ddtrack mc``: Monte Carlo over seeds (and drawn plant parameters) for several controllers, on
common random numbers: seed s gives every controller the same plant, disturbance and noise."""

from __future__ import annotations

import io
import json
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path

import pyarrow as pa
import pyarrow.csv
import pyarrow.parquet as pq

from .._format import significant, with_interval
from ..compilations import ledger_entry, record_compiled
from ..errors import ConfigError
from ..metrics import METRIC_DOMAINS, improvement, mean_ci, warning_counts
from ..outdir import atomic_write
from ..scenario import Scenario, load_scenario
from .batches import batch_size, monte_carlo
from .board import lost, tracking_value
from .cells import batch_program, planned_key, programs_held

STATISTICS = ("e_tr_mean", "e_tr_rms", "e_tr_max", "e_tr_final", "settling_time", "effort", "saturation_fraction")


def vary_override(spec: str) -> str:
    """``FIELD=DIST:SPREAD[:absolute]`` (e.g. ``mass=uniform:0.2``) -> a ``randomize.FIELD`` override."""
    field, sep, rest = spec.partition("=")
    parts = rest.split(":")
    if not sep or len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] not in ("relative", "absolute")):
        raise ConfigError(
            "--vary",
            f"'{spec}' is not FIELD=DISTRIBUTION:SPREAD[:absolute]",
            "e.g. --vary mass=uniform:0.2 (plus or minus 20 %) or --vary com_offset=normal:0.01:absolute",
        )
    kind = parts[2] if len(parts) == 3 else "relative"
    return f'randomize.{field.strip()}={{distribution="{parts[0]}", {kind}={parts[1]}}}'


def load_specs(
    scenario: Path, *, controllers: Sequence[str], vary: Sequence[str] = (), overrides: Sequence[str] = ()
) -> dict[str, Scenario]:
    """The scenario once per controller, with the overrides and the ``--vary`` draws applied."""
    extra = [*overrides, *(vary_override(v) for v in vary)]
    return {name: load_scenario(scenario, overrides=extra, controller=name) for name in controllers}


def run_specs(
    specs: dict[str, Scenario],
    *,
    n: int,
    seed: int = 0,
    chunk_size: int = 64,
    on_chunk: Callable[[str, int], None] = lambda name, done: None,
    on_programs: Callable[[int, int], None] = lambda needed, held: None,
) -> dict[str, list[dict]]:
    """Per controller, one row per seed ``seed .. seed + n - 1`` (see :func:`ddtrack.studies.batches.monte_carlo`).
    ``on_programs(needed, held)`` hears first how many simulation programs the controllers need (one per structure:
    every chunk has one size) and how many the persistent compilation cache holds."""
    seeds = list(range(seed, seed + n))
    size = batch_size(n, chunk_size)
    programs = {name: batch_program(planned_key(spec, None), size) for name, spec in specs.items()}
    on_programs(len(set(programs.values())), programs_held(programs.values()))
    rows = {}
    for name, spec in specs.items():
        rows[name] = monte_carlo(spec, seeds, chunk_size=chunk_size, on_chunk=partial(on_chunk, name))
        record_compiled([ledger_entry(programs[name])])
    return rows


def summarise(rows: dict[str, list[dict]]) -> dict:
    """Mean and 95 % CI of every statistic per controller over its runs that tracked to the end, its failures and
    the runs that lost the path (counted apart: their errors grow without bound), and the paired improvement of
    each controller's mean tracking error over the first controller's (seeds where both runs tracked)."""
    names = list(rows)
    baseline = rows[names[0]]
    summary: dict = {"controllers": {}, "improvement_over": names[0], "improvement": {}}
    for name, runs in rows.items():
        summary["controllers"][name] = {
            key: mean_ci([tracking_value(r, key) for r in runs], domain=METRIC_DOMAINS[key]) for key in STATISTICS
        }
        summary["controllers"][name]["failures"] = sum(r["status"] != "ok" for r in runs)
        summary["controllers"][name]["lost"] = sum(map(lost, runs))
        summary["controllers"][name]["warnings"] = warning_counts(runs)
        if name != names[0]:
            pairs = [(tracking_value(b), tracking_value(r)) for b, r in zip(baseline, runs, strict=True)]
            paired = [improvement(b, r) for b, r in pairs if b is not None and r is not None and b > 0]
            summary["improvement"][name] = mean_ci(paired, domain=METRIC_DOMAINS["improvement"]) | {
                "paired_runs": len(paired)
            }
    return summary


def table(rows: dict[str, list[dict]]) -> pa.Table:
    """One row per run: controller, seed, drawn plant values, metrics, status, and ``warning_codes`` (the run's
    warning codes, comma-separated; the messages are in ``warnings``)."""
    records = []
    for name, runs in rows.items():
        for r in runs:
            flat = {k: v for k, v in r.items() if k not in ("window", "final_gains", "failure_time", "warnings")}
            gains = r.get("final_gains") or [None, None, None]
            records.append(
                {
                    "controller": name,
                    **flat,
                    "window_start": r["window"][0],
                    "window_end": r["window"][1],
                    "failure_time": r.get("failure_time"),
                    "final_kx": gains[0],
                    "final_ky": gains[1],
                    "final_ktheta": gains[2],
                    "warning_codes": ",".join(w["code"] for w in r["warnings"]),
                    "warnings": " | ".join(w["message"] for w in r["warnings"]),
                }
            )
    return pa.Table.from_pylist(records)


def write(out: Path, rows: dict[str, list[dict]], summary: dict) -> None:
    """``runs.parquet``, ``runs.csv`` and ``summary.json`` into ``out``, each written atomically."""
    runs = table(rows)
    atomic_write(out / "runs.parquet", lambda f: pq.write_table(runs, f))
    csv_buffer = io.BytesIO()
    pa.csv.write_csv(runs, csv_buffer)
    atomic_write(out / "runs.csv", lambda f: f.write(csv_buffer.getvalue()))
    atomic_write(
        out / "summary.json", lambda f: f.write((json.dumps(summary, indent=2, allow_nan=False) + "\n").encode())
    )


def format_summary(summary: dict, n: int) -> str:
    """The printed summary: mean [95 % CI] per controller and the paired improvement."""
    lines = [f"{n} runs per controller; mean [95 % CI]"]
    for name, stats in summary["controllers"].items():
        e = stats["e_tr_mean"]
        if e["mean"] is None:
            text = "no run tracked to the end"
        elif e["ci_low"] is None:
            text = f"{significant(e['mean'])} m (one run: no interval)"
        else:
            text = f"{with_interval(e['mean'], e['ci_low'], e['ci_high'])} m"
        saturated = stats["saturation_fraction"]
        mean, low, high = (
            None if saturated[k] is None else 100.0 * saturated[k] for k in ("mean", "ci_low", "ci_high")
        )
        lost = f", lost the path {stats['lost']}" if stats.get("lost") else ""
        lines.append(
            f"  {name:<26} e_tr_mean {text}; saturated {with_interval(mean, low, high)} %; "
            f"failures {stats['failures']}{lost}"
        )
        if stats["warnings"]:
            lines.append(
                f"  {'':<26} warnings: " + ", ".join(f"{code} x {count}" for code, count in stats["warnings"].items())
            )
    for name, gain in summary["improvement"].items():
        if gain["mean"] is None:
            lines.append(f"  {name} vs {summary['improvement_over']}: no paired runs")
        elif gain["ci_low"] is None:
            lines.append(f"  {name} vs {summary['improvement_over']}: {significant(gain['mean'])} % (one paired run)")
        else:
            lines.append(
                f"  {name} vs {summary['improvement_over']}: improvement "
                f"{with_interval(gain['mean'], gain['ci_low'], gain['ci_high'])} % "
                f"(paired, {gain['paired_runs']} seeds)"
            )
    return "\n".join(lines)
