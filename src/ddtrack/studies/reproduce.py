"""``ddtrack reproduce``: the paper's Table 1 and Figures 10 to 17 (model.md §4), over seeds.

Both cases (the shipped ``paper_line`` and ``paper_square`` scenarios, unchanged) are run with
backstepping and with NN-adaptive backstepping on common random numbers: the same seed gives both
controllers the same plant, disturbance and noise; only the NN controller's own draws (emulator
initialisation, identification dither) differ between seeds. The statistic is model.md §4.4's mean of
e_tr over the case's metric window; the improvement is paired per seed.
"""

from __future__ import annotations

import csv
import io
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import matplotlib.pyplot as plt

from .._format import with_interval
from ..compilations import ledger_entry, record_compiled
from ..metrics import METRIC_DOMAINS, improvement, mean_ci, summarize
from ..outdir import atomic_write
from ..plotting import ADAPTIVE, plot_errors, plot_gains, plot_path, plot_states
from ..runner import prepare_batch, row, run_setup
from ..scenario import Scenario, load_scenario
from ..shipped import scenario_path
from ..sim import timeseries
from .cells import batch_program, planned_key, program_key, programs_held

#: The paper's Table 1: mean tracking error [m] and improvement [%] (its 52.04 % rounds to 52.05).
PAPER_TABLE = {
    "paper_line": {"backstepping": 0.0547, "nn_adaptive": 0.0216, "improvement": 60.51},
    "paper_square": {"backstepping": 0.0976, "nn_adaptive": 0.0468, "improvement": 52.04},
}
CASES = {"paper_line": "Case 1: line y = x", "paper_square": "Case 2: square"}
STATISTICS = ("e_tr_mean", "e_tr_rms", "e_tr_max", "settling_time")
NN = ["controller.kind=nn_adaptive_backstepping"]
#: controller variants: name -> scenario overrides; the ablations only change the NN controller
VARIANTS = {"backstepping": ["controller.kind=backstepping"], "nn_adaptive": NN}
ABLATIONS = {
    "nn_jacobian_analytic": [*NN, 'controller.jacobian="analytic"'],
    "nn_jacobian_quasi_static": [*NN, 'controller.jacobian="quasi_static"'],
    "nn_jacobian_model": [*NN, 'controller.jacobian="model"'],
    "nn_jacobian_model_sensitivity": [*NN, 'controller.jacobian="model_sensitivity"'],
    "nn_paper_error_jacobian": [*NN, 'controller.error_jacobian="paper"'],
    "nn_no_identification": [*NN, "controller.identification=false"],
    "nn_no_online_learning": [*NN, "controller.online_learning=false"],
    "nn_learn_saturated": [*NN, "controller.learn_saturated=true"],
}


@dataclass
class CaseResult:
    """Per-seed metrics of every variant on one case, and the seed-0 series for the figures."""

    scenario: Scenario
    metrics: dict[str, list[dict]] = field(default_factory=dict)
    series: dict[str, dict] = field(default_factory=dict)


def case_scenarios(name: str, variants: dict[str, list[str]]) -> dict[str, Scenario]:
    """The shipped scenario ``name`` once per variant, with the variant's overrides."""
    path = scenario_path(name)
    return {variant: load_scenario(path, overrides=overrides) for variant, overrides in variants.items()}


def run_case(
    name: str,
    seeds: int,
    variants: dict[str, list[str]],
    progress: Callable[[str], None] = lambda _: None,
    scenarios: dict[str, Scenario] | None = None,
) -> CaseResult:
    """Run every variant of one case for seeds 0..seeds-1, each variant as one batch over the seeds (a row of a batch
    below 16 runs is its single run, bit for bit: ``ddtrack.runner.run_batch``, docs/reliability.md); ``scenarios``:
    the variants' scenarios where :func:`case_scenarios` has loaded them already."""
    scenarios = scenarios or case_scenarios(name, variants)
    result = CaseResult(scenario=scenarios["backstepping"])
    identification = None  # shared by the variants that identify (the same plants, seeds and emulator inits)
    for variant, scenario in scenarios.items():
        setup, draws = prepare_batch(scenario, range(seeds), identification=identification)
        identification = setup.identification if setup.identification is not None else identification
        runs = run_setup(scenario, setup, draws, batched=True)
        record_compiled([ledger_entry(batch_program(program_key(scenario, setup, draws), seeds, whole=True))])
        sim = scenario.simulation
        for seed in range(seeds):
            run = row(runs, seed)
            columns = timeseries(run)
            metrics = summarize(
                columns,
                status=run.status_name,
                window=sim.window,
                control_period=sim.control_period,
                settling_threshold=sim.settling_threshold,
                failure_time=run.failure_time,
            )
            result.metrics.setdefault(variant, []).append(metrics)
            if seed == 0:
                result.series[variant] = columns
            progress(f"{name} seed {seed} {variant}: {metrics['status']}, e_tr_mean {metrics['e_tr_mean']}")
    return result


def _with_values(values: list, key: str) -> dict:
    """:func:`mean_ci` in the statistic's domain plus the per-seed values, so the table can be re-derived."""
    return mean_ci(values, domain=METRIC_DOMAINS[key]) | {"values": values}


def summarise_case(name: str, case: CaseResult) -> dict:
    """The Table 1 entry of one case: statistics per variant, paired improvements over backstepping."""
    baseline = case.metrics["backstepping"]
    entry: dict = {
        "title": CASES[name],
        "window": list(case.scenario.simulation.window),
        "paper": PAPER_TABLE[name],
        "controllers": {},
        "improvement": {},
    }
    for variant, runs in case.metrics.items():
        entry["controllers"][variant] = {key: _with_values([r[key] for r in runs], key) for key in STATISTICS}
        entry["controllers"][variant]["status"] = [r["status"] for r in runs]
        if runs[0].get("final_gains") is not None and variant != "backstepping":
            entry["controllers"][variant]["final_gains"] = [r["final_gains"] for r in runs]
        if variant != "backstepping":
            paired = [
                improvement(b["e_tr_mean"], r["e_tr_mean"]) if r["e_tr_mean"] is not None else None
                for b, r in zip(baseline, runs, strict=True)
            ]
            entry["improvement"][variant] = _with_values(paired, "improvement")
    return entry


def _fmt(stat: dict) -> str:
    if stat["missing"]:  # a failed run, or a settling time never reached, in some seeds: no mean over the rest
        return f"n/a in {stat['missing']} of {stat['n'] + stat['missing']} seeds"
    return with_interval(stat["mean"], stat.get("ci_low"), stat.get("ci_high"))


def table_markdown(table: dict) -> str:
    """Table 1 as Markdown: ours (mean [95 % CI] over seeds) beside the paper's."""
    lines = [f"# Table 1, reproduced ({table['seeds']} seeds; mean [95 % CI])", ""]
    lines += [
        "| case | controller | mean e_tr [m] | paper [m] | RMS e_tr [m] | max e_tr [m] | settling [s] "
        "| improvement [%] | paper [%] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for _name, entry in table["cases"].items():
        for variant, stats in entry["controllers"].items():
            paper = entry["paper"].get(variant)
            gain = entry["improvement"].get(variant)
            lines.append(
                f"| {entry['title']} | {variant} | {_fmt(stats['e_tr_mean'])} | {paper if paper else ''} | "
                f"{_fmt(stats['e_tr_rms'])} | {_fmt(stats['e_tr_max'])} | {_fmt(stats['settling_time'])} | "
                f"{_fmt(gain) if gain else ''} | "
                f"{entry['paper']['improvement'] if variant == 'nn_adaptive' else ''} |"
            )
    lines += [
        "",
        "Statistic: mean of e_tr over each case's metric window (model.md §4.4): "
        + ", ".join(f"{e['title']} {e['window']} s" for e in table["cases"].values())
        + ". Improvement: 100 (E_BS - E_NN) / E_BS, paired by seed.",
        "",
    ]
    return "\n".join(lines)


def table_csv(table: dict) -> str:
    """One row per case, controller and statistic."""
    out = io.StringIO()
    writer = csv.writer(out)
    writer.writerow(["case", "controller", "statistic", "mean", "ci_low", "ci_high", "n", "paper"])
    for name, entry in table["cases"].items():
        for variant, stats in entry["controllers"].items():
            for key in STATISTICS:
                s = stats[key]
                paper = entry["paper"].get(variant) if key == "e_tr_mean" else None
                writer.writerow(
                    [name, variant, key, s["mean"], s["ci_low"], s["ci_high"], s["n"], "" if paper is None else paper]
                )
            if variant in entry["improvement"]:
                s = entry["improvement"][variant]
                writer.writerow(
                    [
                        name,
                        variant,
                        "improvement_percent",
                        s["mean"],
                        s.get("ci_low"),
                        s.get("ci_high"),
                        table["seeds"],
                        entry["paper"]["improvement"] if variant == "nn_adaptive" else "",
                    ]
                )
    return out.getvalue()


def case_figures(name: str, case: CaseResult) -> dict[str, plt.Figure]:
    """The paper's Figs. 10-13 (line) or 14-17 (square): path, states, deviations, gains (seed 0)."""
    bs, nn = case.series["backstepping"], case.series["nn_adaptive"]
    window = case.scenario.simulation.window
    path = plot_path(bs, label="backstepping", title=CASES[name])
    plot_path(nn, ax=path.axes[0], label="NN-adaptive", color=ADAPTIVE, reference=False)
    path.axes[0].legend(loc="best", fontsize=8)
    states = plot_states(bs, label="backstepping")
    plot_states(nn, axes=states.axes, label="NN-adaptive", color=ADAPTIVE, reference=False)
    states.axes[0].legend(loc="best", fontsize=8)
    errors = plot_errors(bs, window=window, label="backstepping")
    plot_errors(nn, axes=errors.axes, label="NN-adaptive", color=ADAPTIVE)
    errors.axes[0].legend(loc="best", fontsize=8)
    gains = plot_gains(nn, label="NN-adaptive")
    plot_gains(bs, axes=gains.axes, label="backstepping", color="#1f77b4")
    gains.axes[0].legend(loc="best", fontsize=8)
    return {
        f"{name}_path.png": path,
        f"{name}_states.png": states,
        f"{name}_errors.png": errors,
        f"{name}_gains.png": gains,
    }


def reproduce(
    out: Path,
    *,
    seeds: int = 5,
    ablations: bool = False,
    progress: Callable[[str], None] = lambda _: None,
    on_programs: Callable[[int, int], None] = lambda needed, held: None,
) -> dict:
    """Run both cases, write ``table1.{md,csv,json}`` and ``figures/`` into ``out``; return the table.
    ``on_programs(needed, held)`` hears first how many simulation programs the cases' variants need (one per
    structure) and how many the persistent compilation cache holds."""
    start = time.perf_counter()
    variants = VARIANTS | (ABLATIONS if ablations else {})
    scenarios = {name: case_scenarios(name, variants) for name in CASES}
    programs = {batch_program(planned_key(s, None), seeds, whole=True) for c in scenarios.values() for s in c.values()}
    on_programs(len(programs), programs_held(programs))
    cases = {name: run_case(name, seeds, variants, progress, scenarios[name]) for name in CASES}
    table = {
        "seeds": seeds,
        "ablations": ablations,
        "cases": {name: summarise_case(name, case) for name, case in cases.items()},
    }
    for name, case in cases.items():
        for file, fig in case_figures(name, case).items():
            atomic_write(out / "figures" / file, partial(fig.savefig, format="png", dpi=110))
            plt.close(fig)
    table["elapsed_s"] = time.perf_counter() - start
    atomic_write(out / "table1.json", lambda f: f.write((json.dumps(table, indent=2, allow_nan=False) + "\n").encode()))
    atomic_write(out / "table1.csv", lambda f: f.write(table_csv(table).encode()))
    atomic_write(out / "table1.md", lambda f: f.write(table_markdown(table).encode()))
    return table


def nn_beats_backstepping(table: dict) -> dict[str, bool]:
    """Per case: does NN-adaptive backstepping have a lower mean error than backstepping (mean over seeds)?"""
    verdict = {}
    for name, entry in table["cases"].items():
        gain = entry["improvement"]["nn_adaptive"]
        verdict[name] = not gain["missing"] and gain["mean"] > 0.0  # a failed seed is a loss too
    return verdict
